"""The open map and the user's decisions on it, in plain Python (no Qt).

Every view reads from here and every edit goes through here, so the views stay in
step. Loops are addressed by a *key*, the pair of source frames of their two nodes
(smaller first): node ids change when a parameter change rebuilds the map, source
frames do not, and ``TopoMap.decisions()`` is keyed the same way.

Changes are announced by name to listeners (``on(event, fn)``); the Qt ``Document``
turns the same names into Qt signals. Events: ``mapReplaced``, ``loopsChanged``,
``labelsChanged``, ``posesChanged``, ``evaluationChanged``, ``sourceChanged``,
``estimatedYaw`` (key), ``similarityReady``, ``journalFailed`` (message).

Every decision (a status, a manual loop added or removed, a place name) passes
through ``record_decision`` as one plain record (see ``gui.model.journal``), the
single point where a write-through journal hooks in.

A site (several recordings, ``gui.model.site``): ``site`` is set, and every frame the
document speaks of (keys, ``node_frames``, labels) is a *site frame*; what it writes for
the engine or the journal names each recording and its own frame (``address``).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from engine.params import MapParams

from . import journal as journal_records
from . import similarity
from .history import Command, History
from .loop_key import LoopKey, address_item, address_key, frames_key  # noqa: F401  (re-exported)
from .similarity import Similarity

# Loop tiers and decisions. "candidate": found but not accepted, waiting for a person;
# "auto": accepted automatically; the rest are a person's decisions.
STATUSES = ("candidate", "auto", "confirmed", "rejected", "manual")
UNDECIDED = ("candidate", "auto")     # not decided by a person yet: what the review queue walks
DECIDED = ("confirmed", "rejected")   # a person's verdict on a detected loop


@dataclass
class LoopRow:
    """One loop arc as the table and the views show it (plain values)."""

    key: LoopKey
    u: str                 # node id of the earlier node
    v: str
    index_u: int
    index_v: int
    similarity: float
    window_count: int
    yaw: Optional[float]
    status: str
    tier: str = "auto"                     # what detection made of it: "candidate", "auto" or "manual"
    sessions: Optional[tuple[str, str]] = None   # a site: the recordings of u and v (site order)
    # The evidence behind a detected loop, where the engine gives it (engine.graph.EVIDENCE_KEYS).
    score: Optional[float] = None          # calibrated descriptor score (sigmas above the background)
    inliers: Optional[int] = None          # local features consistent with one two-view model
    inlier_ratio: Optional[float] = None
    support: Optional[float] = None        # the score along the matched stretch (sequence support)
    matches: Optional[int] = None
    direction: Optional[int] = None        # +1 same way, -1 reverse
    confidence: Optional[float] = None     # the engine's ranking for the review queue

    @property
    def undecided(self) -> bool:
        return self.status in UNDECIDED

    @property
    def evidence(self) -> float:
        """The number the queue ranks by: the engine's confidence, else the calibrated score,
        else the cosine similarity (maps made before the tiers, manual loops)."""
        for value in (self.confidence, self.score, self.similarity):
            if value is not None and not math.isnan(value):
                return float(value)
        return -math.inf


@dataclass
class PreparedMap:
    """A map made ready to show: decisions applied, indexes and rows computed.

    ``prepare_map`` builds it from the map alone, so a worker thread can do all of it
    and the UI thread only swaps it in (20,000 nodes: about a second of Python).
    """

    topomap: object                      # engine.graph.TopoMap
    node_of_frame: dict[int, str]
    frames: np.ndarray                   # source frame of each node, by node index
    tiers: dict[LoopKey, str]            # the status detection gave each loop
    rows: list[LoopRow]
    poses: object = None                 # the poses its positions came from
    decision_version: int = -1           # the document's decisions it carries (see MapDocument)
    extras: dict = field(default_factory=dict)  # what views asked to compute ahead (``preparers``)


def prepare_map(topomap, decisions: Optional[dict] = None, poses=None,
                preparers: Optional[dict[str, Callable]] = None, site=None) -> PreparedMap:
    """Index ``topomap``, note each loop's tier, apply ``decisions`` and ``poses``, make its rows,
    and run each of ``preparers`` (name -> fn(topomap)) into ``extras``. ``site``: the
    ``gui.model.site.Site`` the map is of (its nodes are then addressed by site frames).

    Touches only ``topomap`` (safe in a worker thread while the UI shows another map).
    """
    g = topomap.graph
    places = _places(topomap, site)
    node_of_frame = {int(places[int(d["index"])]): n for n, d in g.nodes(data=True)}
    frames = places
    # Before the decisions overwrite the statuses; engine maps since the tiers also carry "tier".
    tiers = {_key(g, u, v, site): str(attrs.get("tier", attrs.get("status", "auto")))
             for u, v, attrs in topomap.loops()}
    if decisions and any(decisions.get(k) for k in ("loops", "manual")):
        topomap.apply_decisions(decisions)
        if topomap.graph.graph.get("positions") == "estimated":
            topomap.graph.graph["positions"] = "before decisions"   # estimated without them: stale
    elif decisions:
        topomap.apply_decisions(decisions)
    if poses is not None:
        x, y = poses.at(np.asarray(topomap.stamps(), np.float64))
        topomap.set_positions(x, y)
    extras = {name: fn(topomap) for name, fn in (preparers or {}).items()}
    return PreparedMap(topomap, node_of_frame, frames, tiers, make_loop_rows(topomap, tiers, site), poses,
                       extras=extras)


def _places(topomap, site) -> np.ndarray:
    """Each node's source frame (a site: its site frame), in node order."""
    if site is not None and topomap.node_sessions() is not None:
        return site.node_places(topomap)
    return np.asarray(topomap.frames(), np.int64)


