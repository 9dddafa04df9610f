"""Atomic output files, the checks made on every output location before anything is written,
and the rule that an output never overwrites an input.

A result is written to a hidden temporary file in the target's directory and moved over the
target with :func:`os.replace` (atomic on POSIX and Windows), so a reader sees either the old
file or the complete new one, and a failed command leaves no partial output behind.

The temporary file is ``.<target name>.pkmcal-<host>-<pid>-<random>.tmp`` (``<host>`` 8 hex
digits of the host name's hash). A process killed while writing (``kill -9``) leaves it
behind; the next write of the same target removes such stale files — only files of that
pattern for that same target, owned by the current user, and either written by a process of
this host that no longer exists, or (another host's) older than :data:`STALE_AFTER_S`.

Commands call :func:`check_output_path` / :func:`check_output_dir` for every output before
they load or compute anything, so that a bad location (a missing or read-only folder, a
path ending in ``/``, an empty name, a name the file system cannot hold, an input file) is
refused before any output — of this or another location — is written. Permission bits are
not the whole answer (a superuser passes them in ``/proc`` and on read-only or
root-squashed mounts), so the folder a file would be created in is also tried: a hidden
``.pkmcal-write-check-*`` file is created there and removed at once.

An existing output that is a character device or a named pipe (``-o /dev/null``, a pipe
another program reads) is written in place, not replaced: :func:`os.replace` would put a
regular file where the device was (as root, ``-o /dev/null`` turned ``/dev/null`` into a
file, 2026-12-03). A block device or a socket is refused.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import socket
import stat
import tempfile
import time
from pathlib import Path
from typing import IO, Iterable, Iterator

from pkmcal.errors import PkmcalError

#: Age (s) after which a temporary file of another host (or an unknown writer) is stale.
STALE_AFTER_S = 24 * 3600
#: Longest target-name prefix kept in a temporary file's name (bytes), leaving room for the rest.
_MAX_STEM_BYTES = 180


def _same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def _name_max(directory: str) -> int:
    try:
        return os.pathconf(directory or ".", "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):
        return 255


def _location_problem(output: str, what: str) -> str | None:
    """Why nothing can be written at ``output`` (a file when ``what == "file"``, else a
    folder, created if needed), or None."""
    if output == "":
        return "the path is empty; give a file or folder name"
    if "\x00" in output:
        return "the path holds a NUL character"
    if what == "file" and (output.endswith(os.sep) or (os.altsep and output.endswith(os.altsep))):
        return "the path ends with a separator, so it names a folder; give a file name (e.g. out.csv)"
    path = Path(output)
    directory = str(path.parent) if str(path.parent) else "."
    longest = _name_max(directory)
    for part in path.parts:
        if len(os.fsencode(part)) > longest:
            return f"a name of {len(os.fsencode(part))} bytes; the file system allows at most {longest}"
    try:
        st = os.stat(output)
    except (FileNotFoundError, NotADirectoryError):  # ENOTDIR: an ancestor is a file (found below)
        st = None
    except OSError as exc:
        return str(exc.strerror or exc)
    if st is not None:
        if what == "file" and stat.S_ISDIR(st.st_mode):
            return "it is a folder; give a file name"
        if what == "file" and (stat.S_ISBLK(st.st_mode) or stat.S_ISSOCK(st.st_mode)):
            return "it is a block device or a socket, not a file; give a file name"
        if what == "file" and _written_in_place(st.st_mode):
            return None if os.access(output, os.W_OK) else "no write permission"
        if what == "folder" and not stat.S_ISDIR(st.st_mode):
            return "it exists and is not a folder; give a folder"
        target = output if what == "folder" else directory
        if not os.access(target, os.W_OK | os.X_OK):
            return f"no write permission in {'it' if what == 'folder' else 'its folder'}"
        return _cannot_create_in(target, "it" if what == "folder" else "its folder")
    # The output does not exist yet: its nearest existing ancestor must be a writable folder
    # (a file needs its own folder to exist; a folder is created with its parents).
    parent = path.parent if what == "file" else path
    while True:
        try:
            pst = os.stat(parent)
        except (FileNotFoundError, NotADirectoryError):
            if what == "file":
                return f"the folder '{parent}' does not exist; create it first"
            if parent == parent.parent:
                return "it cannot be created"
            parent = parent.parent
            continue
        except OSError as exc:
            return str(exc.strerror or exc)
        if not stat.S_ISDIR(pst.st_mode):
            return f"'{parent}' is not a folder"
        if not os.access(parent, os.W_OK | os.X_OK):
            return f"no write permission in the folder '{parent}'"
        return _cannot_create_in(str(parent), f"the folder '{parent}'")


def _cannot_create_in(folder: str, name: str) -> str | None:
    """Why no file can be created in the existing ``folder`` (called ``name`` in the message),
    or None, found by creating one and removing it: permission bits do not tell everything
    (a superuser passes ``os.access`` in ``/proc``, on a read-only or root-squashed mount)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".pkmcal-write-check-", dir=folder)
    except OSError as exc:
        return f"nothing can be created in {name} ({exc.strerror or exc})"
    os.close(fd)
    _unlink_quietly(probe)
    return None


