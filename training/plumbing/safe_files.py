"""Files from anywhere: bounded, checked reads; atomic outputs; manifests; a run's lock.

A policy or run directory is data from anywhere (docs/policy_files.md, "Threat model"). Every
read here is bounded before it happens: a file's size is checked before it is read, an npz
member's shape, dtype and stored size before its data is read, a safetensors header before
any tensor is allocated. Nothing here imports, unpickles or follows a symlink out of the
directory it was given. A refusal is an :class:`UntrustedFileError`: one line naming the file
and what was expected; the commands print it and exit with status 2.
"""

from __future__ import annotations

import ast
import errno
import hashlib
import io
import json
import math
import os
import struct
import tomllib
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

MAX_TEXT_BYTES = 1 << 20
"""Largest config.toml / state.json / manifest read (1 MiB; ours are a few kB)."""
MAX_WEIGHTS_BYTES = 256 << 20
"""Largest policy or optimizer file read (256 MiB; the recipe's network is under 1 MiB)."""
MAX_NPZ_BYTES = 1 << 30
"""Largest npz member decompressed (1 GiB; a normaliser is a few hundred bytes)."""
MAX_HEADER_BYTES = 1 << 20
"""Largest safetensors header (1 MiB)."""
MANIFEST_FILE = "manifest.json"
"""A snapshot's file sizes and SHA-256 hashes, written after every other file."""


SHOWN: dict[int, Path] = {}
"""Display paths of the directory descriptors the process holds (``/proc/self/fd/N`` -> the
directory's name), for messages."""


def shown(path: Path | str) -> Path:
    """``path`` as a user named it: ``/proc/self/fd/N/...`` of a held directory -> its name."""
    parts = Path(path).parts
    if parts[:4] == ("/", "proc", "self", "fd") and len(parts) > 4 and parts[4].isdigit():
        base = SHOWN.get(int(parts[4]))
        if base is not None:
            return base.joinpath(*parts[5:])
    return Path(path)


class UntrustedFileError(ValueError):
    """A file of a policy or run directory is not what it must be (one line: file and why)."""


def inside(root: Path, path: Path) -> Path:
    """``path`` if it is a regular file or directory inside ``root`` with no symlink on the way.

    Raises :class:`UntrustedFileError` for a symlink anywhere below ``root`` or a path that
    leaves it (``..``).
    """
    root = Path(root)
    rel = Path(os.path.relpath(path, root))
    if rel.parts[:1] == ("..",):
        raise UntrustedFileError(f"{path}: outside {root}")
    cur = root
    for part in rel.parts:
        cur = cur / part
        if cur.is_symlink():
            raise UntrustedFileError(f"{cur}: a symlink (policy and run directories hold none)")
    return Path(path)


def read_bytes(path: Path, limit: int, root: Path | None = None) -> bytes:
    """A regular file's bytes, refused when larger than ``limit``, a symlink, FIFO or device.

    Opened once with ``O_NOFOLLOW``; the size and kind are read from the open file.
    """
    path = Path(path)
    if root is not None:
        inside(root, path)
    try:
        return _read_in(None, str(path), shown(path), limit)
    except FileNotFoundError:
        raise UntrustedFileError(f"{shown(path)}: missing (or not a regular file)") from None


def read_toml(path: Path, root: Path | None = None) -> dict[str, Any]:
    """A TOML file of at most :data:`MAX_TEXT_BYTES`, parsed (a refusal names the file)."""
    data = read_bytes(path, MAX_TEXT_BYTES, root)
    try:
        return tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise UntrustedFileError(f"{path}: not valid TOML ({str(e)[:120]})") from None
    except RecursionError:
        raise UntrustedFileError(f"{path}: not valid TOML (nested too deeply)") from None


def read_json_object(path: Path, root: Path | None = None) -> dict[str, Any]:
    """A JSON object of at most :data:`MAX_TEXT_BYTES` (anything else, NaN too, is refused)."""
    return parse_json_object(read_bytes(path, MAX_TEXT_BYTES, root), Path(path))


MAX_CSV_BYTES = 64 << 20
"""Largest CSV log read (64 MiB: a long run's monitor files are a few MB)."""


