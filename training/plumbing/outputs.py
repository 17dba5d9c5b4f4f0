"""The one way every command writes: a directory opened once, files that never follow a link.

:class:`OutDir` is a directory held open by a file descriptor (opened with ``O_NOFOLLOW``).
Every file is created through that descriptor (``dir_fd`` operations) with ``O_EXCL`` and
``O_NOFOLLOW`` under a private temporary name, written whole, flushed and renamed into place,
so a link planted anywhere in the directory is replaced, never written through, and a kill
leaves the old file or the new one, never half of one. Appends (a run's CSV logs) refuse
anything but a regular file with one link. Libraries that only take a path (matplotlib,
safetensors, SB3's monitor, TensorBoard) are given ``/proc/self/fd/N/NAME``, a path that
resolves through the held descriptor, not through the directory's name again.

:func:`command_output` is the ``--out DIR`` of a command: DIR is new, empty, or holds only
what commands of this package wrote there (listed in its marker, :data:`MARKER`); anything
else is refused in one line before any work is done. The command's files are staged in a
temporary directory inside DIR and moved into place when the command succeeds; a file of
the same command from an earlier run is replaced, and files of other commands are left as
they are. Nothing outside DIR is created, appended to or deleted.

:class:`RunLock` takes a run directory's lock through the same descriptor, and
:func:`check_tree` refuses a run directory that holds a link, a FIFO, a device, a hard-linked
file or more entries than a run writes.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import io
import json
import os
import re
import secrets
import shutil
import socket
import stat
from collections.abc import Iterator
from pathlib import Path

from training.plumbing import interrupts
from training.plumbing.safe_files import MAX_TEXT_BYTES, SHOWN, UntrustedFileError, shown

MARKER = ".written_by.json"
"""An output directory's record of its files and the command that wrote each one."""
STAGING = ".staging-"
"""Prefix of a command's temporary directory inside its output (removed when it ends)."""
MAX_TREE_ENTRIES = 20_000
"""Most files and directories a run or output directory may hold (a long run has a few hundred)."""
MAX_TREE_DEPTH = 8
_DIR_FLAGS = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC


class OutputError(UntrustedFileError):
    """An output that cannot be written safely (one line: the path and why)."""


def _name(name: str) -> str:
    if not name or "/" in name or name in (".", "..") or "\0" in name:
        raise ValueError(f"not a plain file name: {name!r}")
    return name


