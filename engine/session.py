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
import os
import tempfile
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

    def save(self, path: str | Path) -> None:
        """Write atomically: the old file stays intact until the new one is complete."""
        path = Path(path)
        text = json.dumps(self.to_json(path.parent), indent=1, sort_keys=True)
        fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise

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
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputError(f"{path}: not a panotopo session file")
        version = data.get("version")
        if not isinstance(version, int) or version > VERSION:
            raise InputError(f"{path}: session version {version!r} is newer than this panotopo understands")
        if not isinstance(data.get("input"), str) or not data["input"]:
            raise InputError(f"{path}: session has no input recording")
        for key in ("describe", "params", "decisions", "view"):
            if not isinstance(data.get(key, {}), dict):
                raise InputError(f"{path}: session field '{key}' is malformed")
        poses = data.get("poses")
        if poses is not None and not (isinstance(poses, dict) and isinstance(poses.get("path"), str)):
            raise InputError(f"{path}: session field 'poses' is malformed")
        base = path.parent
        session = cls(
            input_path=_resolve(data["input"], base),
            describe=dict(data.get("describe", {})),
            params=dict(data.get("params", {})),
            decisions=dict(data.get("decisions", {})),
            poses_path=_resolve(poses["path"], base) if poses else None,
            poses_topic=poses.get("topic") if poses else None,
            view=dict(data.get("view", {})),
        )
        try:
            session.map_params()
        except TypeError:
            raise InputError(f"{path}: session parameters are malformed") from None
        return session


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
