"""The files the app keeps beside a recording, decided in plain Python (no Qt).

Beside ``REC`` the app names four files itself: the session ``REC.panotopo.json``, the
autosave ``REC.panotopo.autosave.json``, and the decision journal
``REC.panotopo.json.journal`` with its lock (``engine.journal``). ``RecordingFiles``
owns them for the open recording:

* which saved session belongs to the file the user opened, whichever it is (the
  recording, a descriptors ``.npz``, the session itself: ``saved_session``);
* what unsaved work there is (an autosave newer than the session, journal records)
  and, once the user has answered the one question about it, restoring it
  (``restore``) or dropping it (``discard``): "No" restores nothing;
* the journal: taken when the recording is opened (so a second window is told at
  once), written only when there is a decision to keep, tidied on ``close``; a
  journal that cannot be used (read-only disk, a planted symlink) leaves ``problem``
  set, which the window shows for as long as it lasts;
* writing the session and the autosave only as regular files of this user
  (``Session.save(own=True)``): a planted symlink is refused, never followed;
* journal records checked one by one on replay (``gui.model.journal.replay_checked``):
  a bad one is skipped and counted, never stops the recording from opening.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from engine.errors import InputError
from engine.journal import Journal, JournalLocked, UnsafeJournal, journal_session_path  # noqa: F401
from engine.session import Session, autosave_path_for, session_path_for

from . import journal as journal_records


@dataclass
class Unsaved:
    """Work on a recording that no saved session holds."""

    autosave: Optional[Session] = None     # an autosave newer than the saved session
    records: list = field(default_factory=list)  # journal records not compacted yet
    damaged: int = 0                       # journal lines that could not be read at all

    def __bool__(self) -> bool:
        return self.autosave is not None or bool(self.records)

    def describe(self) -> str:
        parts = []
        if self.records:
            parts.append(f"{len(self.records)} decisions in the journal")
        if self.autosave is not None:
            parts.append("an autosave")
        return " and ".join(parts)


@dataclass
class Restored:
    """What opening restores: the decisions to apply, and what to tell the user."""

    decisions: dict
    skipped: int = 0                       # journal records left out (unreadable or invalid)
    session: Optional[Session] = None      # where the parameters and the view come from


class RecordingFiles:
    """See the module docstring. ``journaling=False``: take and write no journal (a
    screenshot or scripted run must not touch the user's files)."""

    def __init__(self, journaling: bool = True) -> None:
        self.journaling = journaling
        self.journal: Optional[Journal] = None
        self.problem = ""          # why decisions are not journaled now ("" when they are)
        self.input_path: Optional[Path] = None

    # -- opening ------------------------------------------------------------------------
    def attach(self, path: Path) -> None:
        """Take the journal of recording ``path``. Raises ``JournalLocked`` when another
        panotopo has it; any other failure leaves ``problem`` set (the recording opens)."""
        self.problem = ""
        if not self.journaling:
            self.close()
            self.input_path = Path(path)
            return
        old = self.journal
        if old is not None and old.session_path == journal_session_path(path):
            old.close()   # reopening the same recording: release our own lock first
            self.journal = old = None
        try:
            journal = Journal.open(path)
        except JournalLocked:
            raise
        except UnsafeJournal as exc:
            journal = None
            self.problem = (f"Decisions are NOT journaled: {exc.path.name} is a link or not a regular file "
                            "(refused). Save often.")
        except OSError as exc:
            journal = None
            self.problem = f"Decisions are NOT journaled ({exc.strerror or exc}). Save often."
        if old is not None:
            old.close()
        self.journal = journal
        self.input_path = Path(path)

    @staticmethod
    def saved_session(path: Path) -> Optional[Path]:
        """The saved session of the file opened (a recording, a bag folder, a descriptors
        ``.npz``): ``REC.panotopo.json`` beside it, when there is one."""
        saved = session_path_for(path)
        return saved if saved.is_file() else None

    def unsaved(self, path: Path, saved: Optional[Path]) -> tuple[Unsaved, list[str]]:
        """The unsaved work on recording ``path`` (``saved``: its session file, if any),
        and warnings (an autosave that cannot be read)."""
        out, warnings = Unsaved(), []
        auto = autosave_path_for(path)
        if auto.is_file() and (saved is None or auto.stat().st_mtime > saved.stat().st_mtime):
            try:
                out.autosave = Session.load(auto)
            except InputError as exc:
                warnings.append(str(exc))
        if self.journal is not None:
            out.records = self.journal.replay()
            out.damaged = self.journal.damaged
        return out, warnings

    @staticmethod
    def restore(unsaved: Unsaved, saved: Optional[Session]) -> Restored:
        """The decisions of ``saved`` (or the autosave) with the journal's records replayed
        over them, each record checked; the session the parameters come from."""
        base = unsaved.autosave or saved
        decisions, skipped = journal_records.replay_checked(unsaved.records, base.decisions if base else {})
        return Restored(decisions, skipped + unsaved.damaged, base)

    def discard(self, path: Path) -> None:
        """The user does not want the unsaved work: autosave removed, journal emptied."""
        _remove(autosave_path_for(path))
        self.compact()

    # -- saving --------------------------------------------------------------------------
    def is_own_name(self, target: Path) -> bool:
        """Is ``target`` a name the app chose itself (session or autosave of the recording)?"""
        if self.input_path is None:
            return False
        return Path(target) in (session_path_for(self.input_path), autosave_path_for(self.input_path))

    def save(self, session: Session, target: Path) -> None:
        """Write ``session`` to ``target`` (OSError/InputError when it cannot be); the journal
        is compacted when ``target`` is the session it replays over."""
        journaled = self.journal.last_seq if self.journal is not None else None
        session.save(target, own=self.is_own_name(target))
        if self.input_path is not None and Path(target) == session_path_for(self.input_path):
            self.compact(journaled)
        if self.input_path is not None:
            _remove(autosave_path_for(self.input_path))

    def autosave(self, session: Session) -> None:
        session.save(autosave_path_for(self.input_path), own=True)

    def compact(self, upto: Optional[int] = None) -> str:
        """Drop the journal's records a save now holds; a message when that failed."""
        if self.journal is None:
            return ""
        try:
            self.journal.compact(upto)
        except OSError as exc:
            return f"Journal not compacted: {exc}"
        return ""

    def journal_failed(self, message: str) -> None:
        """The journal stopped working mid-session (a full disk): remember why."""
        self.journal = None
        self.problem = message

    def close(self) -> None:
        """Release the journal (its records stay until a save; an empty one is removed)."""
        if self.journal is not None:
            self.journal.close()
            self.journal = None


def _remove(path: Path) -> None:
    """Remove a file the app named itself; a link planted there is removed, never followed."""
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    except OSError:
        pass