class OutDir:
    """A directory held open: every write goes through its descriptor, never through a link."""

    def __init__(self, fd: int, path: Path):
        self.fd, self.path = fd, shown(path)
        SHOWN[fd] = self.path

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, path: Path, create: bool = True) -> OutDir:
        """``path`` opened as a directory; with ``create``, made first (parents included).

        Refuses a ``path`` that is a symlink or not a directory.
        """
        path = Path(path)
        named = shown(path)
        if create and not os.path.lexists(path):
            try:
                path.mkdir(parents=True)
            except FileExistsError:
                pass
            except OSError as e:
                raise OutputError(f"{named}: cannot create it ({e.strerror})") from None
        flags = _DIR_FLAGS
        if path.parent == Path("/proc/self/fd"):  # a descriptor of our own (OutDir.where)
            flags &= ~os.O_NOFOLLOW
        try:
            return cls(os.open(path, flags), path)
        except OSError as e:
            if os.path.islink(path):
                raise OutputError(f"{named}: a symlink (give a directory, not a link)") from None
            raise OutputError(f"{named}: {_why(e, 'a directory')}") from None

    def subdir(self, name: str, create: bool = True) -> OutDir:
        """The directory ``name`` inside this one (made when missing, with ``create``)."""
        _name(name)
        if create:
            with contextlib.suppress(FileExistsError):
                os.mkdir(name, 0o755, dir_fd=self.fd)
        try:
            return OutDir(os.open(name, _DIR_FLAGS, dir_fd=self.fd), self.path / name)
        except OSError as e:
            with contextlib.suppress(OSError):
                if stat.S_ISLNK(os.stat(name, dir_fd=self.fd, follow_symlinks=False).st_mode):
                    raise OutputError(f"{self.path / name}: a symlink (a directory belongs "
                                      f"here, not a link)") from None  # fmt: skip
            raise OutputError(f"{self.path / name}: {_why(e, 'a directory')}") from None

    def close(self) -> None:
        """Release the descriptor (idempotent)."""
        if self.fd >= 0:
            SHOWN.pop(self.fd, None)
            os.close(self.fd)
            self.fd = -1

    def __enter__(self) -> OutDir:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):
        with contextlib.suppress(Exception):
            self.close()

    # ------------------------------------------------------------------ reading the listing
    def where(self, name: str = "") -> str:
        """A path that resolves through the held descriptor (for path-only libraries)."""
        base = f"/proc/self/fd/{self.fd}"
        return f"{base}/{_name(name)}" if name else base

    def kind(self, name: str) -> str | None:
        """The entry's kind: "file", "dir" or None (missing); anything else is refused."""
        try:
            st = os.stat(_name(name), dir_fd=self.fd, follow_symlinks=False)
        except FileNotFoundError:
            return None
        if stat.S_ISDIR(st.st_mode):
            return "dir"
        if stat.S_ISREG(st.st_mode) and st.st_nlink == 1:
            return "file"
        raise OutputError(f"{self.path / name}: {_describe(st)}; only plain files belong here")

    def names(self) -> list[str]:
        """The entries of the directory, sorted."""
        return sorted(os.listdir(self.fd))

    def read_text(self, name: str, limit: int = MAX_TEXT_BYTES) -> str:
        """A regular file's text (bounded; never through a link)."""
        fd = self._open_regular(name, os.O_RDONLY)
        try:
            size = os.fstat(fd).st_size
            if size > limit:
                raise OutputError(f"{self.path / name}: {size} bytes, more than {limit} allowed")
            with os.fdopen(os.dup(fd), "rb") as fh:
                data = fh.read(limit + 1)
        finally:
            os.close(fd)
        try:
            return data.decode("utf-8")
        except UnicodeDecodeError:
            raise OutputError(f"{self.path / name}: not UTF-8 text") from None

    # ------------------------------------------------------------------ writing
    def write(self, name: str, data: bytes | str) -> None:
        """Write ``name`` whole: a private temporary file, flushed, renamed over ``name``."""
        if isinstance(data, str):
            data = data.encode("utf-8")
        tmp, fd = self.new_temp(name)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            self.replace(tmp, name)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp, dir_fd=self.fd)
            raise

    @contextlib.contextmanager
    def writing(self, name: str) -> Iterator[str]:
        """For a path-only library: yields a fresh temporary path here, renamed to ``name`` after.

        The library writes a new file (``O_EXCL`` made it ours), through the held descriptor.
        """
        tmp, fd = self.new_temp(name)
        os.close(fd)
        try:
            yield self.where(tmp)
            fd = os.open(tmp, os.O_RDONLY | os.O_NOFOLLOW, dir_fd=self.fd)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            self.replace(tmp, name)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp, dir_fd=self.fd)
            raise

    def savefig(self, name: str, fig, **kw) -> None:
        """A matplotlib figure written whole as ``name`` (format from its suffix)."""
        buf = io.BytesIO()
        fig.savefig(buf, format=Path(name).suffix.lstrip(".") or "png", **kw)
        self.write(name, buf.getvalue())

    def append(self, name: str, text: str) -> None:
        """Append to ``name`` (created when missing): a regular file of one link, or refused."""
        fd = self._open_regular(name, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
        try:
            data = text.encode("utf-8")
            while data:
                data = data[os.write(fd, data) :]
            os.fsync(fd)
        finally:
            os.close(fd)

    def truncate(self, name: str, size: int) -> None:
        """Cut the plain file ``name`` to ``size`` bytes."""
        fd = self._open_regular(name, os.O_WRONLY)
        try:
            os.ftruncate(fd, size)
            os.fsync(fd)
        finally:
            os.close(fd)

    def create_new(self, name: str) -> None:
        """Create ``name`` empty; FileExistsError when anything (a dangling link too) is there."""
        fd = os.open(_name(name), os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                     | os.O_CLOEXEC, 0o644, dir_fd=self.fd)  # fmt: skip
        os.close(fd)

    def new_temp(self, name: str) -> tuple[str, int]:
        """A new private file beside ``name``: (its name, a descriptor open for writing)."""
        _name(name)
        for _ in range(100):
            tmp = f".{name[:80]}.tmp-{os.getpid()}-{secrets.token_hex(4)}"
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                             | os.O_CLOEXEC, 0o644, dir_fd=self.fd)  # fmt: skip
                return tmp, fd
            except FileExistsError:
                continue
            except OSError as e:
                raise OutputError(f"{self.path}: cannot write ({e.strerror})") from None
        raise OutputError(f"{self.path}: no free temporary name")

    def replace(self, src: str, dst: str, into: OutDir | None = None) -> None:
        """Rename ``src`` here to ``dst`` here (or in ``into``); a link at ``dst`` is replaced."""
        os.rename(_name(src), _name(dst), src_dir_fd=self.fd,
                  dst_dir_fd=(into or self).fd)  # fmt: skip

    def remove(self, name: str) -> None:
        """Delete ``name`` (a file, or a directory with everything in it); never follows links."""
        try:
            st = os.stat(_name(name), dir_fd=self.fd, follow_symlinks=False)
        except FileNotFoundError:
            return
        if stat.S_ISDIR(st.st_mode):
            shutil.rmtree(name, dir_fd=self.fd)
        else:
            os.unlink(name, dir_fd=self.fd)

    def fsync(self) -> None:
        """Flush the directory's entries (renames) to disk."""
        os.fsync(self.fd)

    # ------------------------------------------------------------------ helpers
    def _open_regular(self, name: str, flags: int) -> int:
        path = self.path / name
        try:  # refused before it is opened: opening a device or a FIFO can act
            st = os.stat(_name(name), dir_fd=self.fd, follow_symlinks=False)
            if not (stat.S_ISREG(st.st_mode) and st.st_nlink == 1):
                raise OutputError(f"{path}: {_describe(st)}; only plain files belong here")
            flags &= ~os.O_CREAT  # it exists: opened as the file just checked
        except FileNotFoundError:
            if flags & os.O_CREAT:
                flags |= os.O_EXCL  # a new file: nothing may appear there in between
        try:
            fd = os.open(_name(name), flags | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC,
                         0o644, dir_fd=self.fd)  # fmt: skip
        except OSError as e:
            raise OutputError(f"{path}: {_why(e, 'a regular file')}") from None
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1:
            os.close(fd)
            raise OutputError(f"{path}: {_describe(st)}; only plain files belong here")
        return fd