def read_csv(
    path: Path, types: dict[str, type], root: Path | None = None, comment_lines: int = 0
) -> list[dict[str, Any]]:
    """A bounded CSV log's rows, each of ``types``' columns converted (finite numbers).

    ``comment_lines``: leading lines to skip (SB3's monitor files start with one). A missing
    column, a value of the wrong kind or a non-finite number is refused naming the row.
    """
    import csv

    data = read_bytes(path, MAX_CSV_BYTES, root)
    try:
        lines = data.decode("utf-8").splitlines()[comment_lines:]
    except UnicodeDecodeError:
        raise UntrustedFileError(f"{path}: not UTF-8 text") from None
    try:
        reader = csv.DictReader(lines)
        missing = sorted(set(types) - set(reader.fieldnames or []))
        if missing:
            raise UntrustedFileError(f"{path}: no column {missing[0]!r}")
        rows = []
        for raw in reader:
            row = {}
            for k, kind in types.items():
                v = kind(raw[k])
                if isinstance(v, float) and not np.isfinite(v):
                    raise ValueError(f"{k} = {raw[k]!r}")
                row[k] = v
            rows.append(row)
    except (ValueError, TypeError, OverflowError, RecursionError, csv.Error) as e:
        if isinstance(e, UntrustedFileError):
            raise
        raise UntrustedFileError(f"{path}: row {len(rows) + 2 + comment_lines}: a malformed "
                                 f"value ({str(e)[:60]})") from None  # fmt: skip
    return rows


# ------------------------------------------------------------------------- npz
MAX_NPY_HEADER = 4096
"""Largest .npy header parsed (ours are 128 bytes); read by the project's own code."""
_NPY_DTYPES = {"<f8": np.float64, "<f4": np.float32, "<i8": np.int64, "<i4": np.int32}


def _npy_array(fh, name: str, max_bytes: int) -> tuple[np.ndarray, int]:
    """One .npy stream parsed by length-checked code: magic, a bounded header, exact data.

    numpy's own reader is never called: it would read a header of any declared length first.
    Only little-endian float64/float32/int64/int32 in C order are accepted. Returns the
    array and the bytes its header and data take.
    """
    magic = fh.read(8)
    if len(magic) != 8 or magic[:6] != b"\x93NUMPY" or magic[6] not in (1, 2, 3):
        raise ValueError("not an npy array")
    width = 2 if magic[6] == 1 else 4
    raw = fh.read(width)
    if len(raw) != width:
        raise ValueError("truncated header")
    (n,) = struct.unpack("<H" if width == 2 else "<I", raw)
    if n > MAX_NPY_HEADER:
        raise ValueError(f"a header of {n} bytes (at most {MAX_NPY_HEADER})")
    text = fh.read(n)
    if len(text) != n:
        raise ValueError("truncated header")
    try:
        header = ast.literal_eval(text.decode("latin1").strip())
    except (ValueError, SyntaxError, RecursionError, MemoryError, UnicodeDecodeError):
        raise ValueError("a malformed header") from None
    if not isinstance(header, dict) or set(header) != {"descr", "fortran_order", "shape"}:
        raise ValueError("a malformed header")
    descr, fortran, shape = header["descr"], header["fortran_order"], header["shape"]
    if not isinstance(descr, str) or descr not in _NPY_DTYPES:
        raise ValueError(f"dtype {str(descr)[:20]!r} (plain little-endian numbers only)")
    if fortran is not False:
        raise ValueError("Fortran order")
    if (
        not isinstance(shape, tuple)
        or len(shape) > 8
        or not all(isinstance(d, int) and not isinstance(d, bool) and 0 <= d < 2**40 for d in shape)
    ):
        raise ValueError("a malformed shape")
    dtype = np.dtype(_NPY_DTYPES[descr])
    n_bytes = math.prod(shape) * dtype.itemsize
    if n_bytes > max_bytes:
        raise UntrustedFileError(f"{name} holds {n_bytes} bytes of data, more than {max_bytes}")
    data = fh.read(n_bytes)
    if len(data) != n_bytes:
        raise ValueError(f"{len(data)} bytes of data for {n_bytes}")
    return np.frombuffer(data, dtype=dtype).reshape(shape), 8 + width + n + n_bytes


