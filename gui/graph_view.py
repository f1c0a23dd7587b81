"""Graph view: nodes and arcs of the map, loops styled by status, toggles per status.

Nodes sit at ground-truth positions when poses are loaded, else on a layout of
the map as decided (``gui.model.layout``). Every loop is a curve that bulges away from the path
(``gui.loop_arcs``), so a true loop between two nodes at one position is visible.
A strip above the plot (never over the path) shows one toggle per status with its
count. Click a node: jump to its frame. Click a loop: select it. Ctrl+click a
second node: propose a manual loop between it and the current node.

A site (several recordings): each recording's path and nodes in its own colour
(``style.recording_color``), no path arc from one recording to the next, a start and an
end marker per recording, and a legend strip naming each recording in its colour.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QCheckBox, QGridLayout, QLabel, QSizePolicy, QVBoxLayout, QWidget

from .document import Document, LoopKey
from .background import Worker
from .model.layout import chain_breaks, decided_graph, path_layout, path_pairs, solve_layout
from .loop_arcs import distance_to_curves, loop_curves, nan_joined
from .style import (CURRENT_COLOR, NODE_COLOR, SELECTED_COLOR, SEQUENTIAL_COLOR, STATUS_COLORS,
                    STATUS_LABELS, STATUS_ORDER, recording_color, status_pen)

CLICK_RADIUS_PX = 9
# What a status toggle says on a view too narrow for the full names (the tooltip has them).
STATUS_SHORT = {"candidate": "cand", "auto": "auto", "confirmed": "conf", "manual": "man", "rejected": "rej"}


# Above this many nodes no marker is drawn per node: at full view they only overlap, and
# placing 20,000 scatter markers takes 45-65 ms of the UI thread (issue 14: no stall over
# 100 ms while re-mapping 20,000 nodes); the path line costs 7 ms.
MARKED_NODES_MAX = 5000


class GraphView(QWidget):
    nodeClicked = Signal(int)           # node index
    loopClicked = Signal(object)        # LoopKey
    manualLoopRequested = Signal(int, int)  # node indices (current node, ctrl+clicked node)

    def __init__(self, doc: Document, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.x = np.zeros(0)
        self.y = np.zeros(0)
        self.current_node: Optional[int] = None
        self.selected_key: Optional[LoopKey] = None
        self._loop_segments: list[tuple[LoopKey, int, int]] = []   # the loops drawn (shown statuses)
        self._loop_curves = np.zeros((0, 2, 2))

        self.plot = pg.PlotWidget(background="w")
        self.plot.setAspectLocked(True)
        self.plot.showGrid(x=True, y=True, alpha=0.15)
        self.plot.setMenuEnabled(False)
        self.plot.getPlotItem().hideButtons()
        self.selected_item = pg.PlotDataItem(pen=pg.mkPen(pg.mkColor(SELECTED_COLOR), width=7))
        self.selected_item.setOpacity(0.45)
        self.plot.addItem(self.selected_item)
        self.sequential_item = pg.PlotDataItem(pen=pg.mkPen(SEQUENTIAL_COLOR, width=1.5), name="path (sequential)")
        self.plot.addItem(self.sequential_item)
        self.recording_items: list[pg.PlotDataItem] = []   # a site: one path per recording, in its colour
        self.loop_items: dict[str, pg.PlotDataItem] = {}
        self.toggles: dict[str, QCheckBox] = {}
        for status in reversed(STATUS_ORDER):  # rejected drawn first, below the others
            item = pg.PlotDataItem(pen=status_pen(status, width=2), connect="finite")
            self.loop_items[status] = item
            self.plot.addItem(item)
        for status in STATUS_ORDER:
            box = QCheckBox(STATUS_LABELS[status])
            box.setChecked(True)
            box.setStyleSheet(f"QCheckBox {{ color: {STATUS_COLORS[status]}; font-weight: bold; }}")
            box.setToolTip(f"Show the {STATUS_LABELS[status]} loops in the graph")
            box.toggled.connect(self.redraw_loops)
            self.toggles[status] = box
        self.nodes_item = pg.ScatterPlotItem(size=6, pen=pg.mkPen("w", width=0.5), brush=pg.mkBrush(NODE_COLOR),
                                             name="node", hoverable=True, tip=self._node_tip)
        self.plot.addItem(self.nodes_item)
        self.start_item = pg.ScatterPlotItem(size=13, symbol="t1", pen=pg.mkPen("k"), brush=pg.mkBrush("#2ecc71"),
                                             name="start")
        self.end_item = pg.ScatterPlotItem(size=11, symbol="s", pen=pg.mkPen("k"), brush=pg.mkBrush("#f1c40f"),
                                           name="end")
        self.plot.addItem(self.start_item)
        self.plot.addItem(self.end_item)
        self.current_item = pg.ScatterPlotItem(size=16, pen=pg.mkPen(CURRENT_COLOR, width=3), brush=None,
                                               name="current frame")
        self.plot.addItem(self.current_item)
        self.label_items: list[pg.TextItem] = []
        self.plot.scene().sigMouseClicked.connect(self._scene_clicked)
        self.plot.setToolTip("Click a node to see its frame, click a loop to select it, "
                             "Ctrl+click a node to add a manual loop to the current node")

        # The toggles never set the view's minimum width: on a narrow view (a 1280-px screen)
        # they say less ("cand 49") and, only if that is still too wide, take a second row
        # (``_arrange_toggles``); never clipped, and the plot keeps its height where it can.
        self.toggle_strip = QWidget()
        self.toggle_strip.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self._toggle_grid = QGridLayout(self.toggle_strip)
        self._toggle_grid.setContentsMargins(4, 2, 4, 0)
        self._toggle_grid.setHorizontalSpacing(6)
        self._toggle_grid.setVerticalSpacing(0)
        self._toggle_columns = 0
        self._toggle_counts = {s: 0 for s in STATUS_ORDER}
        self._arrange_toggles()
        # A site: which colour is which recording (wraps on a narrow view; hidden for one recording).
        self.legend = QLabel()
        self.legend.setTextFormat(Qt.RichText)
        self.legend.setWordWrap(True)
        self.legend.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self.legend.setContentsMargins(6, 0, 4, 2)
        self.legend.setToolTip("The recordings of the site: each one's path and nodes are drawn in its colour")
        self.legend.setVisible(False)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(0)
        layout.addWidget(self.toggle_strip)
        layout.addWidget(self.legend)
        layout.addWidget(self.plot)

        # Without ground truth the map as decided is drawn, solved again after each decision
        # (issue 43, defect 2), off the UI thread from a copy of the decided graph.
        self.layout_worker = Worker(self)
        self._layout: Optional[tuple[object, np.ndarray, np.ndarray]] = None  # (map, x, y) solved since
        doc.mapReplaced.connect(self.rebuild)
        doc.posesChanged.connect(self.rebuild)
        doc.loopsChanged.connect(self.redraw_loops)
        doc.loopsChanged.connect(self.relayout)
        doc.labelsChanged.connect(self.redraw_labels)

    # -- drawing ---------------------------------------------------------------------
    def rebuild(self) -> None:
        """Place the nodes again (new map or new poses) and redraw everything."""
        if not self.doc.has_map:
            self.x = self.y = np.zeros(0)
        else:
            positions = self.doc.topomap.positions() if self.doc.poses is not None else None
            solved = self._layout if self._layout is not None and self._layout[0] is self.doc.topomap else None
            if positions is not None:
                self.x, self.y = positions
            elif solved is not None:   # solved again after a decision
                self.x, self.y = solved[1], solved[2]
            else:                      # computed with the map, off the UI thread
                self.x, self.y = self.doc.prepared("layout", path_layout)
        with_gt = self.doc.poses is not None and self.doc.has_map
        self.plot.setLabel("bottom", "x (m)" if with_gt else "")
        self.plot.setLabel("left", "y (m)" if with_gt else "")
        for axis in ("left", "bottom"):  # after setLabel, which shows the axis again
            self.plot.getPlotItem().showAxis(axis, with_gt)
        self.plot.showGrid(x=with_gt, y=with_gt, alpha=0.15)
        title = ("Ground-truth positions" if with_gt else
                 ("The map as decided (no ground truth loaded)" if self.doc.has_map else ""))
        if title:  # the node markers' key, in the title: no legend box over the path
            title += (" &nbsp; <span style='color:#2ecc71'>▲</span> start <span style='color:#f1c40f'>■</span> end "
                      f"<span style='color:{CURRENT_COLOR}'>◯</span> current")
        self.plot.setTitle(title, color="#444", size="9pt")
        n = self.x.size
        recording = self._recording_of_nodes(n)
        breaks = chain_breaks(self.doc.topomap) if recording is not None else ()
        path = path_pairs(n, breaks)
        self.sequential_item.setData(_pairs(self.x, path[:, 0], path[:, 1]) if recording is None else [],
                                     _pairs(self.y, path[:, 0], path[:, 1]) if recording is None else [],
                                     connect="pairs")
        self._draw_recordings(path, recording)
        if n <= MARKED_NODES_MAX:
            brush = (None if recording is None else
                     [pg.mkBrush(recording_color(i)) for i in recording])
            self.nodes_item.setData(x=self.x, y=self.y, data=np.arange(n),
                                    brush=brush if brush is not None else pg.mkBrush(NODE_COLOR))
        else:   # markers would only overlap; the path is drawn and clicks still pick the nearest node
            self.nodes_item.setData([], [])
        starts = np.concatenate([[0], np.asarray(breaks, np.int64)]).astype(np.int64) if n else np.zeros(0, np.int64)
        ends = np.concatenate([np.asarray(breaks, np.int64) - 1, [n - 1]]).astype(np.int64) if n else starts
        self.start_item.setData(x=self.x[starts], y=self.y[starts])   # one per recording of a site
        self.end_item.setData(x=self.x[ends], y=self.y[ends])
        self.redraw_loops()
        self.redraw_labels()
        self.set_current_node(self.current_node)
        if n:
            self.plot.getPlotItem().enableAutoRange()
            self.plot.autoRange(padding=0.06)

    def _arrange_toggles(self) -> None:
        """The status toggles on one row, in full ("candidate (49)") where that fits the view's
        width, else short ("cand 49"), else short in as many columns as fit; called again when
        the view is resized or the counts change."""
        boxes = list(self.toggles.values())
        spacing = self._toggle_grid.horizontalSpacing()
        room = self.width() - 8
        for short in (False, True):
            for status, box in self.toggles.items():
                n = self._toggle_counts.get(status, 0)
                box.setText(f"{STATUS_SHORT[status]} {n}" if short else f"{STATUS_LABELS[status]} ({n})")
            total = sum(b.sizeHint().width() for b in boxes) + spacing * (len(boxes) - 1)
            if total <= room:
                break
        widest = max(b.sizeHint().width() for b in boxes) + spacing
        columns = len(boxes) if total <= room else max(1, room // widest)
        if columns == self._toggle_columns:
            return
        self._toggle_columns = columns
        for b in boxes:
            self._toggle_grid.removeWidget(b)
        for i, b in enumerate(boxes):
            self._toggle_grid.addWidget(b, i // columns, i % columns)
        for c in range(len(boxes) + 1):
            self._toggle_grid.setColumnStretch(c, 1 if c == columns else 0)

    def resizeEvent(self, event) -> None:
        super().resizeEvent(event)
        self._arrange_toggles()

    def _recording_of_nodes(self, n: int) -> Optional[np.ndarray]:
        """A site: each node's recording (index in the site), else None; the legend follows."""
        site = self.doc.site if self.doc.has_map else None
        sessions = self.doc.topomap.node_sessions() if site is not None else None
        if sessions is None or len(sessions) != n:
            self.legend.setVisible(False)
            return None
        index = {name: i for i, name in enumerate(site.names)}
        recording = np.array([index.get(str(s), 0) for s in sessions], np.int64)
        counts = np.bincount(recording, minlength=len(site.names))
        # A bar in the path's colour (not a square: the status toggles above are squares of theirs).
        self.legend.setText(" &nbsp; ".join(
            f"<span style='color:{recording_color(i)}'><b>▬</b></span>&nbsp;{name}" for i, name in enumerate(site.names)))
        self.legend.setToolTip("The recordings of the site, each one's path and nodes in its colour:\n" + "\n".join(
            f"{name}: {counts[i]} nodes" for i, name in enumerate(site.names)))
        self.legend.setVisible(True)
        return recording

    def _draw_recordings(self, path: np.ndarray, recording: Optional[np.ndarray]) -> None:
        """A site: each recording's path in its colour (one item per recording)."""
        wanted = 0 if recording is None else int(recording.max()) + 1 if recording.size else 0
        while len(self.recording_items) < wanted:
            item = pg.PlotDataItem(connect="pairs")
            item.setZValue(-0.5)   # under the loops and the markers
            self.plot.addItem(item)
            self.recording_items.append(item)
        while len(self.recording_items) > wanted:
            self.plot.removeItem(self.recording_items.pop())
        for i, item in enumerate(self.recording_items):
            mine = path[recording[path[:, 0]] == i]
            item.setPen(pg.mkPen(recording_color(i), width=2.5))
            item.setData(_pairs(self.x, mine[:, 0], mine[:, 1]), _pairs(self.y, mine[:, 0], mine[:, 1]),
                         connect="pairs")

    def relayout(self) -> None:
        """Solve the layout again for the decisions of now (no ground truth loaded)."""
        if not self.doc.has_map or self.doc.poses is not None:
            return
        topomap = self.doc.topomap
        graph = decided_graph(topomap, decided_since=True)   # a copy: the user goes on deciding
        start = np.stack([self.x, self.y], axis=1) if self.x.size == graph.n else None
        self.layout_worker.submit(lambda: solve_layout(graph, start),
                                  lambda xy: self._laid_out(topomap, xy))

    def _laid_out(self, topomap, xy: np.ndarray) -> None:
        if topomap is not self.doc.topomap or self.doc.poses is not None:
            return
        self._layout = (topomap, xy[:, 0].copy(), xy[:, 1].copy())
        self.rebuild()

    def shutdown(self) -> None:
        """Stop the layout thread (before the window goes)."""
        self.layout_worker.stop()

    def redraw_loops(self) -> None:
        """Draw the loops of the shown statuses as curves; count every status on its toggle."""
        rows = self.doc.loop_rows() if self.doc.has_map and self.x.size else []
        counts = self.loop_counts()
        for status, box in self.toggles.items():
            box.setToolTip(f"Show the {STATUS_LABELS[status]} loops in the graph ({counts[status]})")
        self._toggle_counts = dict(counts)
        self._arrange_toggles()   # the texts' widths changed: fit them again
        shown = [r for r in rows if self.status_shown(r.status)]
        self._loop_segments = [(r.key, r.index_u, r.index_v) for r in shown]
        pairs = np.array([(a, b) for _, a, b in self._loop_segments], dtype=np.int64).reshape(-1, 2)
        self._loop_curves = loop_curves(self.x, self.y, pairs)
        statuses = np.array([r.status for r in shown])
        for status, item in self.loop_items.items():
            item.setData(*nan_joined(self._loop_curves[statuses == status]), connect="finite")
        self.set_selected_loop(self.selected_key)

    def status_shown(self, status: str) -> bool:
        """Whether loops of ``status`` are drawn (its toggle is on; unknown statuses always)."""
        box = self.toggles.get(status)
        return box is None or box.isChecked()

    def loop_counts(self) -> dict[str, int]:
        """Number of loops per status, as the toggles show them."""
        counts = {s: 0 for s in STATUS_ORDER}
        for row in self.doc.loop_rows() if self.doc.has_map else []:
            counts[row.status] = counts.get(row.status, 0) + 1
        return counts

    def redraw_labels(self) -> None:
        for item in self.label_items:
            self.plot.removeItem(item)
        self.label_items = []
        if not self.doc.has_map or self.x.size == 0:
            return
        for node, data in self.doc.topomap.graph.nodes(data=True):
            if data.get("label"):
                k = int(data["index"])
                text = pg.TextItem(str(data["label"]), color="#111", anchor=(0.5, 1.3),
                                   fill=pg.mkBrush(255, 255, 255, 200), border=pg.mkPen("#999"))
                text.setPos(self.x[k], self.y[k])
                self.plot.addItem(text)
                self.label_items.append(text)

    def set_current_node(self, k: Optional[int]) -> None:
        self.current_node = k
        if k is None or not (0 <= k < self.x.size):
            self.current_item.setData([], [])
            return
        self.current_item.setData([self.x[k]], [self.y[k]])

    def set_selected_loop(self, key: Optional[LoopKey]) -> None:
        self.selected_key = key
        match = [(a, b) for k, a, b in self._loop_segments if k == key] if key is not None else []
        if not match and key is not None and self.doc.has_map and self.doc.nodes_of(key) is not None:
            u, v = self.doc.nodes_of(key)  # a pair that is not a loop (from the matrix)
            match = [(int(self.doc.node_data(u)["index"]), int(self.doc.node_data(v)["index"]))]
        if match and self.x.size:
            curve = loop_curves(self.x, self.y, np.array(match[:1]))
            self.selected_item.setData(*nan_joined(curve), connect="finite")
        else:
            self.selected_item.setData([], [])

    def _node_tip(self, x: float, y: float, data) -> str:
        if not self.doc.has_map:
            return ""
        node = self.doc.node_id(int(data))
        d = self.doc.node_data(node)
        label = f" “{d['label']}”" if d.get("label") else ""
        recording = f"\n{d['session']}" if d.get("session") else ""
        return f"{node}{label}{recording}\nframe {d['frame']}, t = {float(d['stamp']):.2f} s"

    # -- clicks ----------------------------------------------------------------------
    def _scene_clicked(self, event) -> None:
        if event.button() != Qt.LeftButton or self.x.size == 0:
            return
        vb = self.plot.getPlotItem().getViewBox()
        if not vb.sceneBoundingRect().contains(event.scenePos()):
            return
        p = vb.mapSceneToView(event.scenePos())
        k, dist = self.nearest_node(p.x(), p.y())
        ctrl = bool(event.modifiers() & Qt.ControlModifier)
        if k is not None and dist <= CLICK_RADIUS_PX:
            if ctrl and self.current_node is not None and k != self.current_node:
                self.manualLoopRequested.emit(self.current_node, k)
            else:
                self.nodeClicked.emit(k)
            event.accept()
            return
        key, ldist = self.nearest_loop(p.x(), p.y())
        if key is not None and ldist <= CLICK_RADIUS_PX:
            self.loopClicked.emit(key)
            event.accept()

    def _pixel_scale(self) -> tuple[float, float]:
        px, py = self.plot.getPlotItem().getViewBox().viewPixelSize()
        return max(px, 1e-12), max(py, 1e-12)

    def nearest_node(self, x: float, y: float) -> tuple[Optional[int], float]:
        """Nearest node and its distance in screen pixels."""
        if self.x.size == 0:
            return None, np.inf
        px, py = self._pixel_scale()
        d = np.hypot((self.x - x) / px, (self.y - y) / py)
        k = int(np.argmin(d))
        return k, float(d[k])

    def nearest_loop(self, x: float, y: float) -> tuple[Optional[LoopKey], float]:
        """Nearest drawn loop curve and its distance in screen pixels."""
        if not self._loop_segments:
            return None, np.inf
        px, py = self._pixel_scale()
        d = distance_to_curves(self._loop_curves, x, y, px, py)
        i = int(np.argmin(d))
        return self._loop_segments[i][0], float(d[i])

    def loop_apex(self, key: LoopKey):
        """Coordinates (in ``self.plot``) of the middle of the curve of loop ``key``, or None."""
        for i, (k, _, _) in enumerate(self._loop_segments):
            if k == key:
                mid = self._loop_curves[i, self._loop_curves.shape[1] // 2]
                vb = self.plot.getPlotItem().getViewBox()
                return self.plot.mapFromScene(vb.mapViewToScene(pg.Point(float(mid[0]), float(mid[1]))))
        return None

    def node_screen_pos(self, k: int):
        """Coordinates of node ``k`` in the plot widget (``self.plot``), for tests and tooltips."""
        vb = self.plot.getPlotItem().getViewBox()
        scene = vb.mapViewToScene(pg.Point(float(self.x[k]), float(self.y[k])))
        return self.plot.mapFromScene(scene)


def _pairs(values: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Interleave values[a], values[b] for a 'pairs' line item."""
    out = np.empty(2 * len(a), dtype=np.float64)
    out[0::2] = values[a]
    out[1::2] = values[b]
    return out