def _describe(st: os.stat_result) -> str:
    if stat.S_ISLNK(st.st_mode):
        return "a symlink"
    if stat.S_ISFIFO(st.st_mode):
        return "a FIFO"
    if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode):
        return "a device"
    if stat.S_ISSOCK(st.st_mode):
        return "a socket"
    if stat.S_ISREG(st.st_mode) and st.st_nlink != 1:
        return f"a file with {st.st_nlink} hard links"
    if stat.S_ISDIR(st.st_mode):
        return "a directory"
    return "not a regular file"


def _why(e: OSError, what: str) -> str:
    if e.errno == errno.ELOOP:
        return f"a symlink (give {what}, not a link)"
    if e.errno == errno.ENOTDIR:
        return f"not {what}"
    if e.errno == errno.EISDIR:
        return f"a directory, not {what}"
    if e.errno == errno.ENOENT:
        return "missing"
    return f"{e.strerror}"


def check_tree(root: OutDir, max_entries: int = MAX_TREE_ENTRIES) -> int:
    """Refuse a directory holding anything but plain files and directories: its entry count.

    A symlink, FIFO, socket, device or hard-linked file anywhere below ``root``, more than
    ``max_entries`` entries or deeper than :data:`MAX_TREE_DEPTH` is an :class:`OutputError`.
    """
    count = 0

    def walk(fd: int, path: Path, depth: int) -> None:
        nonlocal count
        if depth > MAX_TREE_DEPTH:
            raise OutputError(f"{path}: nested deeper than {MAX_TREE_DEPTH} directories")
        with os.scandir(fd) as it:
            entries = []
            for entry in it:  # counted as read: a folder of millions is not listed first
                entries.append(entry)
                if count + len(entries) > max_entries:
                    raise OutputError(f"{root.path}: more than {max_entries} entries")
        for entry in entries:
            count += 1
            if count > max_entries:
                raise OutputError(f"{root.path}: more than {max_entries} entries")
            st = entry.stat(follow_symlinks=False)
            if stat.S_ISDIR(st.st_mode):
                sub = os.open(entry.name, _DIR_FLAGS, dir_fd=fd)
                try:
                    walk(sub, path / entry.name, depth + 1)
                finally:
                    os.close(sub)
            elif not (stat.S_ISREG(st.st_mode) and st.st_nlink == 1):
                raise OutputError(f"{path / entry.name}: {_describe(st)}; a run or output "
                                  f"directory holds only plain files and directories")  # fmt: skip

    walk(root.fd, root.path, 0)
    return count


