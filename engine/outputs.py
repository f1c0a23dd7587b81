"""Writing an output file safely: the one helper every writer uses.

Rules (issue 16, findings 6, 7, 9, 15), all enforced by ``write_atomically``:

* An output never replaces an input of the command: ``check_output`` compares the
  output with every input by device and inode (``os.path.samefile``), so a hard link,
  a symlink or another spelling of the same path is caught too.
* An existing output must be a regular file: a device node (``/dev/full``), a
  directory or a FIFO is refused, never replaced.
* A symlink is written THROUGH: the file it points to is replaced and the link stays a
  link (the user linked it on purpose; replacing the link would silently cut it).
* The temporary file is made by ``tempfile.mkstemp`` in the target's folder: a random
  name, ``O_CREAT | O_EXCL`` (so a planted file or symlink under that name is never
  followed or reused), then renamed over the target with ``os.replace`` (atomic on one
  file system: a crash leaves the old file or the new one, never half of one).
* The final mode: an existing file keeps its mode; a new file gets 0666 minus the
  user's umask, as any ordinary program would create it (mkstemp's 0600 is only for the
  temporary file while it is being written).
* Errors name the user's file, never the temporary one.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable, Iterable, Optional

from .errors import OutputError

# The mode a new file gets before the umask is applied (what open(..., "w") asks for).
NEW_FILE_MODE = 0o666


def current_umask() -> int:
    """The process umask, read without changing it where the system allows (Linux
    /proc); elsewhere set and restored at once."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def check_output(path: str | Path, inputs: Iterable[Optional[str | Path]] = ()) -> Path:
    """The file that writing ``path`` will actually replace (a symlink's target), after
    checking it is allowed; InputError naming ``path`` otherwise.

    ``inputs`` are the files the command reads (None entries are ignored): the output
    may be none of them.
    """
    path = Path(path)
    for src in inputs:
        if src is not None and _same_file(path, Path(src)):
            raise OutputError(f"{path}: the output is the same file as the input {src}; "
                             f"choose another output name")
    target = Path(os.path.realpath(path)) if path.is_symlink() else path
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise OutputError(f"{path}: cannot write ({exc.strerror})") from None
    if st is not None and not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise OutputError(f"{path}: cannot write the output there, it is {kind}")
    if not target.parent.is_dir():
        raise OutputError(f"{path}: cannot write, the folder {target.parent} does not exist")
    return target


def write_atomically(path: str | Path, write: Callable[[BinaryIO], None],
                     inputs: Iterable[Optional[str | Path]] = ()) -> Path:
    """Write ``path`` by calling ``write(binary_file)``, following the module's rules;
    returns the file written (the target of a symlink). InputError naming ``path``
    when it cannot be written."""
    path = Path(path)
    target = check_output(path, inputs)
    try:
        mode = stat.S_IMODE(os.stat(target).st_mode)
    except FileNotFoundError:
        mode = NEW_FILE_MODE & ~current_umask()
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write ({exc.strerror})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fchmod(f.fileno(), mode)
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise OutputError(f"{path}: cannot write ({exc.strerror or exc.__class__.__name__})") from None
        raise
    sync_folder(target.parent)
    return target


def write_text(path: str | Path, text: str, inputs: Iterable[Optional[str | Path]] = ()) -> Path:
    """``write_atomically`` for UTF-8 text."""
    data = text.encode("utf-8")
    return write_atomically(path, lambda f: f.write(data), inputs)


def sync_folder(folder: Path) -> None:
    """Make the rename itself durable (best effort: not every system allows it)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
