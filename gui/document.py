"""The open document: recording, descriptors, map, poses and the user's edits.

Every view reads from here and every edit goes through here, so the views stay in
step. Loops are addressed by a *key*, the pair of source frames of their two nodes
(smaller first): node ids change when a parameter change rebuilds the map, source
frames do not, and ``TopoMap.decisions()`` is keyed the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np
from PySide6.QtCore import QObject, Signal

from engine.params import MapParams

LoopKey = tuple[int, int]

STATUSES = ("auto", "confirmed", "rejected", "manual")


@dataclass
class LoopRow:
    """One loop arc as the table and the views show it."""

    key: LoopKey
    u: str                 # node id of the earlier node
    v: str
    index_u: int
    index_v: int
    similarity: float
    window_count: int
    yaw: Optional[float]
    status: str


class Document(QObject):
    mapReplaced = Signal()        # a new TopoMap: after a run or a parameter change
    loopsChanged = Signal()       # a loop status changed, a manual loop added or removed
    labelsChanged = Signal()
    posesChanged = Signal()
    evaluationChanged = Signal()
    sourceChanged = Signal()      # a new recording opened (or closed)
    estimatedYaw = Signal(object)  # LoopKey whose yaw was estimated from the images

    def __init__(self, parent: Optional[QObject] = None) -> None:
        super().__init__(parent)
        self.input_path: Optional[Path] = None
        self.source = None                      # engine.frames.FrameSource for the viewer
        self.describe_settings = None           # engine.pipeline.DescribeSettings
        self.params = MapParams()
        self.descs = None                       # engine.descriptors.base.Descriptors
        self.topomap = None                     # engine.graph.TopoMap
        self.poses = None                       # engine.poses.Poses
        self.poses_path: Optional[str] = None
        self.poses_topic: Optional[str] = None
        self.session_path: Optional[Path] = None
        self.evaluation = None
        self.dist_th = 1.0
        self._node_of_frame: dict[int, str] = {}
        self._similarity: Optional[np.ndarray] = None
        self._rows: Optional[list[LoopRow]] = None
        # Relative yaws estimated from the images for pairs whose loop has none (by key).
        self.estimated_yaws: dict[LoopKey, float] = {}

    # -- whole-document changes ------------------------------------------------
    def set_source(self, path: Optional[Path], source) -> None:
        if self.source is not None and self.source is not source:
            self.source.close()
        self.estimated_yaws = {}
        self.input_path = path
        self.source = source
        self.sourceChanged.emit()

    def close(self) -> None:
        if self.source is not None:
            self.source.close()
        self.source = None

    def replace_map(self, topomap, descs=None, decisions: Optional[dict] = None) -> None:
        """Show a new map; ``decisions`` (from the old map or a session) are re-applied."""
        if descs is not None:
            self.descs = descs
        if decisions:
            topomap.apply_decisions(decisions)
        self.topomap = topomap
        self._similarity = None
        self._rows = None
        self._index_nodes()
        self._update_positions()
        self.mapReplaced.emit()
        self.evaluate()

    def clear_map(self) -> None:
        """Forget the map and descriptors (a new recording is being opened)."""
        self.topomap = None
        self.descs = None
        self.evaluation = None
        self._similarity = None
        self._rows = None
        self._node_of_frame = {}

    def set_poses(self, poses, path: Optional[str], topic: Optional[str] = None) -> None:
        self.poses, self.poses_path, self.poses_topic = poses, path, topic
        self._update_positions()
        self.posesChanged.emit()
        self.evaluate()

    def _index_nodes(self) -> None:
        g = self.topomap.graph
        self._node_of_frame = {int(d["frame"]): n for n, d in g.nodes(data=True)}

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
        return np.asarray(self.topomap.frames(), np.int64) if self.topomap is not None else np.zeros(0, np.int64)

    def node_at_or_before(self, frame: int) -> Optional[int]:
        """Index of the node that represents source frame ``frame`` (the last node at or before it)."""
        frames = self.node_frames()
        if frames.size == 0:
            return None
        k = int(np.searchsorted(frames, frame, side="right")) - 1
        return max(k, 0)

    def key_of(self, u: str, v: str) -> LoopKey:
        g = self.topomap.graph
        fu, fv = int(g.nodes[u]["frame"]), int(g.nodes[v]["frame"])
        return (fu, fv) if fu <= fv else (fv, fu)

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

    def loop_rows(self) -> list[LoopRow]:
        """The loop arcs in node order (cached until the next edit)."""
        if self._rows is None:
            self._rows = self._make_loop_rows()
        return self._rows

    def _make_loop_rows(self) -> list[LoopRow]:
        if self.topomap is None:
            return []
        g = self.topomap.graph
        rows = []
        for u, v, attrs in self.topomap.loops():
            iu, iv = int(g.nodes[u]["index"]), int(g.nodes[v]["index"])
            if iu > iv:
                u, v, iu, iv = v, u, iv, iu
            yaw = attrs.get("yaw")
            rows.append(LoopRow(
                key=self.key_of(u, v), u=u, v=v, index_u=iu, index_v=iv,
                similarity=float(attrs.get("similarity", float("nan"))),
                window_count=int(attrs.get("window_count", 0) or 0),
                yaw=None if yaw is None or (isinstance(yaw, float) and np.isnan(yaw)) else float(yaw),
                status=str(attrs.get("status", "auto")),
            ))
        rows.sort(key=lambda r: (r.index_u, r.index_v))
        return rows

    def similarity(self) -> Optional[np.ndarray]:
        """Cosine similarity between every pair of nodes (computed once per map)."""
        if self.topomap is None or self.descs is None:
            return None
        if self._similarity is None:
            from engine.loops import similarity_matrix

            rows = np.asarray(self.topomap.node_rows, np.int64)
            self._similarity = similarity_matrix(self.descs.vectors[rows])
        return self._similarity

    def pair_similarity(self, k_a: int, k_b: int) -> float:
        sim = self.similarity()
        return float("nan") if sim is None else float(sim[k_a, k_b])

    def note_estimated_yaw(self, key: LoopKey, yaw: float) -> None:
        """Remember a yaw the pair view estimated, so the table can show it too."""
        if self.estimated_yaws.get(key) != yaw:
            self.estimated_yaws[key] = float(yaw)
            self.estimatedYaw.emit(key)

    # -- edits (called by the undo commands only) ------------------------------
    def set_loop_status(self, key: LoopKey, status: str) -> None:
        nodes = self._require(key)
        self.topomap.set_status(*nodes, status)
        self._after_loop_edit()

    def add_manual_loop(self, key: LoopKey, yaw: Optional[float] = None,
                        similarity: Optional[float] = None, status: str = "manual") -> None:
        u, v = self._require(key)
        self.topomap.add_manual_loop(u, v, yaw=yaw, similarity=similarity)  # None: from descriptors
        if status != "manual":
            self.topomap.set_status(u, v, status)
        self._after_loop_edit()

    def remove_loop(self, key: LoopKey) -> None:
        self.topomap.remove_loop(*self._require(key))
        self._after_loop_edit()

    def set_label(self, frame: int, label: str) -> None:
        node = self.node_of_frame(frame)
        if node is None:
            raise KeyError(f"no node at frame {frame}")
        self.topomap.set_label(node, label)
        self._rows = None
        self.labelsChanged.emit()

    def label_of_frame(self, frame: int) -> str:
        node = self.node_of_frame(frame)
        return "" if node is None else str(self.node_data(node).get("label", "") or "")

    def _require(self, key: LoopKey) -> tuple[str, str]:
        nodes = self.nodes_of(key) if self.topomap is not None else None
        if nodes is None:
            raise KeyError(f"no nodes at frames {key}")
        return nodes

    def _after_loop_edit(self) -> None:
        self._rows = None
        self.loopsChanged.emit()
        self.evaluate()

    # -- evaluation -------------------------------------------------------------
    def evaluate(self) -> None:
        old = self.evaluation
        self.evaluation = None
        if self.topomap is not None and self.poses is not None:
            from engine.evaluate import evaluate

            self.evaluation = evaluate(self.topomap, self.poses, dist_th=self.dist_th)
        if old is not None or self.evaluation is not None:
            self.evaluationChanged.emit()

    # -- session state -----------------------------------------------------------
    def decisions(self) -> dict[str, Any]:
        return self.topomap.decisions() if self.topomap is not None else {}