# ----------------------------------------------------------------------------- command outputs
_STAGING_RE = re.compile(r"\.staging-[A-Za-z0-9_-]+-([0-9]{1,10})-[0-9a-f]{8}")
"""The name of a command's staging folder: the command, its pid, a random tag."""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _listing(d: OutDir, prefix: str = "", skip: set[str] | None = None) -> list[str]:
    """Every file below ``d`` as a relative path (directories by their files; links refused)."""
    out = []
    for name in d.names():
        if skip and name in skip:
            continue
        kind = d.kind(name)
        if kind == "dir":
            with d.subdir(name, create=False) as sub:
                out += _listing(sub, f"{prefix}{name}/")
                if not sub.names():
                    out.append(f"{prefix}{name}/")
        else:
            out.append(prefix + name)
    return out


def _remove_rel(out: OutDir, rel: str) -> None:
    """Delete the file ``rel`` below ``out``, or the folder ``rel`` ("name/") if it is empty.

    A folder that holds anything (another command's files, or this run's own) stays.
    """
    parts = rel.rstrip("/").split("/")
    d = out
    try:
        for part in parts[:-1]:
            if d.kind(part) != "dir":
                return
            d = d.subdir(part, create=False)
        kind = d.kind(parts[-1])
        if rel.endswith("/"):
            if kind == "dir":
                os.rmdir(parts[-1], dir_fd=d.fd)  # only an empty folder: OSError otherwise
        elif kind == "file":
            d.remove(parts[-1])
    except (OSError, ValueError):
        pass


def _read_marker(out: OutDir) -> tuple[dict[str, str], dict[str, str]]:
    """(files: {relative path: command}, sha256: {relative path: digest}) of the record."""
    if out.kind(MARKER) is None:
        return {}, {}
    text = out.read_text(MARKER)
    try:
        record = json.loads(text)
        files, digests = record["files"], record.get("sha256", {})
        for table in (files, digests):
            if not all(isinstance(k, str) and isinstance(v, str) for k, v in table.items()):
                raise TypeError
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError):
        raise OutputError(f"{out.path / MARKER}: not this package's output record") from None
    return dict(files), dict(digests)