def read_npz(
    path: Path,
    spec: dict[str, tuple[tuple[int | None, ...], str]],
    root: Path | None = None,
    max_bytes: int = MAX_NPZ_BYTES,
    data: bytes | None = None,
) -> dict[str, np.ndarray]:
    """The arrays of an npz, each checked against ``spec`` before its data is read.

    ``spec``: member name -> (shape, dtype kind) with ``None`` for a free dimension and kind
    ``"f"`` (float) or ``"i"`` (integer). Missing or extra members, another shape or kind, a
    member stored encrypted or compressed by anything but deflate, a declared size that does
    not match the header, a non-finite float and a pickled (object) array are refused.
    ``data``: the file's bytes, already read (``path`` then only names it). Arrays come back
    as float64 / int64.
    """
    if data is None:
        data = read_bytes(path, max_bytes, root)  # size, regular file, no symlink
    out = {}
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            infos = {i.filename.removesuffix(".npy"): i for i in zf.infolist()}
            if set(infos) != set(spec) or len(infos) != len(zf.infolist()):
                raise UntrustedFileError(
                    f"{path}: holds {sorted(infos)[:8]}, expected exactly {sorted(spec)}"
                )
            for name, (shape, kind) in spec.items():
                info = infos[name]
                if info.flag_bits & 0x1 or info.compress_type not in (
                    zipfile.ZIP_STORED,
                    zipfile.ZIP_DEFLATED,
                ):
                    raise UntrustedFileError(f"{path}: {name} is encrypted or oddly compressed")
                if info.file_size > max_bytes + MAX_NPY_HEADER + 16:
                    raise UntrustedFileError(
                        f"{path}: {name} declares {info.file_size} bytes, more than {max_bytes}"
                    )
                try:
                    with zf.open(info) as fh:
                        arr, used = _npy_array(fh, f"{path}: {name}", max_bytes)
                    if info.file_size != used:
                        raise UntrustedFileError(
                            f"{path}: {name} stores {info.file_size} bytes for {used}"
                        )
                except ValueError as e:
                    if isinstance(e, UntrustedFileError):
                        raise
                    raise UntrustedFileError(
                        f"{path}: {name} is no plain npy array ({e})"
                    ) from None
                got = arr.shape
                ok = len(got) == len(shape) and all(
                    w is None or w == g for w, g in zip(shape, got, strict=True)
                )
                if not ok or arr.dtype.kind != kind:
                    raise UntrustedFileError(
                        f"{path}: {name} is {arr.dtype} {got}, expected kind {kind!r} shape "
                        f"{tuple('any' if w is None else w for w in shape)}"
                    )
                arr = arr.astype(np.float64 if kind == "f" else np.int64)
                if kind == "f" and not np.all(np.isfinite(arr)):
                    raise UntrustedFileError(f"{path}: {name} holds NaN or inf")
                out[name] = arr
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError,
            NotImplementedError, RuntimeError) as e:  # fmt: skip
        raise UntrustedFileError(f"{path}: not a valid npz ({str(e)[:80]})") from None
    return out


# ------------------------------------------------------------------------- safetensors
_ST_DTYPES = {"F32": 4, "F64": 8, "F16": 2, "BF16": 2, "I64": 8, "I32": 4}


