"""One map from several recordings of one site (``panotopo map A B C -o site.graphml``).

Contract:

* ``map_site(inputs, params, settings)``: ``inputs`` is any mix of recordings (videos, bags,
  photo folders), descriptors ``.npz`` and site maps (``.graphml`` written by panotopo, whose
  recordings are mapped again with the new ones). Each recording is a *session* named by its
  file name as given (``Path(input).name``; the path as given where two names clash).
* The recordings' descriptors are concatenated (``combine``: rows, local features and shifts
  offset, so that every row stays unique), nodes are made per recording, the thresholds are
  calibrated on the whole set and the one loop search (retrieval, geometry, robust pose graph
  with each recording its own chain) runs on all nodes: ``engine.pipeline.build_map`` with
  ``row_starts`` and ``sessions``.
* Descriptors of different models (meta ``descriptor`` name or settings, dimension, panorama
  shift) are refused together in one line (``check_models``).
* The map records each session in the graph attribute ``sessions`` (JSON list of
  {"session", "source", "descriptors", "nodes"}; paths absolute): a site map given as an
  input is re-read from there, its descriptors loaded from the ``.npz`` where one is named and
  exists, else from the recording through the descriptor cache (described again only when
  the cache has none). The decisions already taken on the site (confirmed, rejected and manual
  loops, place names; ``TopoMap.decisions`` keyed by (session, frame), the graph attribute
  ``decisions`` keeping rejected loops) are applied to the new map.
* ``components``: which sessions the exported map's loops join; a session that joins nothing
  is its own component (the CLI says so in one line).
"""

from __future__ import annotations

import gc
import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from .descriptors.base import Descriptors
from .errors import InputError
from .params import MapParams


@dataclass(frozen=True)
class SessionSource:
    """One recording of a site: its name, the recording and its descriptors file (either may be
    empty: an .npz given alone has no recording; a recording may have no .npz of its own)."""

    name: str
    source: str = ""
    descriptors: str = ""


@dataclass
class SiteResult:
    topomap: object                   # engine.graph.TopoMap
    descs: Descriptors                # the concatenated descriptors
    sessions: list                    # [SessionSource], in map order
    row_starts: list                  # first row of each session in ``descs``
    components: list = field(default_factory=list)   # [[session names]] joined by loops
    notes: list = field(default_factory=list)        # one line each, for the user


def is_site_map(path: str | Path) -> bool:
    return Path(path).suffix.lower() == ".graphml"


def _absolute(path: str | Path) -> str:
    return str(Path(path).expanduser().resolve()) if str(path) else ""


def read_site(path: str | Path) -> tuple[list[SessionSource], dict]:
    """The sessions of a map written by panotopo and the decisions taken on it. A map of one
    recording (no ``sessions`` attribute) is one session named after its ``source``."""
    from .graph import TopoMap

    topomap = TopoMap.read_graphml(path)
    records = topomap.session_records()
    if not records:
        source = str(topomap.meta.get("source", ""))
        if not source:
            raise InputError(f"{path}: the map does not say which recording it was made from "
                             f"(no 'source'); give the recording or its descriptors .npz instead")
        records = [{"session": Path(source).name, "source": source, "descriptors": ""}]
    sessions = [SessionSource(str(r["session"]), str(r.get("source", "")), str(r.get("descriptors", "")))
                for r in records]
    decisions = stored_decisions(topomap)
    if topomap.node_sessions() is None:   # one recording's decisions, keyed by frame only: name it
        name = sessions[0].name
        for key in ("loops", "manual"):
            for item in decisions.get(key, []):
                item.setdefault("sessions", [name, name])
        for item in decisions.get("labels", []):
            item.setdefault("session", name)
    del topomap
    gc.collect()   # the map's graph is cyclic garbage once read: 600 MB at 360,000 nodes, freed now
    return sessions, decisions


