"""Shared plumbing of the training scripts: config dataclass <-> TOML <-> argparse, run dirs.

Precedence: dataclass defaults < ``--config file.toml`` < command-line flags. Flags are
generated from the dataclass fields (``--total-timesteps 256``); tuples take several values.
A run directory ``runs/<script>/<env_id>__seed<seed>__<YYYYmmdd-HHMMSS>/`` is created fresh
(never overwritten) and receives ``config.toml``, ``command.txt`` and ``versions.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import datetime as _dt
import errno
import json
import math
import os
import platform
import shlex
import subprocess
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar, get_type_hints

C = TypeVar("C")


def _coerce(kind: Any, value: Any, name: str) -> Any:
    """``value`` (from TOML or a flag) as the field's type; ValueError naming ``name``."""
    if kind is bool:
        if isinstance(value, bool):
            return value
        if str(value).lower() in ("1", "true", "yes"):
            return True
        if str(value).lower() in ("0", "false", "no"):
            return False
        raise ValueError(f"{name} must be true or false, got {value!r}")
    if kind is Path:
        if not isinstance(value, str | Path):
            raise ValueError(f"{name} must be a path, got {value!r}")
        return Path(value)
    if getattr(kind, "__origin__", None) is tuple:
        (elem, *_) = kind.__args__
        if not isinstance(value, list | tuple) or len(value) > 64:
            raise ValueError(f"{name} must be a list of at most 64 values, got {value!r}")
        return tuple(_coerce(elem, v, name) for v in value)
    if kind in (int, float):
        if isinstance(value, bool) or isinstance(value, list | dict):
            raise ValueError(f"{name} must be a number, got {value!r}")
        if kind is int and isinstance(value, float) and not value.is_integer():
            raise ValueError(f"{name} must be an integer, got {value!r}")
        try:
            out = kind(value)
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"{name} must be {'an integer' if kind is int else 'a number'}, "
                             f"got {str(value)[:40]!r}") from None  # fmt: skip
        if kind is float and not math.isfinite(out):
            raise ValueError(f"{name} must be finite, got {str(value)[:40]!r}")
        if kind is int and not -(2**63) <= out < 2**63:
            raise ValueError(f"{name} must be a 64-bit integer, got {str(value)[:40]!r}")
        return out
    if kind is str:
        if not isinstance(value, str):
            raise ValueError(f"{name} must be a string, got {value!r}")
        return value
    if kind is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{name} must be a table of key = value, got {value!r}")
        return dict(value)
    return kind(value)


def parse_assignment(item: str, flag: str) -> tuple[str, Any]:
    """``KEY=VALUE`` of a table flag (``--env dt=0.02``) as (key, value).

    VALUE is read as a TOML value (a number, true/false, a [list], an {inline = table}), else
    as a plain string.
    """
    import tomllib

    key, sep, value = item.partition("=")
    if not sep or not key.strip() or not value.strip():
        raise ValueError(f"{flag} takes KEY=VALUE items, got {item!r}")
    try:
        parsed = tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return key.strip(), parsed


def _toml_kind_ok(kind: Any, value: Any) -> bool:
    """Whether a TOML value has the field's type (a string is no number, a number no bool)."""
    if kind is bool:
        return isinstance(value, bool)
    if kind in (int, float):
        return isinstance(value, int | float) and not isinstance(value, bool)
    if kind in (str, Path):
        return isinstance(value, str)
    if getattr(kind, "__origin__", None) is tuple:
        return isinstance(value, list) and all(_toml_kind_ok(kind.__args__[0], v) for v in value)
    if kind is dict:
        return isinstance(value, dict)
    return True


def check_toml_kinds(cls: type, data: dict[str, Any], source: str) -> None:
    """Refuse a config file's value of the wrong TOML type (``stop_evals = "2"``): ValueError.

    Flags arrive as text and are converted; a file's values are typed, and a string where a
    number belongs (or a number where a boolean belongs) is a mistake, not a spelling.
    """
    hints = get_type_hints(cls)
    names = {"int": "an integer", "float": "a number", "bool": "true or false",
             "str": "a string", "Path": "a path (a string)", "dict": "a table"}  # fmt: skip
    for key, value in data.items():
        kind = hints.get(key)
        if kind is not None and not _toml_kind_ok(kind, value):
            want = names.get(getattr(kind, "__name__", ""), "a list")
            raise ValueError(f"{source}: {key} must be {want}, got {value!r}")


