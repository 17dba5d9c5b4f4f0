"""Files from anywhere: bounded, checked reads; atomic outputs; manifests; a run's lock.

A policy or run directory is data from anywhere (docs/policies.md, "Threat model"). Every
read here is bounded before it happens: a file's size is checked before it is read, an npz
member's shape, dtype and stored size before its data is read, a safetensors header before
any tensor is allocated. Nothing here imports, unpickles or follows a symlink out of the
directory it was given. A refusal is an :class:`UntrustedFileError`: one line naming the file
and what was expected; the commands print it and exit with status 2.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import socket
import struct
import tempfile
import tomllib
import zipfile
from collections.abc import Iterator
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
    """A regular file's bytes, refused when larger than ``limit`` or a symlink."""
    path = Path(path)
    if root is not None:
        inside(root, path)
    if path.is_symlink():
        raise UntrustedFileError(f"{path}: a symlink (policy and run directories hold none)")
    if not path.is_file():
        raise UntrustedFileError(f"{path}: missing (or not a regular file)")
    size = path.stat().st_size
    if size > limit:
        raise UntrustedFileError(f"{path}: {size} bytes, more than the {limit} allowed")
    with open(path, "rb") as fh:
        return fh.read(limit + 1)[:limit]


def read_toml(path: Path, root: Path | None = None) -> dict[str, Any]:
    """A TOML file of at most :data:`MAX_TEXT_BYTES`, parsed (a refusal names the file)."""
    data = read_bytes(path, MAX_TEXT_BYTES, root)
    try:
        return tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise UntrustedFileError(f"{path}: not valid TOML ({e})") from None


def read_json_object(path: Path, root: Path | None = None) -> dict[str, Any]:
    """A JSON object of at most :data:`MAX_TEXT_BYTES` (anything else is refused)."""
    data = read_bytes(path, MAX_TEXT_BYTES, root)
    try:
        out = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise UntrustedFileError(f"{path}: not valid JSON ({str(e)[:80]})") from None
    if not isinstance(out, dict):
        raise UntrustedFileError(f"{path}: a JSON object expected, got {type(out).__name__}")
    return out


# ------------------------------------------------------------------------- npz
def _npy_header(zf: zipfile.ZipFile, info: zipfile.ZipInfo) -> tuple[tuple, np.dtype]:
    """Shape and dtype of one .npy member, read from its header alone."""
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ValueError(f"npy version {version}")
    if fortran:
        raise ValueError("Fortran order")
    return shape, dtype


def read_npz(
    path: Path,
    spec: dict[str, tuple[tuple[int | None, ...], str]],
    root: Path | None = None,
    max_bytes: int = MAX_NPZ_BYTES,
) -> dict[str, np.ndarray]:
    """The arrays of an npz, each checked against ``spec`` before its data is read.

    ``spec``: member name -> (shape, dtype kind) with ``None`` for a free dimension and kind
    ``"f"`` (float) or ``"i"`` (integer). Missing or extra members, another shape or kind, a
    stored size that does not match the header, a non-finite float and a pickled (object)
    array are refused. Arrays come back as float64 / int64.
    """
    read_bytes(path, max_bytes, root)  # size, regular file, no symlink
    out = {}
    try:
        with zipfile.ZipFile(path) as zf:
            infos = {i.filename.removesuffix(".npy"): i for i in zf.infolist()}
            if set(infos) != set(spec):
                raise UntrustedFileError(
                    f"{path}: holds {sorted(infos)}, expected exactly {sorted(spec)}"
                )
            for name, (shape, kind) in spec.items():
                info = infos[name]
                try:
                    got, dtype = _npy_header(zf, info)
                except ValueError as e:
                    raise UntrustedFileError(
                        f"{path}: {name} is no plain npy array ({e})"
                    ) from None
                ok = len(got) == len(shape) and all(
                    w is None or w == g for w, g in zip(shape, got, strict=True)
                )
                if not ok or dtype.kind != kind or dtype.hasobject:
                    raise UntrustedFileError(
                        f"{path}: {name} is {dtype} {got}, expected kind {kind!r} shape "
                        f"{tuple('any' if w is None else w for w in shape)}"
                    )
                n_bytes = int(np.prod(got, dtype=np.int64)) * dtype.itemsize
                if n_bytes > max_bytes:
                    raise UntrustedFileError(
                        f"{path}: {name} holds {n_bytes} bytes of data, more than {max_bytes}"
                    )
                if info.file_size > n_bytes + 4096:
                    raise UntrustedFileError(
                        f"{path}: {name} stores {info.file_size} bytes for {n_bytes} of data"
                    )
                with zf.open(info) as fh:
                    arr = np.lib.format.read_array(fh, allow_pickle=False)
                arr = arr.astype(np.float64 if kind == "f" else np.int64)
                if kind == "f" and not np.all(np.isfinite(arr)):
                    raise UntrustedFileError(f"{path}: {name} holds NaN or inf")
                out[name] = arr
    except (zipfile.BadZipFile, EOFError, OSError) as e:
        raise UntrustedFileError(f"{path}: not a valid npz ({e})") from None
    return out