def safetensors_header(
    path: Path, root: Path | None = None, data: bytes | None = None
) -> tuple[dict[str, tuple[int, ...]], dict[str, str]]:
    """(tensor shapes, metadata) from a safetensors file's header, checked against its size.

    Reads only the header (no tensor is allocated). Refuses a header over
    :data:`MAX_HEADER_BYTES`, a file over :data:`MAX_WEIGHTS_BYTES`, an unknown dtype,
    offsets that do not tile the data exactly and metadata that is not a table of strings.
    ``data``: the file's bytes, already read.
    """
    if data is None:
        data = read_bytes(path, MAX_WEIGHTS_BYTES, root)
    size = len(data)
    if size > MAX_WEIGHTS_BYTES:
        raise UntrustedFileError(f"{path}: {size} bytes, more than {MAX_WEIGHTS_BYTES} allowed")
    if size < 8:
        raise UntrustedFileError(f"{path}: truncated (no safetensors header)")
    (n,) = struct.unpack("<Q", data[:8])
    if n > min(MAX_HEADER_BYTES, size - 8):
        raise UntrustedFileError(f"{path}: header of {n} bytes in a {size}-byte file")
    try:
        header = json.loads(data[8 : 8 + n].decode("utf-8"))
    except (ValueError, RecursionError):
        raise UntrustedFileError(f"{path}: the safetensors header is not JSON") from None
    if not isinstance(header, dict):
        raise UntrustedFileError(f"{path}: the safetensors header is not a JSON object")
    meta = header.get("__metadata__", {})
    if not isinstance(meta, dict) or not all(isinstance(v, str) for v in meta.values()):
        raise UntrustedFileError(f"{path}: the safetensors metadata is not a table of strings")
    shapes, spans = {}, []
    for name, entry in header.items():
        if name == "__metadata__":
            continue
        try:
            dtype, shape, (a, b) = entry["dtype"], tuple(entry["shape"]), entry["data_offsets"]
            ok = (
                dtype in _ST_DTYPES
                and len(shape) <= 8
                and all(type(d) is int and 0 <= d < 2**40 for d in (*shape, a, b))
                and set(entry) == {"dtype", "shape", "data_offsets"}
            )
            ok = ok and b - a == math.prod(shape) * _ST_DTYPES[dtype]
        except (TypeError, KeyError, ValueError):
            ok = False
        if not ok:
            raise UntrustedFileError(f"{path}: tensor {name!r} has a malformed header entry")
        shapes[name] = shape
        spans.append((a, b))
    spans.sort()
    end = 0
    for a, b in spans:
        if a != end:
            raise UntrustedFileError(f"{path}: tensor offsets overlap or leave gaps")
        end = b
    if 8 + n + end != size:
        raise UntrustedFileError(f"{path}: {size} bytes, the header describes {8 + n + end}")
    return shapes, dict(meta)


def safetensors_shapes(path: Path, root: Path | None = None) -> dict[str, tuple[int, ...]]:
    """Tensor shapes from a safetensors file's header (:func:`safetensors_header`)."""
    return safetensors_header(path, root)[0]


def load_safetensors(path: Path, data: bytes) -> dict[str, Any]:
    """The tensors of a safetensors file's bytes (header checked first; torch tensors)."""
    safetensors_header(path, data=data)
    from safetensors.torch import load

    try:
        return load(data)
    except Exception as e:  # the Rust parser's own refusal (SafetensorError)
        raise UntrustedFileError(f"{path}: refused by the safetensors parser ({e})") from None


# ------------------------------------------------------------------------- snapshots
SNAPSHOT_FILES = {
    "policy.safetensors": MAX_WEIGHTS_BYTES,
    "optimizer.safetensors": MAX_WEIGHTS_BYTES,
    "normalizer.npz": 1 << 20,
    "state.json": MAX_TEXT_BYTES,
    "data.npz": MAX_WEIGHTS_BYTES,
    "demos.npz": MAX_WEIGHTS_BYTES,
}
"""The files a snapshot may hold, each with its largest size [bytes]."""


class Snapshot:
    """A snapshot's files read once into memory, each checked against the manifest's hash.

    Everything a load parses comes from :attr:`files`, so a snapshot replaced while it is
    loaded gives the old files or the new ones, never a mix.
    """

    def __init__(self, path: Path, files: dict[str, bytes]):
        self.path, self.files = Path(path), files

    def __contains__(self, name: str) -> bool:
        return name in self.files

    def name(self, name: str) -> Path:
        """The path of the snapshot's file ``name`` (for messages)."""
        return self.path / name

    def json(self, name: str) -> dict[str, Any]:
        """The snapshot's JSON file ``name``, parsed from the bytes read."""
        return parse_json_object(self.files[name], self.path / name)