def config_from_mapping(cls: type[C], data: dict[str, Any], source: str) -> C:
    """``cls`` from a mapping (a TOML file's): unknown keys and bad values raise ValueError.

    A ``validate()`` method of ``cls``, if any, checks ranges and choices.
    """
    hints = get_type_hints(cls)
    unknown = set(data) - {f.name for f in dataclasses.fields(cls)}
    retired = sorted(unknown & set(getattr(cls, "RETIRED", {})))
    if retired:
        raise ValueError(f"{source}: {retired[0]}: {cls.RETIRED[retired[0]]}")
    if unknown:
        raise ValueError(f"{source}: unknown keys {sorted(unknown)}")
    cfg = cls(**{k: _coerce(hints[k], v, k) for k, v in data.items()})
    if hasattr(cfg, "validate"):
        cfg.validate()
    return cfg


def field_help(cls: type) -> dict[str, str]:
    """Each field's help text: the comment after its definition (and comment lines below it).

    The dataclass source is the one place a setting is documented; ``--help`` shows it.
    """
    import inspect
    import re

    out: dict[str, str] = {}
    current = None
    for line in inspect.getsource(cls).splitlines():
        m = re.match(r"\s{4}(\w+): [^=]+=[^#]*(#\s*(.*))?$", line)
        if m:
            current = m.group(1)
            out[current] = (m.group(3) or "").strip()
        elif current and re.match(r"\s{4}#", line):
            out[current] = (out[current] + " " + line.strip().lstrip("#").strip()).strip()
        else:
            current = None
    return out


class Refusal(SystemExit):
    """A refusal: one line (its message), exit status 2.

    A ``SystemExit`` whose ``str`` is the line (a test can match it); :func:`command` prints
    it. Uncaught elsewhere, the interpreter exits with status 2 without a traceback.
    """

    def __init__(self, message: str):
        super().__init__(message)
        self.code = 2


EXPECTED_ERRNOS = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is exceeded",
    errno.EROFS: "a read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.ENOENT: "no such file or directory",
    errno.ENOTDIR: "not a directory",
    errno.EISDIR: "a directory",
    errno.ELOOP: "a symlink",
    errno.EEXIST: "already exists",
    errno.ENAMETOOLONG: "a name too long",
    errno.EIO: "an input/output error",
}
"""File-system failures that are the machine's state, not a bug: each refused in one line."""


def command(prog: str, interrupted: str = "nothing was written"):
    """Decorate a command's ``main``: every expected failure one line, exit status 2.

    A refused file or value (:class:`UntrustedFileError`, ``FileNotFoundError``), a full or
    read-only disk, a link where a file belongs: ``PROG: error: WHAT``. Ctrl-C:
    ``PROG: interrupted; INTERRUPTED`` and status 130 (``interrupted`` may be a callable of
    no arguments, for a message known only at run time). Unexpected exceptions keep their
    traceback.
    """
    import functools

    def wrap(main):
        @functools.wraps(main)
        def run(*args, **kwargs):
            from training.plumbing.safe_files import UntrustedFileError

            _PROG.append(prog)
            try:
                return main(*args, **kwargs)
            except Refusal as e:
                if not getattr(e, "printed", False):  # once, by the innermost command
                    print(str(e), file=sys.stderr, flush=True)
                    e.printed = True
                raise
            except (UntrustedFileError, FileNotFoundError) as e:
                line = f"{prog}: error: {_one_line(e)}"
            except OSError as e:
                if e.errno not in EXPECTED_ERRNOS:
                    raise
                where = e.filename or ""
                line = f"{prog}: error: {where}{': ' if where else ''}{EXPECTED_ERRNOS[e.errno]}"
            except KeyboardInterrupt:
                text = interrupted() if callable(interrupted) else interrupted
                print(f"\n{prog}: interrupted; {text}", file=sys.stderr, flush=True)
                raise SystemExit(130) from None
            finally:
                _PROG.pop()
            print(line, file=sys.stderr, flush=True)
            refusal = Refusal(line)
            refusal.printed = True
            raise refusal from None

        return run

    return wrap


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return text[0] if text else type(e).__name__


_PROG: list[str] = []
"""The names of the commands running (the innermost last): a parser's default ``prog``."""


class CliParser(argparse.ArgumentParser):
    """argparse with one line per refusal: ``PROG: error: WHAT (see --help)``, exit status 2.

    The message travels in the :class:`Refusal` (a test can match it); no usage block is
    printed above it. ``prog`` defaults to the running :func:`command`'s name.
    """

    def __init__(self, *args, **kwargs):
        if "prog" not in kwargs and _PROG:
            kwargs["prog"] = _PROG[-1]
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        """Refuse with one line naming the flag or file."""
        raise Refusal(f"{self.prog}: error: {message} (see --help)")


