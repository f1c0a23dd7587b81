"""A curation session on disk: everything needed to reopen a user's work.

A session is a small JSON file (by default ``<recording>.panotopo.json`` next to
the recording) with the input path, the describe settings, the map parameters,
the user's loop decisions (``TopoMap.decisions()``, keyed by source frames so
they survive a parameter change), the ground-truth poses used and some view
state. Writes are atomic (temp file + ``os.replace``) so a crash never leaves a
half-written session. Plain data only: no Qt here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from .errors import InputError
from .params import MapParams

FORMAT = "panotopo-session"
VERSION = 1
SESSION_SUFFIX = ".panotopo.json"
AUTOSAVE_SUFFIX = ".panotopo.autosave.json"


def session_path_for(input_path: str | Path) -> Path:
    """The session file that belongs next to a recording (or a directory bag)."""
    p = Path(input_path)
    return p.with_name(p.name + SESSION_SUFFIX)


def autosave_path_for(input_path: str | Path) -> Path:
    """The autosave file of a recording: separate from the session the user saved."""
    p = Path(input_path)
    return p.with_name(p.name + AUTOSAVE_SUFFIX)


def is_session_file(path: str | Path) -> bool:
    return str(path).lower().endswith(".json")


@dataclass
class Session:
    input_path: str                                   # the recording or descriptors .npz
    describe: dict = field(default_factory=dict)      # DescribeSettings.as_dict()
    params: dict = field(default_factory=dict)        # MapParams.as_dict()
    decisions: dict = field(default_factory=dict)     # TopoMap.decisions()
    poses_path: Optional[str] = None
    poses_topic: Optional[str] = None
    view: dict = field(default_factory=dict)          # current frame, selected loop, ...

    def map_params(self) -> MapParams:
        known = set(MapParams.__dataclass_fields__)
        return MapParams(**{k: v for k, v in self.params.items() if k in known})

    # -- writing ---------------------------------------------------------------
    def to_json(self, base_dir: Optional[Path] = None) -> dict:
        data: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "input": _portable(self.input_path, base_dir),
            "describe": self.describe,
            "params": self.params,
            "decisions": self.decisions,
            "poses": None,
            "view": self.view,
        }
        if self.poses_path:
            data["poses"] = {"path": _portable(self.poses_path, base_dir), "topic": self.poses_topic}
        return data

    def save(self, path: str | Path, own: bool = False) -> None:
        """Write atomically: the old file stays intact until the new one is complete.

        ``own``: ``path`` is a name the app chose itself (the session or autosave beside
        the recording): it is written only as a regular file of this user, never through a
        symlink or a hard link someone planted there (``InputError`` naming it); the new
        file replaces the name itself, so a link planted meanwhile is replaced, not followed.
        """
        path = Path(path)
        text = json.dumps(self.to_json(path.parent), indent=1, sort_keys=True)
        if own:
            write_own(path, text)
            return
        from .outputs import write_text

        write_text(path, text)

    # -- reading ---------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path) -> "Session":
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError(f"{path}: no such session file") from None
        except (UnicodeDecodeError, json.JSONDecodeError):
            raise InputError(f"{path}: not a panotopo session (the file is not valid JSON)") from None
        except OSError as exc:
            raise InputError(f"{path}: cannot read session file ({exc.strerror})") from None
        return cls.from_json(data, path)

    @classmethod
    def from_json(cls, data: Any, path: Path) -> "Session":
        """A session from parsed JSON; every field is checked (``check_fields``) so that a
        malformed or crafted file gets one line naming the field, never reaches Qt slots
        or the descriptor constructor unchecked."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputError(f"{path}: not a panotopo session file")
        try:
            fields = check_fields(data)
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None
        base = path.parent
        poses = fields["poses"]
        return cls(
            input_path=_resolve(fields["input"], base),
            describe=fields["describe"],
            params=fields["params"],
            decisions=fields["decisions"],
            poses_path=_resolve(poses["path"], base) if poses else None,
            poses_topic=poses.get("topic") if poses else None,
            view=fields["view"],
        )


def check_fields(data: dict) -> dict:
    """The checked fields of a session's JSON (see ``engine.session_fields``)."""
    from .session_fields import check_session

    return check_session(data, VERSION)


def _portable(path: str, base_dir: Optional[Path]) -> str:
    """Relative to the session's folder when the recording is beside it, so a moved
    folder still opens; absolute otherwise."""
    p = Path(path).resolve()
    if base_dir is not None:
        try:
            return p.relative_to(Path(base_dir).resolve()).as_posix()
        except ValueError:
            pass
    return str(p)


def _resolve(text: str, base: Path) -> str:
    p = Path(text)
    return str(p if p.is_absolute() else (base / p).resolve())


def check_own_file(path: Path) -> None:
    """OutputError (an InputError and an OSError) when ``path`` exists and is not a plain
    regular file of this user."""
    from .errors import OutputError
    from .journal import UnsafeJournal, check_own

    try:
        check_own(Path(path))
    except UnsafeJournal:
        raise OutputError(f"{path}: is a link or not a regular file of yours; panotopo will not write "
                         "through it (remove it, or save the session under another name)") from None


def write_own(path: Path, text: str) -> None:
    """``text`` into ``path`` as a new regular file (see ``Session.save(own=True)``)."""
    from .errors import OutputError
    from .journal import Journal

    check_own_file(path)
    try:
        Journal._replace_own(Path(path), text)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write ({exc.strerror or exc.__class__.__name__})") from None