def parse_json_object(data: bytes, path: Path) -> dict[str, Any]:
    """A JSON object from bytes (standard JSON: NaN and Infinity refused)."""

    def no_constant(c):
        raise ValueError(f"{c} is not JSON")

    try:
        out = json.loads(data.decode("utf-8"), parse_constant=no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise UntrustedFileError(f"{path}: not valid JSON ({str(e)[:80]})") from None
    if not isinstance(out, dict):
        raise UntrustedFileError(f"{path}: a JSON object expected, got {type(out).__name__}")
    return out


def _read_in(dir_fd: int | None, name: str, path: Path, limit: int) -> bytes:
    import stat as st_

    try:  # the kind checked before it is opened: opening a device or a FIFO can act
        pre = os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
        if st_.S_ISLNK(pre.st_mode):
            raise UntrustedFileError(f"{path}: a symlink")
        if not st_.S_ISREG(pre.st_mode):
            raise UntrustedFileError(f"{path}: not a regular file")
        fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC,
                     dir_fd=dir_fd)  # fmt: skip
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing") from None
    except OSError as e:
        why = "a symlink" if e.errno == errno.ELOOP else f"not a regular file ({e.strerror})"
        raise UntrustedFileError(f"{path}: {why}") from None
    try:
        st = os.fstat(fd)
        if not st_.S_ISREG(st.st_mode):
            raise UntrustedFileError(f"{path}: not a regular file")
        if st.st_size > limit:
            raise UntrustedFileError(f"{path}: {st.st_size} bytes, more than {limit} allowed")
        with os.fdopen(os.dup(fd), "rb") as fh:  # the size read, not the limit: read(n)
            data = fh.read(st.st_size + 1)  # allocates n bytes before it reads
        if len(data) > limit:
            raise UntrustedFileError(f"{path}: grew past {limit} bytes while it was read")
        return data
    finally:
        os.close(fd)


def read_snapshot(where: Path) -> Snapshot:
    """Every file a snapshot's manifest lists, read once through one descriptor and hashed.

    Files the manifest does not list are never opened. Raises FileNotFoundError (no such
    snapshot, or no manifest: incomplete) or :class:`UntrustedFileError` (a link, an odd
    file, a size or hash that differs from the manifest).
    """
    real = Path(where)
    where = shown(real)
    try:
        dfd = os.open(real, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except FileNotFoundError:
        raise FileNotFoundError(f"{where}: missing") from None
    except OSError as e:
        raise UntrustedFileError(f"{where}: not a directory (or a symlink: {e.strerror})") from None
    try:
        entries = parse_json_object(
            _read_in(dfd, MANIFEST_FILE, where / MANIFEST_FILE, MAX_TEXT_BYTES),
            where / MANIFEST_FILE,
        )
        if len(entries) > 16:
            raise UntrustedFileError(f"{where}: {len(entries)} files (a snapshot has at most 16)")
        files, total = {}, 0
        for name, meta in entries.items():
            if name not in SNAPSHOT_FILES:
                raise UntrustedFileError(f"{where / MANIFEST_FILE}: lists {name[:40]!r}, not a "
                                         f"snapshot file {sorted(SNAPSHOT_FILES)}")  # fmt: skip
            p = where / name
            if not isinstance(meta, dict) or type(meta.get("bytes")) is not int:
                raise UntrustedFileError(f"{p}: a malformed manifest entry")
            total += meta["bytes"]
            if not 0 <= meta["bytes"] <= SNAPSHOT_FILES[name] or total > MAX_NPZ_BYTES:
                raise UntrustedFileError(f"{p}: the manifest declares {meta['bytes']} bytes, "
                                         f"more than allowed")  # fmt: skip
            data = _read_in(dfd, name, p, meta["bytes"])
            if len(data) != meta["bytes"]:
                raise UntrustedFileError(f"{p}: {len(data)} bytes, the manifest says "
                                         f"{meta['bytes']}")  # fmt: skip
            if hashlib.sha256(data).hexdigest() != meta.get("sha256"):
                raise UntrustedFileError(f"{p}: its SHA-256 differs from the manifest's")
            files[name] = data
    finally:
        os.close(dfd)
    return Snapshot(where, files)


def verify_manifest(where: Path) -> str | None:
    """None when ``where`` is a complete, intact snapshot; else what is wrong ("missing")."""
    where = Path(where)
    if not os.path.lexists(where):
        return "missing"
    try:
        read_snapshot(where)
    except FileNotFoundError as e:
        return "missing" if str(e).endswith(f"{where}: missing") else str(e)
    except UntrustedFileError as e:
        return str(e)
    return None
