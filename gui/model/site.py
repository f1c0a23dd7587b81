"""Several recordings open as one site, decided in plain Python (no Qt).

A *site* is a map of several recordings (``engine.site``: nodes carry ``session``, the
graph attribute ``sessions`` lists each recording and its descriptors). The app opens
one from a site map (a ``.graphml`` written by ``panotopo map A B C`` or by the app),
or from several recordings or descriptors files chosen together. ``plan_site`` decides
which: what ``engine.site.map_site`` is given (the same orchestrator as the CLI), and the
*site file* the user's work hangs on (session, autosave and journal beside it, as beside a
recording): the site map opened, or, for recordings chosen together, a new
``A+B+C.site.graphml`` beside the first one, written once the first map is built (the
same recordings chosen again reopen it, so their saved work comes back).

Frames: every recording keeps its own source frame numbers. The views address a node by
one integer (a loop by two), so each recording gets a stretch of one *site timeline*:
``site frame = offset + source frame`` (``Site.place``), offsets in the site's order and
each stretch as long as the recording (``span``). ``SiteFrames`` reads a site frame from
the recording it belongs to, by that recording's own path and its own frame number.
Nothing on disk holds a site frame: journal records, sessions and decisions name the
recording and its own frame (``Site.address``; ``gui.model.loop_key``).

Bad input is one line (``InputError``): a recording or descriptors file that is gone
(``check_sessions``) refuses the site before anything of the open document is touched.
A recording whose descriptors are there but whose frames are not (moved, or an ``.npz``
whose recording is elsewhere) still maps; ``open_site`` says in one line whose frames
cannot be shown.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from engine.errors import InputError

SITE_SUFFIX = ".site.graphml"
NAMED_IN_FILE = 3          # recordings named in a new site file's name; the rest are counted


@dataclass(frozen=True)
class SiteRecording:
    """One recording of an open site and its stretch of the site timeline."""

    name: str                # the session name (``engine.site``: the file name as given)
    source: str = ""         # the recording as the site lists it ("" when only an .npz is known)
    descriptors: str = ""    # its descriptors .npz, when it has one
    frames_path: str = ""    # where its frames are read ("" when they cannot be shown)
    span: int = 0            # site frames its stretch takes
    offset: int = 0          # its first site frame


@dataclass
class SitePlan:
    """What opening a site does: what to map, the site file, and the recordings."""

    inputs: list[str]        # given to ``engine.site.map_site``
    anchor: Path             # the site file: session, autosave and journal beside it
    sessions: list           # ``engine.site.SessionSource``, in the site's order
    new: bool = False        # the site file is written when the first map is built


def is_site_input(paths: Sequence[str]) -> bool:
    """Several files, or one site map: a site."""
    from engine.site import is_site_map

    return len(paths) > 1 or (len(paths) == 1 and is_site_map(paths[0]))


def plan_site(paths: Sequence[str]) -> SitePlan:
    """The plan of opening ``paths`` as a site (module notes); InputError in one line."""
    from engine.site import expand, is_site_map

    paths = [str(Path(p).expanduser()) for p in paths]
    for p in paths:
        if not Path(p).exists():
            raise InputError(f"{p}: no such file or directory")
    if len(paths) == 1 and is_site_map(paths[0]):
        sessions, _decisions = expand(paths)
        check_sessions(sessions)
        return SitePlan(paths, Path(paths[0]).resolve(), sessions)
    sessions, _decisions = expand(paths)
    check_sessions(sessions)
    anchor, same = anchor_for(sessions)
    if same:   # these recordings were opened together before: their site file, and its work
        return SitePlan([str(anchor)], anchor, sessions)
    return SitePlan(paths, anchor, sessions, new=True)


def check_sessions(sessions: Sequence) -> None:
    """One line for a recording whose descriptors and recording are both gone
    (``engine.site.load_session`` could not map it)."""
    missing = [s for s in sessions
               if not (s.descriptors and Path(s.descriptors).is_file()) and not (s.source and Path(s.source).exists())]
    if missing:
        s = missing[0]
        where = s.descriptors or s.source or "no path recorded"
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise InputError(f"recording {s.name} of the site is not where the site says ({where}): "
                         f"move it back or open its recordings again{more}")


def anchor_for(sessions: Sequence, folder: Optional[Path] = None) -> tuple[Path, bool]:
    """The site file of recordings chosen together, and whether it is theirs already.

    ``A+B+C.site.graphml`` beside the first recording (``A+B+2 more`` past three); when a
    file of that name belongs to other recordings, ``-2``, ``-3``... are tried."""
    first = Path(sessions[0].source or sessions[0].descriptors)
    folder = Path(folder) if folder is not None else first.parent
    stems = [_stem(s.name) for s in sessions]
    if len(stems) > NAMED_IN_FILE:
        stems = stems[:NAMED_IN_FILE - 1] + [f"{len(stems) - NAMED_IN_FILE + 1} more"]
    base = "+".join(stems)
    for k in range(1, 1000):
        path = folder / f"{base}{'' if k == 1 else f'-{k}'}{SITE_SUFFIX}"
        if not path.exists():
            return path.resolve(), False
        if _same_site(path, sessions):
            return path.resolve(), True
    raise InputError(f"{folder}: too many site files named {base}{SITE_SUFFIX}")


def _stem(name: str) -> str:
    stem = Path(name).name
    for suffix in (".npz", ".mp4", ".avi", ".mkv", ".mov", ".webm", ".m4v", ".bag", ".db3", ".mcap", ".graphml"):
        if stem.lower().endswith(suffix):
            stem = stem[: -len(suffix)]
            break
    return re.sub(r"[^\w.-]+", "_", stem) or "recording"


def _same_site(path: Path, sessions: Sequence) -> bool:
    from engine.site import read_site

    try:
        found, _decisions = read_site(path)
    except (InputError, OSError, ValueError):
        return False
    return [(s.name, s.source) for s in found] == [(s.name, s.source) for s in sessions]


def frames_path_of(session) -> str:
    """Where a recording's frames are read: the recording itself, else the recording its
    descriptors file was made from (its meta ``source``), when either is there; else ""."""
    from engine.pipeline import is_descriptor_file

    if session.source and Path(session.source).exists() and not is_descriptor_file(session.source):
        return session.source
    npz = session.descriptors or (session.source if is_descriptor_file(session.source or "x") else "")
    meta = _npz_meta(npz) if npz else {}
    source = str(meta.get("source") or "")
    return source if source and Path(source).exists() else ""


def _npz_array(path: str, key: str):
    """One array of a descriptors file (checked like ``Descriptors.load``), or None."""
    from engine.npz_guard import check_archive

    try:
        check_archive(Path(path))
        with np.load(path, allow_pickle=False) as z:
            return z[key] if key in z.files else None
    except (InputError, OSError, ValueError, KeyError):
        return None


def _npz_meta(path: str) -> dict:
    raw = _npz_array(path, "meta")
    try:
        meta = json.loads(str(raw)) if raw is not None else {}
    except ValueError:
        return {}
    return meta if isinstance(meta, dict) else {}


def _npz_frame_span(path: str) -> int:
    frames = _npz_array(path, "frames")
    return int(np.max(frames)) + 1 if frames is not None and np.size(frames) else 0


def open_site(plan: SitePlan, open_recording: Callable[[str], object]) -> tuple["Site", "SiteFrames", str]:
    """The site of ``plan`` with each recording's frames opened (``open_recording(path)``
    gives a ``FrameSource``; slow: call it off the UI thread), and one line naming the
    recordings whose frames cannot be shown ("" when all can)."""
    recordings, sources, missing = [], [], []
    offset = 0
    for s in plan.sessions:
        path = frames_path_of(s)
        source = None
        if path:
            try:
                source = open_recording(path)
                source.stamps()   # the one indexing pass, here in the background
            except Exception:     # noqa: BLE001 - frames are a view of the map: none shown, said in one line
                source = None
        npz = s.descriptors or (s.source if s.source.lower().endswith(".npz") else "")
        span = max(int(source.frame_count) if source is not None else 0, _npz_frame_span(npz) if npz else 0)
        if source is None:
            missing.append(s.name)
            path = ""
        recordings.append(SiteRecording(s.name, s.source, s.descriptors, path, span, offset))
        sources.append(source)
        offset += span
    site = Site(plan.anchor, list(plan.inputs), recordings, new=plan.new)
    line = ""
    if missing:
        which = ", ".join(missing)
        line = (f"Frames of {which} cannot be shown: {'its recording was' if len(missing) == 1 else 'their recordings were'} "
                f"not found (the map is made from the descriptors)")
    return site, SiteFrames(site, sources), line


class Site:
    """The recordings of an open site, their stretches of the site timeline, and the
    translation between site frames and (recording, source frame) (module notes)."""

    def __init__(self, anchor: Path, inputs: list[str], recordings: list[SiteRecording], new: bool = False) -> None:
        self.anchor = Path(anchor)
        self.inputs = list(inputs)
        self.recordings = list(recordings)
        self.new = new                        # the site file is still to be written
        self.row_starts: list[int] = []       # first descriptor row of each recording (after a run)
        self._index = {r.name: i for i, r in enumerate(self.recordings)}
        self._offsets = np.array([r.offset for r in self.recordings], np.int64)

    # -- the recordings ------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        return [r.name for r in self.recordings]

    def index(self, name: str) -> int:
        try:
            return self._index[str(name)]
        except KeyError:
            raise InputError(f"the map names a recording the site does not have: {name}") from None

    @property
    def frame_count(self) -> int:
        return int(sum(r.span for r in self.recordings))

    @property
    def descriptors_only(self) -> bool:
        """Every recording mapped from a descriptors file (none can be described again)."""
        return all(r.descriptors and not (r.source and not r.source.lower().endswith(".npz"))
                   for r in self.recordings)

    # -- site frames ---------------------------------------------------------------------
    def place(self, name: str, frame: int) -> int:
        """The site frame of source frame ``frame`` of recording ``name``."""
        return int(self._offsets[self.index(name)]) + int(frame)

    def local(self, place: int) -> tuple[str, int]:
        """(recording, its source frame) of site frame ``place``."""
        i = max(int(np.searchsorted(self._offsets, int(place), side="right")) - 1, 0)
        return self.recordings[i].name, int(place) - int(self._offsets[i])

    def places(self, sessions: Sequence[str], frames: Sequence[int]) -> np.ndarray:
        """Site frames of many (recording, source frame) pairs."""
        lookup = np.array([self.index(s) for s in sessions], np.int64) if len(sessions) else np.zeros(0, np.int64)
        return self._offsets[lookup] + np.asarray(frames, np.int64) if lookup.size else np.zeros(0, np.int64)

    def node_places(self, topomap) -> np.ndarray:
        """Site frame of each node of ``topomap``, in node order."""
        return self.places(topomap.node_sessions().tolist(), topomap.frames())

    def row_places(self, descs) -> np.ndarray:
        """Site frame of each row of the site's concatenated descriptors (``row_starts`` known)."""
        starts = np.asarray(self.row_starts or [0], np.int64)
        which = np.searchsorted(starts, np.arange(len(descs)), side="right") - 1
        return self._offsets[which] + np.asarray(descs.frames, np.int64)

    def span_of(self, name: str) -> tuple[int, int]:
        """[first, end) site frames of recording ``name``."""
        r = self.recordings[self.index(name)]
        return r.offset, r.offset + r.span

    def address(self, key: Sequence[int]) -> tuple[list[int], list[str]]:
        """([frame, frame], [recording, recording]) of a key of site frames, as on disk."""
        (sa, fa), (sb, fb) = self.local(key[0]), self.local(key[1])
        return [fa, fb], [sa, sb]

    def key_of(self, frames: Sequence[int], sessions: Optional[Sequence[str]] = None) -> tuple[int, int]:
        """The key of site frames of an address on disk (no ``sessions``: the first recording's)."""
        names = list(sessions) if sessions else [self.recordings[0].name] * 2
        a, b = self.place(names[0], frames[0]), self.place(names[1], frames[1])
        return (a, b) if a <= b else (b, a)

    def place_text(self, place: int) -> str:
        name, frame = self.local(place)
        return f"{name} frame {frame}"

    # -- pairs of recordings (the review queue's filter) ---------------------------------
    def pair(self, a: str, b: str) -> tuple[str, str]:
        """The pair of recordings ``a``, ``b`` in the site's order."""
        return (a, b) if self.index(a) <= self.index(b) else (b, a)

    def pairs(self) -> list[tuple[str, str]]:
        """Every pair of recordings (a recording with itself too), in the site's order."""
        names = self.names
        return [(a, b) for i, a in enumerate(names) for b in names[i:]]