def _parser(cls: type, description: str) -> argparse.ArgumentParser:
    hints = get_type_hints(cls)
    helps = field_help(cls)
    parser = CliParser(description=description)
    parser.add_argument("--config", type=Path, help="TOML file of field = value pairs")
    for f in dataclasses.fields(cls):
        flag = "--" + f.name.replace("_", "-")
        kind = hints[f.name]
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        text = f"{helps.get(f.name, '')} (default: {default})".strip()
        if kind is dict:  # a table: KEY=VALUE items on top of the config file's table;
            # the flag given twice adds the second's items (argparse would drop the first's)
            parser.add_argument(flag, nargs="+", action="extend", default=None, help=text,
                                metavar="KEY=VALUE")  # fmt: skip
        elif getattr(kind, "__origin__", None) is tuple:
            elem = kind.__args__[0]
            if elem is dict:  # a list of tables ([[schedule]]): the config file's only
                continue
            parser.add_argument(
                flag, nargs="+", type=elem, default=None, help=text, metavar=elem.__name__.upper()
            )
        elif kind is bool:  # a bare flag means true; "--flag false" still reads
            parser.add_argument(
                flag, nargs="?", const="true", default=None, help=text, metavar="BOOL"
            )
        else:
            metavar = {int: "INT", float: "X", Path: "PATH"}.get(kind, "S")
            typ = kind if kind in (int, float) else None
            parser.add_argument(flag, type=typ, default=None, help=text, metavar=metavar)
    return parser


TABLE_FIELDS = ("env", "train_env")
"""Config tables that a recipe file merges key by key onto its base's."""


def read_config_file(path: Path) -> dict[str, Any]:
    """A recipe TOML file's values, on top of its ``base`` file's when it names one.

    ``base = "ppo_base.toml"``: a file name in the same folder (no path), itself without a
    base; the recipe's values replace the base's, its ``[env]`` and ``[train_env]`` entries
    key by key. The merged values are what a run saves (its config has no ``base``).
    """
    from training.plumbing.safe_files import read_toml

    own = read_toml(path)
    base_name = own.pop("base", None)
    if base_name is None:
        return own
    if not isinstance(base_name, str) or Path(base_name).name != base_name or not base_name:
        raise ValueError(f"{path}: base must be a file name in the same folder, got {base_name!r}")
    base = read_toml(path.parent / base_name)
    if "base" in base:
        raise ValueError(f"{path.parent / base_name}: a base names no base of its own")
    merged = {**base, **own}
    for table in TABLE_FIELDS:
        if table in base or table in own:
            merged[table] = {**base.get(table, {}), **own.get(table, {})}
    return merged


def parse_config(cls: type[C], argv: Sequence[str] | None, description: str) -> C:
    """Build ``cls`` from defaults, an optional TOML file and CLI flags (in that precedence).

    Every refusal (a missing or malformed file, an unknown key, a value of the wrong type or
    out of range) is one line from argparse (exit status 2), before anything is written.
    """
    from training.plumbing.safe_files import UntrustedFileError

    parser = _parser(cls, description)
    args = parser.parse_args(argv)
    values: dict[str, Any] = {}
    if args.config is not None:
        try:
            values.update(read_config_file(Path(args.config)))
            check_toml_kinds(cls, values, str(args.config))
        except (UntrustedFileError, ValueError) as e:
            parser.error(f"--config: {e}")
    hints = get_type_hints(cls)
    try:
        for f in dataclasses.fields(cls):
            v = getattr(args, f.name, None)  # a list of tables has no flag
            if v is not None and hints[f.name] is dict:
                flag = "--" + f.name.replace("_", "-")
                table = dict(values.get(f.name, {}))
                table.update(parse_assignment(item, flag) for item in v)
                values[f.name] = table
            elif v is not None:
                values[f.name] = v
        return config_from_mapping(cls, values, str(args.config or "flags"))
    except ValueError as e:
        parser.error(str(e))


def given_flags(cls: type, argv: Sequence[str] | None) -> set[str]:
    """The fields set by a flag on the command line (not by default or by a config file)."""
    args = _parser(cls, "").parse_args(argv)
    return {f.name for f in dataclasses.fields(cls) if getattr(args, f.name, None) is not None}


def toml_value(v: Any) -> str:
    """One TOML value: a string, number, boolean, path, list/tuple or dict (inline table)."""
    if isinstance(v, dict):
        items = (f"{k} = {toml_value(x)}" for k, x in v.items() if x is not None)
        return "{" + ", ".join(items) + "}"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, Path):
        v = str(v)
    if isinstance(v, float) and not math.isfinite(v):
        raise ValueError(f"TOML has no {v}")
    return json.dumps(v)