def make_loop_rows(topomap, tiers: dict[LoopKey, str], site=None) -> list[LoopRow]:
    """The loop arcs of ``topomap`` as rows, in node order."""
    g = topomap.graph
    rows = []
    for u, v, attrs in topomap.loops():
        iu, iv = int(g.nodes[u]["index"]), int(g.nodes[v]["index"])
        if iu > iv:
            u, v, iu, iv = v, u, iv, iu
        key = _key(g, u, v, site)
        sessions = None
        if site is not None and "session" in g.nodes[u]:
            sessions = site.pair(str(g.nodes[u]["session"]), str(g.nodes[v]["session"]))
        status = str(attrs.get("status", "auto"))
        inliers, matches, direction = (_number(attrs.get(k)) for k in ("inliers", "matches", "direction"))
        rows.append(LoopRow(
            key=key, u=u, v=v, index_u=iu, index_v=iv,
            similarity=float(attrs.get("similarity", float("nan"))),
            window_count=int(attrs.get("window_count", 0) or 0),
            yaw=_number(attrs.get("yaw")),
            status=status,
            tier="manual" if status == "manual" else tiers.get(key, "auto"),
            score=_number(attrs.get("score")),
            inliers=None if inliers is None else int(inliers),
            inlier_ratio=_number(attrs.get("inlier_ratio")),
            support=_number(attrs.get("support")),
            matches=None if matches is None else int(matches),
            direction=None if direction is None else int(direction),
            confidence=_number(attrs.get("confidence")),
            sessions=sessions,
        ))
    rows.sort(key=lambda r: (r.index_u, r.index_v))
    return rows


def _key(g, u: str, v: str, site=None) -> LoopKey:
    du, dv = g.nodes[u], g.nodes[v]
    if site is not None and "session" in du:
        return frames_key((site.place(du["session"], du["frame"]), site.place(dv["session"], dv["frame"])))
    return frames_key((du["frame"], dv["frame"]))