def stored_decisions(topomap) -> dict:
    """Decisions of a map read from a file: the graph's ``decisions`` attribute (which keeps
    the rejected loops the exported arcs leave out) merged with what its arcs and labels say."""
    seen = topomap.decisions()
    raw = topomap.graph.graph.get("decisions")
    if not raw:
        return seen
    try:
        stored = json.loads(raw)
    except ValueError:
        raise InputError("the map's 'decisions' attribute is not JSON") from None
    out = {}
    for key in ("loops", "manual", "labels"):
        items = list(stored.get(key, [])) if isinstance(stored, dict) else []
        known = {json.dumps(i, sort_keys=True) for i in items}
        out[key] = items + [i for i in seen.get(key, []) if json.dumps(i, sort_keys=True) not in known]
    return out


def session_names(inputs: Sequence[str], taken: Sequence[str] = ()) -> list[str]:
    """Each input's session name: its file name, or the path as given where names clash."""
    names = [Path(str(p).rstrip("/")).name or str(p) for p in inputs]
    out = []
    for p, name in zip(inputs, names):
        if names.count(name) > 1 or name in taken:
            name = str(p)
        if name in out or name in taken:
            raise InputError(f"{p}: given twice (each recording once per site)")
        out.append(name)
    return out


def _model(descs: Descriptors) -> tuple:
    meta = descs.meta or {}
    return (str(meta.get("descriptor", "")), int(descs.vectors.shape[1]))


def check_models(named: Sequence[tuple[str, Descriptors]]) -> None:
    """One line when the recordings were not described alike: descriptor model or its
    settings, dimension, or panorama shift."""
    first_name, first = named[0]
    for name, descs in named[1:]:
        a, b = _model(first), _model(descs)
        if a != b:
            raise InputError(f"{first_name} was described with {a[0] or 'an unnamed model'} ({a[1]}-D) and "
                             f"{name} with {b[0] or 'an unnamed model'} ({b[1]}-D): describe every "
                             f"recording of a site with one descriptor")
        sa, sb = (first.meta or {}).get("settings"), (descs.meta or {}).get("settings")
        if sa and sb and sa != sb:
            diff = sorted(k for k in set(sa) | set(sb) if sa.get(k) != sb.get(k))
            raise InputError(f"{first_name} and {name} were described with different {a[0]} settings "
                             f"({', '.join(diff)}): describe every recording of a site alike")
        if bool(first.meta.get("shift", True)) != bool(descs.meta.get("shift", True)):
            raise InputError(f"{first_name} and {name}: one was described with the panorama shift and "
                             f"the other without: describe every recording of a site alike")


def combine(parts: Sequence[Descriptors]) -> tuple[Descriptors, list[int]]:
    """The recordings' descriptors as one (rows in order) and the first row of each. Local
    features are concatenated (offsets moved on) when every recording has them, column
    signatures when all have the same shape; shifts are rescaled to the first recording's
    frame width (the one ``frame_width`` of the result)."""
    from .features import FeatureTable

    starts = np.cumsum([0] + [len(d) for d in parts[:-1]]).astype(np.int64).tolist()
    widths = [int((d.meta or {}).get("frame_width", 0)) for d in parts]
    width = widths[0]
    shifts = []
    for d, w in zip(parts, widths):
        s = np.asarray(d.shifts, np.int64)
        if width > 0 and w > 0 and w != width:
            s = np.rint(s * (width / w)).astype(np.int64) % width
        shifts.append(s)
    features = None
    if all(d.features is not None for d in parts):
        tables = [d.features for d in parts]
        base = np.cumsum([0] + [int(t.offsets[-1]) for t in tables[:-1]])
        offsets = np.concatenate([t.offsets[:-1] + b for t, b in zip(tables, base)] +
                                 [[int(base[-1] + tables[-1].offsets[-1])]]).astype(np.int64)
        features = FeatureTable(offsets, np.concatenate([t.uv for t in tables]),
                                np.concatenate([t.desc for t in tables]))
    columns = None
    if all(d.columns is not None for d in parts) and len({d.columns.shape[1:] for d in parts}) == 1:
        columns = np.concatenate([d.columns for d in parts])
    meta = dict(parts[0].meta or {})
    meta.update(source="", frame_width=width)
    combined = Descriptors(
        stamps=np.concatenate([np.asarray(d.stamps, np.float64) for d in parts]),
        frames=np.concatenate([np.asarray(d.frames, np.int64) for d in parts]),
        shifts=np.concatenate(shifts),
        vectors=np.concatenate([np.asarray(d.vectors, np.float32) for d in parts]),
        meta=meta, columns=columns, features=features)
    return combined, starts