# ------------------------------------------------------------------------- safetensors
_ST_DTYPES = {"F32": 4, "F64": 8, "F16": 2, "BF16": 2, "I64": 8, "I32": 4}


def safetensors_shapes(path: Path, root: Path | None = None) -> dict[str, tuple[int, ...]]:
    """Tensor shapes from a safetensors file's header, checked against the file's size.

    Reads only the header (no tensor is allocated). Refuses a header over
    :data:`MAX_HEADER_BYTES`, a file over :data:`MAX_WEIGHTS_BYTES`, an unknown dtype, and
    offsets that do not tile the data exactly.
    """
    path = Path(path)
    if root is not None:
        inside(root, path)
    if path.is_symlink() or not path.is_file():
        raise UntrustedFileError(f"{path}: missing (or not a regular file)")
    size = path.stat().st_size
    if size > MAX_WEIGHTS_BYTES:
        raise UntrustedFileError(f"{path}: {size} bytes, more than {MAX_WEIGHTS_BYTES} allowed")
    with open(path, "rb") as fh:
        raw = fh.read(8)
        if len(raw) < 8:
            raise UntrustedFileError(f"{path}: truncated (no safetensors header)")
        (n,) = struct.unpack("<Q", raw)
        if n > min(MAX_HEADER_BYTES, size - 8):
            raise UntrustedFileError(f"{path}: header of {n} bytes in a {size}-byte file")
        try:
            header = json.loads(fh.read(n))
        except ValueError:
            raise UntrustedFileError(f"{path}: the safetensors header is not JSON") from None
    if not isinstance(header, dict):
        raise UntrustedFileError(f"{path}: the safetensors header is not a JSON object")
    shapes, spans = {}, []
    for name, entry in header.items():
        if name == "__metadata__":
            continue
        try:
            dtype, shape, (a, b) = entry["dtype"], tuple(entry["shape"]), entry["data_offsets"]
            ok = dtype in _ST_DTYPES and all(isinstance(d, int) and d >= 0 for d in shape)
            ok = ok and b - a == int(np.prod(shape, dtype=np.int64)) * _ST_DTYPES[dtype]
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
    return shapes


# ------------------------------------------------------------------------- manifests
def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_manifest(where: Path) -> None:
    """Record every file of ``where`` (size, SHA-256) in its manifest, written last."""
    where = Path(where)
    files = sorted(p for p in where.iterdir() if p.is_file() and p.name != MANIFEST_FILE)
    entries = {p.name: {"bytes": p.stat().st_size, "sha256": _sha256(p)} for p in files}
    tmp = where / (MANIFEST_FILE + ".tmp")
    tmp.write_text(json.dumps(entries, indent=1, sort_keys=True) + "\n")
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    tmp.rename(where / MANIFEST_FILE)


def verify_manifest(where: Path) -> str | None:
    """None when ``where`` holds exactly its manifest's files, intact; else what is wrong."""
    where = Path(where)
    if where.is_symlink() or not where.is_dir():
        return "missing"
    try:
        entries = read_json_object(where / MANIFEST_FILE)
    except UntrustedFileError as e:
        return str(e)
    for name, meta in entries.items():
        p = where / name
        if "/" in name or p.is_symlink() or not p.is_file() or not isinstance(meta, dict):
            return f"{p}: missing"
        if p.stat().st_size != meta.get("bytes"):
            return f"{p}: {p.stat().st_size} bytes, the manifest says {meta.get('bytes')}"
        if _sha256(p) != meta.get("sha256"):
            return f"{p}: its SHA-256 differs from the manifest's"
    return None


# ------------------------------------------------------------------------- outputs
@contextlib.contextmanager
def atomic_output(out: Path) -> Iterator[Path]:
    """Write a whole output directory or nothing: yields a fresh temporary directory to fill.

    The directory is created beside ``out`` (same file system) with a private name; on
    success it replaces ``out`` (an older ``out`` is removed only after the rename), on any
    exception or interrupt it is deleted, leaving the old ``out`` as it was. ``out`` must not
    be a symlink; nothing inside the temporary directory existed before, so no write follows
    a link planted by someone else.
    """
    out = Path(out)
    if out.is_symlink():
        raise UntrustedFileError(f"{out}: a symlink; give a real directory as the output")
    if out.exists() and not out.is_dir():
        raise UntrustedFileError(f"{out}: exists and is not a directory")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        yield tmp
        old = None
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
            out.rename(old / "x")
        tmp.rename(out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


# ------------------------------------------------------------------------- lock
class RunLock:
    """An exclusive lock on a run directory (``RUN/.lock``, ``flock``): one writer at a time.

    The kernel releases it when the holder exits, however it exits (SIGKILL included), so a
    stale lock never blocks a resume. A second writer is refused with the holder's pid.
    """

    def __init__(self, run: Path):
        self.path = Path(run) / ".lock"
        self.fd: int | None = None

    def __enter__(self) -> RunLock:
        if self.path.is_symlink():
            raise UntrustedFileError(f"{self.path}: a symlink")
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise UntrustedFileError(
                f"{self.path.parent}: in use by {holder}; one writer at a time"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
        self.fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            os.close(self.fd)  # releases the flock
            self.fd = None