def check_output_path(output: str | os.PathLike, inputs: Iterable[str | os.PathLike | None] = ()) -> None:
    """Refuse an output file path that cannot be written (see the module docstring) or that
    names one of the command's input files. Raises :class:`PkmcalError` saying what to do."""
    text = os.fspath(output)
    problem = _location_problem(text, "file")
    if problem is not None:
        raise PkmcalError(f"cannot write output file '{text}': {problem}")
    for inp in inputs:
        if inp is None or not _exists(inp):
            continue
        if _same_file(output, inp):
            raise PkmcalError(
                f"output file '{output}' is the input file '{inp}'; pkmcal never overwrites its "
                "inputs: choose another output path with -o"
            )


def check_output_dir(folder: str | os.PathLike, option: str = "output folder") -> None:
    """Refuse an output folder that is not a folder or cannot be created or written into."""
    text = os.fspath(folder)
    problem = _location_problem(text, "folder")
    if problem is not None:
        raise PkmcalError(f"cannot write {option} '{text}': {problem}")


def make_folder(folder: str | os.PathLike, option: str = "output folder") -> Path:
    """Create the output folder ``folder`` with its parents (nothing if it exists);
    :class:`PkmcalError` naming ``option`` when it cannot be."""
    path = Path(folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise PkmcalError(f"cannot create {option} '{folder}': {exc.strerror or exc}; choose another path") from None
    return path


def _exists(path: str | os.PathLike) -> bool:
    try:
        return os.path.exists(path)
    except (OSError, ValueError):
        return False


def _default_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _host_tag() -> str:
    return hashlib.sha1(socket.gethostname().encode("utf-8", "replace")).hexdigest()[:8]


def _stem(name: str) -> str:
    """``name`` cut to at most :data:`_MAX_STEM_BYTES` bytes of UTF-8 (at a character)."""
    data = name.encode("utf-8", "surrogateescape")
    if len(data) <= _MAX_STEM_BYTES:
        return name
    return data[:_MAX_STEM_BYTES].decode("utf-8", "ignore")


def _temp_pattern(stem: str) -> re.Pattern[str]:
    return re.compile(rf"\.{re.escape(stem)}\.pkmcal-(?P<host>[0-9a-f]{{8}})-(?P<pid>[0-9]+)-[a-z0-9_]+\.tmp")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def remove_stale_temporaries(target: str | os.PathLike, now: float | None = None) -> list[str]:
    """Delete the temporary files that killed writes of ``target`` left in its folder
    (module docstring); returns the names removed. Never raises."""
    target = Path(target)
    directory = target.parent if str(target.parent) else Path(".")
    pattern = _temp_pattern(_stem(target.name))
    now = time.time() if now is None else now
    host, removed = _host_tag(), []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        m = pattern.fullmatch(name)
        if m is None:
            continue
        path = directory / name
        try:
            st = os.lstat(path)
            if not stat.S_ISREG(st.st_mode) or (hasattr(os, "getuid") and st.st_uid != os.getuid()):
                continue
            pid = int(m.group("pid"))
            ours = m.group("host") == host
            dead = ours and pid != os.getpid() and not _pid_alive(pid)
            if dead or now - st.st_mtime > STALE_AFTER_S:
                os.unlink(path)
                removed.append(name)
        except (OSError, ValueError):
            continue
    return removed


def _written_in_place(mode: int) -> bool:
    """Whether an existing output of ``st_mode`` ``mode`` is written in place (module
    docstring): a character device or a named pipe."""
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)


@contextlib.contextmanager
def atomic_writer(path: str | os.PathLike, binary: bool = False) -> Iterator[IO]:
    """A file that becomes ``path`` when the block ends without an exception, atomically; on
    an exception it is deleted and ``path`` is left as it was. Text (UTF-8, ``\\n`` line
    ends kept), or bytes with ``binary=True``. An existing file keeps its permission bits; a
    new one gets ``0o666 & ~umask``. An existing character device or named pipe is written
    in place (module docstring). Raises :class:`PkmcalError` if it cannot be written."""
    target = Path(path)
    try:
        in_place = _written_in_place(os.stat(target).st_mode)
    except OSError:
        in_place = False
    if in_place:
        try:
            with (open(target, "wb") if binary else open(target, "w", encoding="utf-8", newline="")) as fh:
                yield fh
        except OSError as exc:
            raise PkmcalError(f"cannot write '{path}': {exc.strerror or exc}") from None
        return
    directory = target.parent if str(target.parent) else Path(".")
    remove_stale_temporaries(target)
    try:
        mode = os.stat(target).st_mode & 0o7777 if target.exists() else _default_mode()
        fd, tmp = tempfile.mkstemp(prefix=f".{_stem(target.name)}.pkmcal-{_host_tag()}-{os.getpid()}-",
                                   suffix=".tmp", dir=directory)
    except OSError as exc:
        raise PkmcalError(f"cannot write '{path}': {exc.strerror or exc}; check that the directory exists "
                          "and is writable") from None
    try:
        with (os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="")) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, target)
    except OSError as exc:
        _unlink_quietly(tmp)
        raise PkmcalError(f"cannot write '{path}': {exc.strerror or exc}") from None
    except BaseException:
        _unlink_quietly(tmp)
        raise


def _unlink_quietly(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_writer`)."""
    with atomic_writer(path) as fh:
        fh.write(text)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_writer`)."""
    with atomic_writer(path, binary=True) as fh:
        fh.write(data)
