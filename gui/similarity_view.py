"""Similarity matrix: cosine similarity between every pair of nodes, loops overlaid.

Loops appear as markers coloured by status (in both triangles). Clicking a cell
selects that pair: the loop if there is one, otherwise the pair is shown in the
pair view, where it can be added as a manual loop.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QVBoxLayout, QWidget

from .document import Document, LoopKey
from .style import SELECTED_COLOR, STATUS_COLORS, STATUS_LABELS, STATUS_ORDER


class SimilarityView(QWidget):
    pairClicked = Signal(int, int)   # node indices (a < b)

    def __init__(self, doc: Document, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.glw = pg.GraphicsLayoutWidget()
        self.glw.setBackground("w")
        self.plot = self.glw.addPlot(row=0, col=0)
        self.plot.setAspectLocked(True)
        self.plot.invertY(True)
        self.plot.setMenuEnabled(False)
        self.plot.hideButtons()
        self.plot.setLabel("bottom", "node index")
        self.plot.setLabel("left", "node index")
        self.image = pg.ImageItem()
        self.plot.addItem(self.image)
        self.colorbar = pg.ColorBarItem(values=(0, 1), colorMap=pg.colormap.get("viridis"), interactive=False,
                                        label="cosine similarity", width=14)
        self.colorbar.setImageItem(self.image, insert_in=self.plot)
        self.markers: dict[str, pg.ScatterPlotItem] = {}
        self.legend = self.plot.addLegend(offset=(-8, 8), labelTextColor="#222",
                                          brush=pg.mkBrush(255, 255, 255, 220), pen=pg.mkPen("#bbb"))
        for status in STATUS_ORDER:
            symbol = "x" if status == "rejected" else "o"
            item = pg.ScatterPlotItem(size=9, symbol=symbol, pen=pg.mkPen(STATUS_COLORS[status], width=2),
                                      brush=None, name=STATUS_LABELS[status])
            self.markers[status] = item
            self.plot.addItem(item)
        self.selected = pg.ScatterPlotItem(size=18, symbol="s", pen=pg.mkPen(SELECTED_COLOR, width=2.5), brush=None)
        self.plot.addItem(self.selected)
        self.plot.scene().sigMouseClicked.connect(self._clicked)
        self.setToolTip("Click a cell to look at that pair of nodes")

        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.glw)

        doc.mapReplaced.connect(self.rebuild)
        doc.similarityReady.connect(self.rebuild)  # computed off the UI thread (gui.background)
        doc.loopsChanged.connect(self.redraw_loops)

    def rebuild(self) -> None:
        sim = self.doc.similarity() if self.doc.similarity_ready() else None
        if sim is None:
            self.image.clear()
            self.selected.setData([], [])
            for item in self.markers.values():
                item.setData([], [])
            return
        preview, lo = self.doc.similarity_preview()  # block maxima and floor, made off the UI thread
        n = sim.shape[0]
        self.image.setImage(preview, autoLevels=False, rect=(0, 0, n, n))
        self.colorbar.setLevels((max(min(lo, 0.99), -1.0), 1.0))
        self.plot.setRange(xRange=(0, n), yRange=(0, n), padding=0.02)
        self.plot.setTitle(f"Similarity between the {n} nodes", color="#444", size="9pt")
        self.redraw_loops()

    def redraw_loops(self) -> None:
        pairs: dict[str, list[tuple[int, int]]] = {s: [] for s in self.markers}
        for row in self.doc.loop_rows():
            pairs.setdefault(row.status, []).append((row.index_u, row.index_v))
        for status, item in self.markers.items():
            p = np.array(pairs.get(status, []), dtype=np.float64).reshape(-1, 2) + 0.5
            # Both triangles: (a, b) and (b, a); x is the column.
            item.setData(x=np.concatenate([p[:, 1], p[:, 0]]), y=np.concatenate([p[:, 0], p[:, 1]]))

    def set_selected_pair(self, key: Optional[LoopKey]) -> None:
        nodes = self.doc.nodes_of(key) if key is not None and self.doc.has_map else None
        if nodes is None:
            self.selected.setData([], [])
            return
        a, b = (int(self.doc.node_data(n)["index"]) for n in nodes)
        self.selected.setData([b + 0.5, a + 0.5], [a + 0.5, b + 0.5])

    def _clicked(self, event) -> None:
        sim = self.doc.similarity() if self.doc.similarity_ready() else None
        if event.button() != Qt.LeftButton or sim is None:
            return
        vb = self.plot.getViewBox()
        if not vb.sceneBoundingRect().contains(event.scenePos()):
            return
        p = vb.mapSceneToView(event.scenePos())
        col, row = int(np.floor(p.x())), int(np.floor(p.y()))
        n = sim.shape[0]
        if 0 <= row < n and 0 <= col < n and row != col:
            self.pairClicked.emit(min(row, col), max(row, col))
            event.accept()

    def cell_scene_pos(self, a: int, b: int):
        """Scene position of cell (row a, column b), for tests."""
        return self.plot.getViewBox().mapViewToScene(pg.Point(b + 0.5, a + 0.5))