class MapDocument:
    """Recording, descriptors, map, poses and the user's edits (plain Python)."""

    def __init__(self) -> None:
        self.input_path: Optional[Path] = None
        self.site = None                        # gui.model.site.Site when several recordings are open
        self.source = None                      # engine.frames.FrameSource for the viewer
        # engine.pipeline.DescribeSettings as the user chose them: the run adds the method's
        # describe options (engine.pipeline.method_settings), so another method gets its own.
        self.describe_settings = None
        self.params = MapParams()
        self.descs = None                       # engine.descriptors.base.Descriptors
        self.topomap = None                     # engine.graph.TopoMap
        self.poses = None                       # engine.poses.Poses
        self.poses_path: Optional[str] = None
        self.poses_topic: Optional[str] = None
        self.session_path: Optional[Path] = None
        self.evaluation = None
        self.dist_th = 1.0
        self.history = History(self)            # the Qt window swaps in its QUndoStack adapter
        self.journal = None                     # anything with append(record): decisions written through
        # name -> fn(topomap): per-map work a view wants done with the map, off the UI thread
        # (the graph view's layout); read back with ``prepared``.
        self.preparers: dict[str, Callable] = {}
        self._extras: dict = {}
        self._listeners: dict[str, list[Callable]] = {}
        self._node_of_frame: dict[int, str] = {}
        self._frames = np.zeros(0, np.int64)
        self._row_places: Optional[np.ndarray] = None   # descriptor rows' site frames (a site)
        self.decision_version = 0               # +1 on every decision: a map prepared meanwhile is stale
        self._similarity: Optional[Similarity] = None
        self._rows: Optional[list[LoopRow]] = None
        self._tiers: dict[LoopKey, str] = {}    # the status detection gave each loop (for "reset")
        # Relative yaws estimated from the images for pairs whose loop has none (by key).
        self.estimated_yaws: dict[LoopKey, float] = {}

    # -- events ----------------------------------------------------------------
    def on(self, event: str, fn: Callable) -> None:
        self._listeners.setdefault(event, []).append(fn)

    def _notify(self, event: str, *args) -> None:
        for fn in list(self._listeners.get(event, ())):
            fn(*args)

    # -- whole-document changes ------------------------------------------------
    def set_source(self, path: Optional[Path], source) -> None:
        if self.source is not None and self.source is not source:
            self.source.close()
        self.estimated_yaws = {}
        self.input_path = path
        self.source = source
        self._notify("sourceChanged")

    def close(self) -> None:
        if self.source is not None:
            self.source.close()
        self.source = None

    def replace_map(self, topomap, descs=None, decisions: Optional[dict] = None) -> None:
        """Show a new map; ``decisions`` (from the old map, a session or a journal) are re-applied."""
        self.install(prepare_map(topomap, decisions, self.poses, site=self.site), descs)  # small maps, tests: here

    def remap_job(self, build: Callable[[], object], decisions: Optional[dict] = None) -> Callable[[], PreparedMap]:
        """A function for a worker thread: ``build()`` a map and prepare it with today's decisions
        (or with ``decisions``: a session or journal being opened).

        The decisions are copied from the map shown now, here on the UI thread: the worker
        gets a snapshot and never reads the live map (a decision made while it read them
        changed a dict under it). A decision made while it runs bumps ``decision_version``
        and ``is_current`` then refuses the result (the caller asks again), so no decision
        is ever lost to a re-map.
        """
        old, poses, version, site = self.topomap, self.poses, self.decision_version, self.site
        preparers = dict(self.preparers)
        carried = copy.deepcopy(decisions if decisions is not None else (old.decisions() if old is not None else {}))

        def job() -> PreparedMap:
            prepared = prepare_map(build(), carried, poses, preparers, site=site)
            prepared.decision_version = version
            return prepared

        return job

    def is_current(self, prepared: PreparedMap) -> bool:
        """Was ``prepared`` made from the decisions and poses of now?"""
        return prepared.decision_version == self.decision_version and prepared.poses is self.poses

    def install(self, prepared: PreparedMap, descs=None) -> None:
        """Show a prepared map (the only work left on the UI thread: swapping it in)."""
        if descs is not None:
            self.descs = descs
        self.topomap = prepared.topomap
        self._node_of_frame = prepared.node_of_frame
        self._frames = prepared.frames
        self._row_places = None
        self._tiers = prepared.tiers
        self._rows = prepared.rows
        self._extras = prepared.extras
        self._similarity = None
        if prepared.poses is not self.poses:
            self._update_positions()
        self._notify("mapReplaced")
        self.evaluate()

    def clear_map(self) -> None:
        """Forget the map and descriptors (a new recording is being opened)."""
        self.topomap = None
        self.descs = None
        self.evaluation = None
        self._similarity = None
        self._rows = None
        self._tiers = {}
        self._node_of_frame = {}
        self._frames = np.zeros(0, np.int64)
        self._row_places = None

    def set_poses(self, poses, path: Optional[str], topic: Optional[str] = None) -> None:
        self.poses, self.poses_path, self.poses_topic = poses, path, topic
        self._update_positions()
        self._notify("posesChanged")
        self.evaluate()

    def _update_positions(self) -> None:
        if self.topomap is None or self.poses is None:
            return
        x, y = self.poses.at(np.asarray(self.topomap.stamps(), np.float64))
        self.topomap.set_positions(x, y)

    # -- queries -----------------------------------------------------------------
    @property
    def has_map(self) -> bool:
        return self.topomap is not None

    def node_count(self) -> int:
        return 0 if self.topomap is None else int(self.topomap.node_count)

    def node_id(self, k: int) -> str:
        return self.topomap.node_id(k)

    def node_data(self, node: str) -> dict:
        return self.topomap.graph.nodes[node]

    def node_of_frame(self, frame: int) -> Optional[str]:
        return self._node_of_frame.get(int(frame))

    def node_frames(self) -> np.ndarray:
        """Source frame of each node, by node index (computed once per map)."""
        return self._frames if self.topomap is not None else np.zeros(0, np.int64)

    def node_at_or_before(self, frame: int) -> Optional[int]:
        """Index of the node that represents source frame ``frame`` (the last node at or before it)."""
        frames = self.node_frames()
        if frames.size == 0:
            return None
        k = max(int(np.searchsorted(frames, frame, side="right")) - 1, 0)
        if self.site is not None:   # a site: a node of the frame's own recording (its first one)
            lo, hi = self.site.span_of(self.site.local(frame)[0])
            if frames[k] < lo:
                first = int(np.searchsorted(frames, lo, side="left"))
                if first < frames.size and frames[first] < hi:
                    k = first
        return k

    def key_of(self, u: str, v: str) -> LoopKey:
        return _key(self.topomap.graph, u, v, self.site)

    # -- where things are: one recording, or a site's recordings -----------------------
    def address(self, key: LoopKey) -> tuple[list[int], Optional[list[str]]]:
        """(frames, recordings) of ``key`` as the engine and the journal name it: the
        frames themselves for one recording; each recording's own frame in a site."""
        if self.site is None:
            return [int(key[0]), int(key[1])], None
        return self.site.address(key)

    def key_of_address(self, frames, sessions=None) -> LoopKey:
        """The key of an address on disk (the inverse of ``address``)."""
        if self.site is None:
            return frames_key(frames)
        return self.site.key_of(frames, sessions)

    def place_text(self, frame: int) -> str:
        """How a frame is named to the user: "frame 12" (a site: "A.mp4 frame 12")."""
        return f"frame {int(frame)}" if self.site is None else self.site.place_text(frame)

    def node_place(self, k: int) -> int:
        """The frame (a site: the site frame) of node index ``k``."""
        return int(self.node_frames()[int(k)])

    def descriptors_only(self) -> bool:
        """The map is made from descriptors files only (nothing can be described again)."""
        if self.site is not None:
            return self.site.descriptors_only
        return str(self.input_path).endswith(".npz")

    def descriptor_places(self) -> np.ndarray:
        """The frame (a site: the site frame) of each descriptor row."""
        if self.descs is None:
            return np.zeros(0, np.int64)
        if self.site is None:
            return np.asarray(self.descs.frames, np.int64)
        if getattr(self, "_row_places", None) is None or len(self._row_places) != len(self.descs):
            self._row_places = self.site.row_places(self.descs)
        return self._row_places

    def descriptor_row(self, frame: int) -> Optional[int]:
        """The descriptor row of ``frame`` (a site: site frame), or None."""
        rows = np.flatnonzero(self.descriptor_places() == int(frame))
        return int(rows[0]) if rows.size else None

    def key_of_nodes(self, a: int, b: int) -> LoopKey:
        """The key of the pair of node indices ``a``, ``b``."""
        return self.key_of(self.node_id(a), self.node_id(b))

    def nodes_of(self, key: LoopKey) -> Optional[tuple[str, str]]:
        u, v = self.node_of_frame(key[0]), self.node_of_frame(key[1])
        if u is None or v is None:
            return None
        return u, v

    def loop_attrs(self, key: LoopKey) -> Optional[dict]:
        nodes = self.nodes_of(key)
        if nodes is None or self.topomap is None:
            return None
        data = self.topomap.graph.get_edge_data(*nodes)
        if not data or data.get("kind") != "loop":
            return None
        return dict(data)

    def status_of(self, key: LoopKey) -> Optional[str]:
        attrs = self.loop_attrs(key)
        return None if attrs is None else str(attrs.get("status", "auto"))

    def tier_of(self, key: LoopKey) -> str:
        """What detection made of the loop ("candidate" or "auto"): where "reset" takes it back to."""
        return self._tiers.get(tuple(key), "auto")

    def loop_rows(self) -> list[LoopRow]:
        """The loop arcs in node order (cached until the next edit)."""
        if self._rows is None:
            self._rows = self._make_loop_rows()
        return self._rows

    def _make_loop_rows(self) -> list[LoopRow]:
        return [] if self.topomap is None else make_loop_rows(self.topomap, self._tiers, self.site)

    def prepared(self, name: str, fallback: Callable):
        """What preparer ``name`` computed for the current map, else ``fallback(topomap)`` now."""
        if name in self._extras:
            return self._extras[name]
        return fallback(self.topomap)

    def similarity(self) -> Optional[np.ndarray]:
        """Cosine similarity between every pair of nodes (computed here when not ready yet).

        The window computes it off the UI thread (``similarity_job`` + ``set_similarity``);
        this blocking form serves callers that need it now.
        """
        if self._similarity is None:
            job = self.similarity_job()
            if job is None:
                return None
            self._similarity = job()
        return self._similarity.matrix

    def similarity_preview(self) -> Optional[tuple[np.ndarray, float]]:
        """(picture-sized block maxima, colour floor) of the matrix, once it is computed."""
        s = self._similarity
        return None if s is None else (s.preview, s.floor)

    def similarity_ready(self) -> bool:
        return self._similarity is not None

    def similarity_job(self) -> Optional[Callable[[], Similarity]]:
        """A function computing the similarity matrix of the current map and its preview
        (safe to run in a thread)."""
        if self.topomap is None or self.descs is None:
            return None
        vectors = self.descs.vectors[np.asarray(self.topomap.node_rows, np.int64)]
        return lambda: similarity.compute(vectors)

    def set_similarity(self, topomap, result: Similarity) -> bool:
        """Store a matrix computed in the background, unless the map changed meanwhile."""
        if topomap is not self.topomap:
            return False
        self._similarity = result
        self._notify("similarityReady")
        return True

    def pair_similarity(self, k_a: int, k_b: int) -> float:
        """Cosine of two nodes (from the matrix when it is ready, else from the two vectors)."""
        if self._similarity is not None:
            return float(self._similarity.matrix[k_a, k_b])
        if self.topomap is None or self.descs is None:
            return float("nan")
        rows = np.asarray(self.topomap.node_rows, np.int64)
        v = self.descs.vectors
        return float(np.dot(v[rows[k_a]], v[rows[k_b]]))

    def note_estimated_yaw(self, key: LoopKey, yaw: float) -> None:
        """Remember a yaw the pair view estimated, so the table can show it too."""
        if self.estimated_yaws.get(key) != yaw:
            self.estimated_yaws[key] = float(yaw)
            self._notify("estimatedYaw", key)

    def label_of_frame(self, frame: int) -> str:
        node = self.node_of_frame(frame)
        return "" if node is None else str(self.node_data(node).get("label", "") or "")

    # -- edits: through commands (undoable), one record each ----------------------
    def push(self, command: Command) -> None:
        """Apply an undoable edit through the history (the only way views edit)."""
        self.history.push(command)

    def record_decision(self, record: dict) -> None:
        """Every decision passes here as one plain record, as it is made (and as it is undone).

        The write-through hook: with a journal attached (``self.journal``), the record is
        appended to it at once, so a crash loses nothing.
        """
        self.decision_version += 1
        if self.journal is not None:
            try:
                self.journal.append(record)
            except OSError as exc:  # a full or vanished disk: the decision stands, the user is told
                self.journal = None
                self._notify("journalFailed", f"Decisions are no longer journaled ({exc.strerror or exc}): "
                                              "save the session now")

    # -- edits (called by the commands only) ---------------------------------------
    def set_loop_statuses(self, changes: dict[LoopKey, str]) -> None:
        """Set many statuses with one notification (a bulk action)."""
        for key, status in changes.items():
            if self.loop_attrs(key) is None:
                self._carry(key, status)  # an undo after a re-map dropped the loop
            else:
                self._set_status(key, status)
            frames, sessions = self.address(key)
            self.record_decision(journal_records.status(frames, status, sessions))
        self._after_loop_edit()

    def _carry(self, key: LoopKey, status: str) -> None:
        """A decision on a loop this map does not have: kept with the map's unapplied ones, so
        it comes back when a later map has the loop again (``TopoMap.apply_decisions``)."""
        frames, sessions = self.address(key)
        here = address_key(frames, sessions)
        unapplied = self.topomap.unapplied["loops"]
        unapplied[:] = [d for d in unapplied if address_key(d["frames"], d.get("sessions")) != here]
        if status not in UNDECIDED:
            unapplied.append({**address_item(frames, sessions), "status": status})

    def set_loop_status(self, key: LoopKey, status: str) -> None:
        self.set_loop_statuses({tuple(key): status})

    def _set_status(self, key: LoopKey, status: str) -> None:
        self.topomap.set_status(*self._require(key), status)

    def add_manual_loop(self, key: LoopKey, yaw: Optional[float] = None,
                        similarity: Optional[float] = None, status: str = "manual") -> None:
        u, v = self._nodes_near(key)
        self.topomap.add_manual_loop(u, v, yaw=yaw, similarity=similarity)  # None: from descriptors
        key = self.key_of(u, v)
        if status != "manual":
            self._set_status(key, status)
        frames, sessions = self.address(key)
        self.record_decision(journal_records.manual(frames, yaw, status, sessions))
        self._after_loop_edit()

    def remove_loop(self, key: LoopKey) -> None:
        self.topomap.remove_loop(*self._nodes_near(key))
        frames, sessions = self.address(key)
        self.record_decision(journal_records.removed(frames, sessions))
        self._after_loop_edit()

    def set_label(self, frame: int, label: str) -> None:
        node = self.node_of_frame(frame)
        if node is None:  # an undo after a re-map moved the nodes: the nearest, as apply_decisions does
            node = self.node_id(self._nearest_node(int(frame)))
        self.topomap.set_label(node, label)
        frames, sessions = self.address((frame, frame))
        self.record_decision(journal_records.label(frames[0], label, sessions[0] if sessions else None))
        self._rows = None
        self._notify("labelsChanged")

    def _nodes_near(self, key: LoopKey) -> tuple[str, str]:
        """The nodes at frames ``key``, else those nearest in frame (where ``TopoMap.apply_decisions``
        put a manual loop after a re-map moved the nodes)."""
        nodes = self.nodes_of(key) if self.topomap is not None else None
        if nodes is not None:
            return nodes
        if self.node_frames().size == 0:
            raise KeyError(f"no nodes at frames {key}")
        a, b = (self._nearest_node(int(f)) for f in key)
        return self.node_id(a), self.node_id(b)

    def _nearest_node(self, frame: int) -> int:
        """The node nearest in frame to ``frame`` (a site: among its own recording's nodes)."""
        frames = self.node_frames()
        candidates = np.arange(frames.size)
        if self.site is not None:
            lo, hi = self.site.span_of(self.site.local(frame)[0])
            mine = candidates[(frames >= lo) & (frames < hi)]
            if mine.size == 0:
                raise KeyError(f"no nodes of {self.site.local(frame)[0]} in this map")
            candidates = mine
        return int(candidates[int(np.argmin(np.abs(frames[candidates] - int(frame))))])

    def _require(self, key: LoopKey) -> tuple[str, str]:
        nodes = self.nodes_of(key) if self.topomap is not None else None
        if nodes is None:
            raise KeyError(f"no nodes at frames {key}")
        return nodes

    def _after_loop_edit(self) -> None:
        self._rows = None
        self._notify("loopsChanged")
        self.evaluate()

    # -- evaluation -------------------------------------------------------------
    def evaluate(self) -> None:
        old = self.evaluation
        self.evaluation = None
        if self.topomap is not None and self.poses is not None:
            from engine.evaluate import evaluate

            self.evaluation = evaluate(self.topomap, self.poses, dist_th=self.dist_th)
        if old is not None or self.evaluation is not None:
            self._notify("evaluationChanged")

    # -- session state -----------------------------------------------------------
    def decisions(self) -> dict[str, Any]:
        return self.topomap.decisions() if self.topomap is not None else {}


def _number(value) -> Optional[float]:
    """A float, or None for a missing or NaN attribute."""
    if value is None:
        return None
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(f) else f


from .run_plan import needs_remap  # noqa: E402,F401  (declared once, in run_plan)
