"""Decisions that survive kill -9: an append-only journal beside the session.

Why: the app saved curation on a 30 s autosave timer, and issue 16 lost 36 % of the
decisions over 8 kill -9 (everything before the first autosave). Now every decision is
one line appended to ``<session>.journal`` and forced to disk (``flush`` + ``os.fsync``)
before the app moves on; on open the journal is replayed over the last saved session,
and it is compacted (emptied) once the session has been saved.

* File: JSON lines, ``{"seq": n, "time": unix seconds, "data": {...}}``; ``seq`` grows
  by one per record across openings. A torn last line (the process died mid-write) is
  ignored on replay and cut off before the next append; any other undecodable line is
  skipped and counted (``Journal.damaged``).
* Key: the journal belongs to the session path derived from the recording
  (``engine.session.session_path_for``), so opening the recording, its
  ``.panotopo.json`` session or its autosave all find the same journal
  (``journal_session_path``).
* Lock: ``<journal>.lock`` held with ``fcntl.flock`` (non-blocking, exclusive) while a
  journal is open for writing; a second instance gets ``JournalLocked`` naming the
  holder's pid and host, and may open it ``read_only`` instead. The lock is released by
  the kernel when its holder dies, so a kill -9 never leaves a stale lock.
* Nothing left behind: the journal file is created by the first record, not by
  opening; ``close`` removes it when it holds no record (a clean quit, a save that
  compacted everything) and removes the lock file it holds. A lock or journal path
  that is a symlink or not a regular file is refused (``UnsafeJournal``, an OSError):
  the journal never writes through a name someone else planted.
* Fallback: when the session's folder cannot be written (a read-only share, a DVD, a
  folder of another user), the journal goes to
  ``$XDG_STATE_HOME/panotopo/journals/<sha1 of the session path>-<name>.journal``
  (``~/.local/state`` when XDG_STATE_HOME is unset), or ``fallback_dir`` when given;
  ``Journal.fallback`` says so, for the app to tell the user. Replay reads both places.

Plain Python, no Qt: the app calls ``append`` on every decision.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import socket
import time
from pathlib import Path
from typing import Optional

from .errors import PanotopoError

JOURNAL_SUFFIX = ".journal"
LOCK_SUFFIX = ".lock"


class UnsafeJournal(OSError):
    """A journal or lock path is a symlink or not a regular file: refused, nothing written."""

    def __init__(self, path: Path):
        self.path = path
        super().__init__(f"{path} is a link or not a regular file; refused")
        self.strerror = f"{path.name} is a link or not a regular file (refused)"


def check_own(path: Path) -> None:
    """Raise ``UnsafeJournal`` when ``path`` exists and is not a plain regular file of ours."""
    import stat

    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1 or (hasattr(os, "getuid") and st.st_uid != os.getuid()):
        raise UnsafeJournal(path)


class JournalLocked(PanotopoError):
    """The journal is open for writing in another panotopo (``holder`` says which)."""

    def __init__(self, path: Path, holder: str):
        self.path, self.holder = path, holder
        super().__init__(f"{path}: this work is open in another panotopo ({holder}); "
                         f"close it there, or open this one read-only")


def journal_session_path(path: str | Path) -> Path:
    """The session path a journal is keyed by, from the recording, its session file or
    its autosave (all three give the same answer). Any other ``.json`` (a session saved
    under its own name) keys its own journal."""
    from .session import AUTOSAVE_SUFFIX, SESSION_SUFFIX, session_path_for

    p = Path(os.path.abspath(path))
    if p.name.endswith(SESSION_SUFFIX):
        return p
    if p.name.endswith(AUTOSAVE_SUFFIX):
        return p.with_name(p.name[: -len(AUTOSAVE_SUFFIX)] + SESSION_SUFFIX)
    if p.suffix.lower() == ".json":
        return p
    return session_path_for(p)


def state_dir() -> Path:
    """Where journals go when the session's folder is read-only."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "panotopo" / "journals"


def _fallback_path(session: Path, fallback_dir: Optional[Path]) -> Path:
    digest = hashlib.sha1(str(session).encode("utf-8", "surrogateescape")).hexdigest()[:16]
    return Path(fallback_dir or state_dir()) / f"{digest}-{session.name}{JOURNAL_SUFFIX}"