def to_toml(cfg: Any) -> str:
    """Resolved config as TOML text: the plain fields, then each dict field as a [table]."""
    lines, tables = [], []
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if isinstance(v, dict):
            tables += ["", f"[{f.name}]"] + [f"{k} = {toml_value(x)}" for k, x in v.items()
                                              if x is not None]  # fmt: skip
        else:
            lines.append(f"{f.name} = {toml_value(v)}")
    return "\n".join(lines + tables) + "\n"


def versions() -> dict[str, str | bool]:
    """Package versions, the git commit and whether tracked files differ from it (the run dir)."""
    out = {"python": platform.python_version()}
    for name in (
        "numpy",
        "numba",
        "gymnasium",
        "stable_baselines3",
        "torch",
        "biped_constraint_env",
    ):
        try:
            mod = __import__(name)
            out[name] = getattr(mod, "__version__", "?")
        except ImportError:
            out[name] = "not installed"
    here = Path(__file__).resolve().parent
    try:
        out["git_commit"] = _git(["rev-parse", "HEAD"], here)
        # tracked files changed since that commit: the code that ran is not the commit's
        out["git_dirty"] = bool(_git(["status", "--porcelain", "--untracked-files=no"], here))
    except (OSError, subprocess.CalledProcessError):
        out["git_commit"] = "unknown"
    return out


def _git(args: list[str], cwd: Path) -> str:
    return subprocess.run(
        ["git", *args], capture_output=True, text=True, check=True, cwd=cwd
    ).stdout.strip()


def make_run_dir(
    out_dir: Path,
    script: str,
    env_id: str,
    seed: int,
    cfg: Any,
    argv: Sequence[str] | None,
    module: str = "",
):
    """Create a fresh run directory with config.toml, command.txt and versions.json.

    ``command.txt`` is the command line shell-quoted (``shlex.join``): it pastes back as it ran.

    ``module``: the command's module, for command.txt (default ``training.SCRIPT``).
    ``OUT_DIR/SCRIPT/ENV__seedS__STAMP`` is made with ``mkdir`` through its opened parent
    (a name that exists, a link included, takes the next suffix). Returns the run's
    :class:`~training.plumbing.outputs.OutDir` (its ``path`` is the directory's name).
    """
    from training.plumbing.outputs import OutDir

    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    with OutDir.open(Path(out_dir) / script) as parent:
        for suffix in range(1000):
            name = f"{env_id}__seed{seed}__{stamp}" + (f"-{suffix}" if suffix else "")
            try:
                os.mkdir(name, 0o755, dir_fd=parent.fd)
                break
            except FileExistsError:
                continue
        else:
            raise FileExistsError(errno.EEXIST, "1000 runs of this second", str(parent.path))
        run = parent.subdir(name, create=False)
    run.subdir("figures").close()
    run.write("config.toml", to_toml(cfg))
    cmd = [sys.executable, "-m", module or f"training.{script}",
           *(sys.argv[1:] if argv is None else argv)]  # fmt: skip
    run.write("command.txt", shlex.join(cmd) + "\n")  # pastes back into a shell as run
    run.write("versions.json", json.dumps(versions(), indent=2) + "\n")
    return run


def _number_in(kind: type, name: str, lo, hi):
    def parse(text: str):
        v = kind(text)
        if not lo <= v <= hi:  # False for NaN too
            raise argparse.ArgumentTypeError(f"must be in [{lo}, {hi}], got {v}")
        return v

    parse.__name__ = name  # argparse's "invalid NAME value" and its refusal name the flag
    return parse


def int_in(lo: int, hi: int):
    """An argparse type: an integer in [lo, hi]."""
    return _number_in(int, "integer", lo, hi)


def float_in(lo: float, hi: float):
    """An argparse type: a number in [lo, hi] (NaN refused)."""
    return _number_in(float, "number", lo, hi)


@contextlib.contextmanager
def refusals(parser: argparse.ArgumentParser) -> Iterator[None]:
    """Turn a refused file (missing, damaged, untrusted) into the parser's one-line error."""
    from training.plumbing.safe_files import UntrustedFileError

    try:
        yield
    except (UntrustedFileError, FileNotFoundError) as e:
        parser.error(str(e))


def progress(iterable, total: int | None = None, desc: str = "", enabled: bool = True):
    """A tqdm progress bar when tqdm is installed and enabled, else the iterable itself."""
    if not enabled:
        return iterable
    try:
        from tqdm import tqdm
    except ImportError:
        return iterable
    return tqdm(iterable, total=total, desc=desc, mininterval=1.0)