def _sha256(d: OutDir, rel: str) -> str | None:
    """The SHA-256 of the plain file ``rel`` below ``d`` (None: not a plain file there)."""
    parts = rel.split("/")
    opened = []
    try:
        for part in parts[:-1]:
            if d.kind(part) != "dir":
                return None
            d = d.subdir(part, create=False)
            opened.append(d)
        if d.kind(parts[-1]) != "file":
            return None
        fd = d._open_regular(parts[-1], os.O_RDONLY)
        h = hashlib.sha256()
        with os.fdopen(fd, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        return h.hexdigest()
    finally:
        for sub in opened:
            sub.close()


class CommandOutput:
    """The output of one command: files staged under a temporary name, moved in at the end.

    Use :func:`command_output`. :meth:`dir` gives the staging directory (or a sub-directory of
    it) to write into with :class:`OutDir`'s methods.
    """

    def __init__(self, out: OutDir, command: str, owned: dict[str, str],
                 digests: dict[str, str] | None = None, staged: bool = True):  # fmt: skip
        self.out, self.command, self.owned = out, command, owned
        self.digests = dict(digests or {})
        self.path = out.path
        self.stage_name = ""
        self.stage = out
        if staged:
            self.stage_name = f"{STAGING}{command}-{os.getpid()}-{secrets.token_hex(4)}"
            os.mkdir(self.stage_name, 0o755, dir_fd=out.fd)
            self.stage = out.subdir(self.stage_name, create=False)

    def dir(self, sub: str = "") -> OutDir:
        """The staging directory, or its sub-directory ``sub`` ("figures"), made when missing."""
        d = self.stage
        for part in Path(sub).parts:
            d = d.subdir(part)
        return d

    def _commit(self) -> list[str]:
        written = _listing(self.stage)
        for rel in written:
            parts = rel.rstrip("/").split("/")
            src, dst = self.stage, self.out
            for part in parts[:-1]:
                src = src.subdir(part, create=False)
                if dst.kind(part) not in (None, "dir"):
                    dst.remove(part)
                dst = dst.subdir(part)
            if rel.endswith("/"):
                continue
            if dst.kind(parts[-1]) == "dir":
                dst.remove(parts[-1])
            src.replace(parts[-1], parts[-1], into=dst)
        files, digests = dict(self.owned), dict(self.digests)
        for rel, cmd in self.owned.items():  # this command's files of an earlier run, not rewritten
            if cmd == self.command and rel not in written:
                _remove_rel(self.out, rel)
                del files[rel]
                digests.pop(rel, None)
        files.update({rel: self.command for rel in written})
        for rel in written:
            if not rel.endswith("/"):
                digests[rel] = _sha256(self.out, rel)
        self.out.write(MARKER, json.dumps({"files": files, "sha256": digests}, indent=1,
                                          sort_keys=True) + "\n")  # fmt: skip
        self.out.fsync()
        return written


WHOLE = "*"
"""A marker entry naming the command that owns the whole directory (a tool that writes into
it itself, as Ray Tune does); the command names the entries it may hold (``whole``)."""


def _check_output(out: OutDir, command: str, whole: tuple[str, ...]):
    """(owned, digests, staging folders) of an output ``command`` may write; else refused."""
    path = out.path
    owned, digests = _read_marker(out)
    if owned.get(WHOLE, command) != command:
        raise OutputError(f"{path}: the output of {owned[WHOLE]}, not of {command}; give "
                          f"a new or empty --out directory")  # fmt: skip
    stagings = {n for n in out.names() if _STAGING_RE.fullmatch(n) and out.kind(n) == "dir"}
    if whole:
        foreign = [n for n in out.names()
                   if n != MARKER and n not in stagings and n not in whole]  # fmt: skip
    else:
        foreign = [
            rel
            for rel in _listing(out, skip=stagings)
            if rel != MARKER
            and not rel.endswith("/")  # an empty folder: nothing to protect
            and (rel not in owned or digests.get(rel) != _sha256(out, rel))
        ]
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise OutputError(
            f"{path}: holds {foreign[0]}{more}, which no command of this package wrote "
            f"there (or changed since); give a new or empty --out directory"
        )
    return owned, digests, stagings


def check_command_output(path: Path, command: str, whole: tuple[str, ...] = ()) -> None:
    """Refuse now what :func:`command_output` would refuse, creating nothing.

    A command calls it before its work (loading a policy, compiling) so that a wrong ``--out``
    costs no time; :func:`command_output` checks again when it writes.
    """
    if not os.path.lexists(path):
        parent = Path(path).parent
        while not os.path.lexists(parent) and parent != parent.parent:
            parent = parent.parent
        if os.path.lexists(parent) and not os.path.isdir(parent):
            raise OutputError(f"{shown(Path(path))}: cannot create it ({shown(parent)} is not a "
                              f"directory)")  # fmt: skip
        if os.path.isdir(parent) and os.statvfs(parent).f_flag & os.ST_RDONLY:
            raise OutputError(f"{shown(Path(path))}: cannot create it ({shown(parent)} is on a "
                              f"read-only file system)")  # fmt: skip
        if os.path.isdir(parent) and not os.access(parent, os.W_OK):
            raise OutputError(f"{shown(Path(path))}: cannot create it ({shown(parent)}: "
                              f"permission denied)")  # fmt: skip
        return
    with OutDir.open(path, create=False) as out:
        _check_output(out, command, whole)


@contextlib.contextmanager
def command_output(
    path: Path, command: str, whole: tuple[str, ...] = (), keep_on_interrupt: bool = False
) -> Iterator[CommandOutput]:
    """The ``--out`` directory of ``command``: checked before the work, filled after it.

    ``path`` must be new, empty, or hold only files that commands of this package wrote there
    and that are as they wrote them: each listed in its :data:`MARKER` with its SHA-256 (a
    record cannot claim a file it did not write, nor one changed since); anything else (a
    policy, a run, a user's files, a link) is refused with one line before any work is done.
    On success the staged files replace the same names of an earlier run and the marker
    records them; on any exception or interrupt the staging directory is deleted and the
    directory is as it was (a directory made for the command is removed again; with
    ``keep_on_interrupt``, Ctrl-C still moves in what was written so far).

    ``whole``: the top-level names a command that owns the whole directory writes itself (a
    library writes into it directly, as Ray Tune does): the marker says so before the work,
    :meth:`CommandOutput.dir` is the directory itself, and the directory may hold nothing but
    those names (whatever its record says). A directory owned whole by another command, or
    holding anything else, is refused.
    """
    created = not os.path.lexists(path)
    out = OutDir.open(path)
    done = False
    try:
        owned, digests, stagings = _check_output(out, command, whole)
        for name in stagings:  # a killed command's staging (its pid gone): ours by its name
            if not _alive(int(_STAGING_RE.fullmatch(name).group(1))):
                out.remove(name)
        if whole:
            if owned and set(owned) != {WHOLE}:
                raise OutputError(f"{path}: holds other commands' files; give a new or empty "
                                  f"--out directory")  # fmt: skip
            out.write(MARKER, json.dumps({"files": {WHOLE: command}}) + "\n")
            done = True
            yield CommandOutput(out, command, owned, staged=False)
            return
        co = CommandOutput(out, command, owned, digests)
        try:
            yield co
            if interrupts.received():  # a Ctrl-C that Python dropped (raised in a finaliser)
                raise KeyboardInterrupt
            co._commit()
            done = True
        except KeyboardInterrupt:
            if keep_on_interrupt:
                co._commit()
                done = True
            raise
        finally:
            with contextlib.suppress(OSError):
                out.remove(co.stage_name)
    finally:
        out.close()
        if created and not done:  # made for this command, which wrote nothing: gone again
            with contextlib.suppress(OSError):
                os.rmdir(path)


# ----------------------------------------------------------------------------- the run's lock
class RunLock:
    """An exclusive lock on a run directory (``RUN/.lock``, ``flock``): one writer at a time.

    Taken through the run's held descriptor before anything of the run is read or written.
    The kernel releases it when the holder exits, however it exits (SIGKILL included), so a
    stale lock never blocks a resume. A second writer is refused with the holder's pid; a
    ``.lock`` that is a link, a directory or a FIFO is refused.
    """

    def __init__(self, run: OutDir):
        self.run = run
        self.fd: int | None = None

    def __enter__(self) -> RunLock:
        fd = self.run._open_regular(".lock", os.O_RDWR | os.O_CREAT)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise OutputError(
                f"{self.run.path}: in use by {holder}; one writer at a time"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
        self.fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            os.close(self.fd)  # releases the flock
            self.fd = None


# ----------------------------------------------------------------------------- path helpers
def write_file(path: Path, data: bytes | str) -> None:
    """Write ``path`` whole through its opened parent (made when missing): never via a link.

    A link at ``path`` is replaced, not followed; a kill leaves the old file or the new one.
    """
    path = Path(path)
    with OutDir.open(path.parent) as d:
        d.write(path.name, data)


def save_figure(fig, path: Path, **kw) -> None:
    """A matplotlib figure written whole as ``path`` (:func:`write_file`), then closed."""
    import matplotlib.pyplot as plt

    path = Path(path)
    with OutDir.open(path.parent) as d:
        d.savefig(path.name, fig, **kw)
    plt.close(fig)


def append_file(path: Path, text: str) -> None:
    """Append to ``path`` (made when missing): a plain file of one link, never via a link."""
    path = Path(path)
    with OutDir.open(path.parent) as d:
        d.append(path.name, text)