def _writable_folder(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (tried, not guessed: os.access is
    wrong on read-only mounts and for root)."""
    probe = folder / f".panotopo-probe-{os.getpid()}-{time.monotonic_ns()}"
    try:
        fd = os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
    except OSError:
        return False
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:
        pass
    return True


def _read_records(path: Path) -> tuple[list[dict], int, int]:
    """(records, damaged lines, byte length of the whole lines) of one journal file."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return [], 0, 0
    records, damaged = [], 0
    end = raw.rfind(b"\n") + 1          # bytes after the last newline: a torn last line
    for line in raw[:end].split(b"\n"):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
            if not isinstance(rec, dict) or not isinstance(rec.get("seq"), int) or "data" not in rec:
                raise ValueError
        except ValueError:
            damaged += 1
            continue
        records.append(rec)
    return records, damaged, end


class Journal:
    """An open journal; see the module docstring."""

    def __init__(self, session_path: Path, path: Path, paths: list[Path], fallback: bool,
                 read_only: bool):
        self.session_path = session_path   # the session this journal belongs to
        self.path = path                   # the file appended to
        self.paths = paths                 # every place a journal of this session may be
        self.fallback = fallback           # True: the session's folder is read-only
        self.read_only = read_only
        self.damaged = 0                   # undecodable lines skipped by the last replay
        self._fd: Optional[int] = None
        self._lock_fd: Optional[int] = None
        self._seq = 0

    # ----- opening ----------------------------------------------------------------------
    @classmethod
    def open(cls, session_path: str | Path, fallback_dir: Optional[str | Path] = None,
             read_only: bool = False) -> "Journal":
        """The journal of ``session_path`` (a recording, its session or its autosave),
        locked for this process unless ``read_only``. Raises JournalLocked when another
        process holds it, OSError when neither place can be written."""
        session = journal_session_path(session_path)
        primary = session.with_name(session.name + JOURNAL_SUFFIX)
        fallback = _fallback_path(session, Path(fallback_dir) if fallback_dir else None)
        use_fallback = not read_only and not _writable_folder(primary.parent)
        path = fallback if use_fallback else primary
        journal = cls(session, path, [primary, fallback], use_fallback, read_only)
        if read_only:
            return journal
        if use_fallback:
            path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        check_own(path)
        journal._lock()
        journal._seq = max((r["seq"] for rs in journal._all_records() for r in rs), default=0)
        return journal   # the journal file itself is created by the first record

    def _lock(self) -> None:
        import fcntl

        lock_path = self.lock_path
        for _attempt in range(20):
            check_own(lock_path)
            try:
                fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
            except OSError as exc:
                if exc.errno == errno.ELOOP:
                    raise UnsafeJournal(lock_path) from None
                raise
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "unknown process"
                os.close(fd)
                raise JournalLocked(self.session_path, holder) from None
            try:   # the holder before us may have removed the file between our open and our lock
                same = os.stat(lock_path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        else:
            raise OSError(errno.EAGAIN, f"{lock_path}: could not be locked")
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
        self._lock_fd = fd

    @property
    def lock_path(self) -> Path:
        return self.path.with_name(self.path.name + LOCK_SUFFIX)

    def _open_for_append(self) -> None:
        from .outputs import sync_folder

        check_own(self.path)
        whole = _read_records(self.path)[2]
        created = not self.path.exists()
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW, 0o600)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise UnsafeJournal(self.path) from None
            raise
        if os.fstat(fd).st_size > whole:
            os.ftruncate(fd, whole)      # cut a torn last line so the next record starts clean
            os.fsync(fd)
        if created:
            sync_folder(self.path.parent)  # the new file's name survives a power cut too
        self._fd = fd

    def _all_records(self) -> list[list[dict]]:
        out = []
        self.damaged = 0
        for p in self.paths:
            recs, damaged, _ = _read_records(p)
            out.append(recs)
            self.damaged += damaged
        return out

    # ----- use --------------------------------------------------------------------------
    def append(self, record: dict) -> int:
        """Write ``record`` (JSON-ready) as the next line and force it to disk before
        returning its sequence number."""
        if self._fd is None:
            if self._lock_fd is None:
                raise PanotopoError(f"{self.path}: the journal is not open for writing")
            self._open_for_append()   # the first record creates the file
        self._seq += 1
        line = json.dumps({"seq": self._seq, "time": time.time(), "data": record},
                          separators=(",", ":"), allow_nan=False) + "\n"
        data = line.encode("utf-8")
        written = 0
        while written < len(data):
            written += os.write(self._fd, data[written:])
        os.fsync(self._fd)
        return self._seq

    @property
    def last_seq(self) -> int:
        """Sequence number of the last record appended (or replayed); 0 when none."""
        return self._seq

    def replay(self) -> list[dict]:
        """Every record (the ``data`` given to ``append``) not yet compacted, oldest first,
        from both places a journal of this session may be."""
        merged = [r for recs in self._all_records() for r in recs]
        merged.sort(key=lambda r: (r["seq"], r.get("time", 0.0)))
        return [r["data"] for r in merged]

    def compact(self, upto: Optional[int] = None) -> None:
        """Drop the records a successful save now holds: all of them, or those with
        ``seq <= upto`` (records appended while the save was running are kept)."""
        if self._lock_fd is None:
            raise PanotopoError(f"{self.path}: the journal is not open for writing")
        keep = [r for recs in self._all_records() for r in recs if upto is not None and r["seq"] > upto]
        for p in self.paths:
            if p != self.path and p.exists():
                try:
                    p.unlink()
                except OSError:
                    pass
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if not keep:   # nothing left to keep: no file (the next record creates it again)
            self._remove_own(self.path)
            return
        keep.sort(key=lambda r: r["seq"])
        self._replace_own(self.path, "".join(json.dumps(r, separators=(",", ":")) + "\n" for r in keep))
        self._fd = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_NOFOLLOW)

    @staticmethod
    def _remove_own(path: Path) -> None:
        try:
            check_own(path)
            path.unlink()
        except FileNotFoundError:
            pass
        except OSError:
            pass   # not ours (refused) or not removable: left as it is

    @staticmethod
    def _replace_own(path: Path, text: str) -> None:
        """Write ``path`` atomically as a new regular file (a rename never follows a link)."""
        import tempfile

        from .outputs import sync_folder

        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(text.encode("utf-8"))
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
        sync_folder(path.parent)

    def close(self) -> None:
        """Release the file and the lock (the records stay until compacted); a journal
        file with no record and the lock file are removed, so nothing is left behind."""
        if self._lock_fd is not None:   # ours: tidy up while we still hold the lock
            try:
                if self.path.exists() and os.lstat(self.path).st_size == 0:
                    self._remove_own(self.path)
            except OSError:
                pass
            self._remove_own(self.lock_path)
        for attr in ("_fd", "_lock_fd"):
            fd = getattr(self, attr)
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
                setattr(self, attr, None)

    def __enter__(self) -> "Journal":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