class _SharedVocabulary:
    """One vocabulary for every recording a site describes. A descriptor that pools over a
    vocabulary clustered from the recording itself (effnet-vlad's default, "map") gives
    vectors that only compare within that recording: two recordings described apart are no
    closer at one place than at places 5 m apart (benchmarks/bench_sessions.py). So the first
    recording described fits the vocabulary (never from the cache, which would not hold it)
    and every other one is pooled over it (``vocabulary`` fixed, named by its sha1 in the
    settings, so those are cached)."""

    def __init__(self, settings):
        from . import descriptors as registry

        self.settings = settings
        self.model = registry.get(settings.descriptor, **settings.options)
        self.fitting = getattr(self.model, "fixed_vocabulary", True) is False
        self.fitted_on: Optional[str] = None     # the recording whose own vocabulary all share

    def describe(self, source: str, *, cache=None, progress=None, cancel=None) -> Descriptors:
        from . import descriptors as registry
        from .pipeline import describe

        if not self.fitting:
            return describe(source, self.settings, progress=progress, cancel=cancel, cache=cache, model=self.model)
        descs = describe(source, self.settings, progress=progress, cancel=cancel, cache=None, model=self.model)
        fixed = registry.get(self.settings.descriptor, **{**self.settings.options, "vocabulary": self.model.vocabulary})
        descs.meta["settings"] = fixed.settings()     # it was pooled over exactly these centres
        self.model, self.fitting, self.fitted_on = fixed, False, str(source)
        return descs


def check_vocabularies(named: Sequence[tuple[str, Descriptors]], fitted_on: Optional[str] = None) -> None:
    """One line when two recordings were each pooled over their own vocabulary (settings
    ``vocabulary`` "map", or the one this site fitted): their vectors do not compare."""
    own = [name for name, d in named if ((d.meta or {}).get("settings") or {}).get("vocabulary") == "map"]
    own += [fitted_on] if fitted_on else []
    if len(own) > 1:
        raise InputError(f"{own[0]} and {own[1]} were each described over their own vocabulary, so their "
                         f"descriptors do not compare: give the recordings themselves (a site describes them "
                         f"over one vocabulary), not .npz files described apart")


def load_session(session: SessionSource, settings, *, cache=None, progress=None, cancel=None,
                 shared: Optional[_SharedVocabulary] = None) -> Descriptors:
    """A session's descriptors: its .npz when named and present, else its recording described
    (through ``cache``: described again only when the cache has none; over the site's
    ``shared`` vocabulary where given)."""
    from .pipeline import describe, is_descriptor_file

    if session.descriptors and Path(session.descriptors).is_file():
        return Descriptors.load(session.descriptors)
    if session.source and Path(session.source).exists():
        if is_descriptor_file(session.source):
            return Descriptors.load(session.source)
        if shared is not None:
            return shared.describe(session.source, cache=cache, progress=progress, cancel=cancel)
        return describe(session.source, settings, progress=progress, cancel=cancel, cache=cache)
    where = session.descriptors or session.source or "nowhere recorded"
    raise InputError(f"session {session.name}: neither its descriptors nor its recording can be found ({where})")


def expand(inputs: Sequence[str]) -> tuple[list[SessionSource], dict]:
    """Sessions of ``inputs`` in order (a site map's sessions where it stands) and the
    decisions taken on the site maps among them."""
    from .pipeline import is_descriptor_file

    sessions: list[SessionSource] = []
    decisions = {"loops": [], "manual": [], "labels": []}
    new: list[tuple[int, str]] = []
    for path in inputs:
        if is_site_map(path):
            found, dec = read_site(path)
            for s in found:
                if any(s.name == other.name for other in sessions):
                    raise InputError(f"{path}: session {s.name} is already in the site")
            sessions.extend(found)
            for k in decisions:
                decisions[k].extend(dec.get(k, []))
        else:
            if not Path(path).exists():
                raise InputError(f"{path}: no such file or directory")
            new.append((len(sessions), str(path)))
            sessions.append(SessionSource("", "", ""))
    known = [s.source for s in sessions if s.source] + [s.descriptors for s in sessions if s.descriptors]
    for _, path in new:
        if any(_absolute(path) == _absolute(k) for k in known):
            raise InputError(f"{path}: already in the site")
    names = session_names([p for _, p in new], taken=[s.name for s in sessions if s.name])
    for (at, path), name in zip(new, names):
        if is_descriptor_file(path):
            sessions[at] = SessionSource(name, _absolute(path), _absolute(path))
        else:
            sessions[at] = SessionSource(name, _absolute(path), "")
    return sessions, decisions