@dataclass
class SiteFrames:
    """The frames of a site, each read from its own recording (a ``FrameSource`` for the
    viewer's cache): site frame ``k`` is source frame ``k - offset`` of the recording whose
    stretch holds it. A recording that could not be opened has no frames (InputError)."""

    site: Site
    sources: list = field(default_factory=list)     # a FrameSource, or None, per recording

    @property
    def path(self) -> Path:
        return self.site.anchor

    @property
    def frame_count(self) -> int:
        return self.site.frame_count

    def recording_at(self, place: int):
        """(the recording's source or None, its name, its source frame) of site frame ``place``."""
        name, frame = self.site.local(place)
        return self.sources[self.site.index(name)], name, frame

    def frame_at(self, index: int):
        from engine.frames import Frame

        source, name, frame = self.recording_at(int(index))
        if source is None:
            raise InputError(f"the frames of {name} are not available")
        if not (0 <= frame < int(source.frame_count)):
            raise InputError(f"{name} has no frame {frame}")
        got = source.frame_at(frame)
        return Frame(int(index), float(got.stamp), got.rgb, getattr(got, "source_width", 0))

    def stamps(self) -> np.ndarray:
        """Stamps of the first recording that has frames (the playback rate comes from them)."""
        for source in self.sources:
            if source is not None:
                return source.stamps()
        return np.zeros(0)

    def close(self) -> None:
        for source in self.sources:
            if source is not None:
                source.close()


def site_remap(descs, params, site: Site, records: str, source: str = ""):
    """The map of a site's descriptors with ``params`` (a parameter change): what
    ``engine.site.map_site`` builds from them, without describing or loading anything."""
    from engine.pipeline import build_map

    topomap = build_map(descs, params, source=source or ", ".join(site.names),
                        row_starts=site.row_starts, sessions=site.names)
    if records:
        topomap.graph.graph["sessions"] = topomap.meta["sessions"] = records
    return topomap