def map_site(inputs: Sequence[str], params: MapParams = MapParams(), settings=None, *, cache=None,
             auto_thresholds: bool = False, progress=None, cancel=None) -> SiteResult:
    """One map of the recordings ``inputs`` (module notes); ``settings`` an
    ``engine.pipeline.DescribeSettings`` (the method's shift and options are added)."""
    from .pipeline import build_map, method_settings
    from .progress import check

    if not inputs:
        raise InputError("no recordings to map")
    sessions, decisions = expand(inputs)
    settings = method_settings(params, settings)
    shared = _SharedVocabulary(settings)
    parts = []
    for s in sessions:
        parts.append(load_session(s, settings, cache=cache, progress=progress, cancel=cancel, shared=shared))
        check(cancel)
    check_models([(s.name, d) for s, d in zip(sessions, parts)])
    check_vocabularies([(s.name, d) for s, d in zip(sessions, parts)], shared.fitted_on)
    notes = [f"{s.name}: {note}" for s, d in zip(sessions, parts) for note in getattr(d, "notes", ())]
    if any(d.features is None for d in parts) and any(d.features is not None for d in parts):
        notes.append("some recordings have no local features: the site is mapped without two-view geometry")
    descs, starts = combine(parts)
    if auto_thresholds:
        from .calibrate import paper_thresholds

        found = paper_thresholds(descs.vectors, params.neighbor_node_num)
        params = replace(params, **{k: v for k, v in found.items() if getattr(params, k) is None})
    if progress is not None:
        progress(0, 0, "building the map")
    topomap = build_map(descs, params, source=", ".join(s.name for s in sessions),
                        row_starts=starts, sessions=[s.name for s in sessions])
    counts = {}
    for name in topomap.node_sessions().tolist():
        counts[name] = counts.get(name, 0) + 1
    records = [{"session": s.name, "source": s.source, "descriptors": s.descriptors, "nodes": counts.get(s.name, 0)}
               for s in sessions]
    topomap.graph.graph["sessions"] = topomap.meta["sessions"] = json.dumps(records)
    if any(decisions.values()):
        topomap.apply_decisions(decisions)
    return SiteResult(topomap, descs, sessions, starts, components(topomap), notes)


def components(topomap) -> list[list[str]]:
    """Groups of sessions joined by the loops the exported map holds (auto, confirmed,
    manual), largest first; one group when every recording is joined to the others."""
    names = topomap.node_sessions()
    if names is None:
        return []
    order = list(dict.fromkeys(names.tolist()))
    parent = {s: s for s in order}

    def root(s: str) -> str:
        while parent[s] != s:
            parent[s] = parent[parent[s]]
            s = parent[s]
        return s

    session = {n: str(d.get("session", "")) for n, d in topomap.graph.nodes(data=True)}
    for u, v, _ in topomap.loops(statuses=("auto", "confirmed", "manual")):
        a, b = root(session[u]), root(session[v])
        if a != b:
            parent[b] = a
    groups: dict[str, list[str]] = {}
    for s in order:
        groups.setdefault(root(s), []).append(s)
    return sorted(groups.values(), key=lambda g: -len(g))


def components_line(groups: list[list[str]]) -> Optional[str]:
    """One line for the user when the site falls apart, else None."""
    if len(groups) <= 1:
        return None
    alone = [g[0] for g in groups if len(g) == 1]
    parts = " | ".join(", ".join(g) for g in groups)
    if len(alone) == 1 and len(groups) == 2:
        return f"{alone[0]} joins no other recording: the map has {len(groups)} separate parts ({parts})"
    return f"no loop joins these recordings: the map has {len(groups)} separate parts ({parts})"
