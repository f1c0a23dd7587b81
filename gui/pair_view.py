"""Pair view: the two panoramas of a loop candidate, one above the other.

The candidate (lower) is rolled by the pair's relative yaw so that the same
directions line up with the query (upper); the yaw comes from the loop arc when
it has one, else from ``engine.shift.relative_yaw``. Decision buttons sit below.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Signal
from PySide6.QtWidgets import QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from .document import Document, LoopKey
from .frame_cache import FrameCache
from .style import STATUS_COLORS, panorama_view


class PairView(QWidget):
    decide = Signal(str)          # "confirmed" | "rejected" | "auto"
    addManual = Signal(object)    # LoopKey of a pair that is not a loop yet
    removeManual = Signal(object)

    def __init__(self, doc: Document, cache: FrameCache, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.cache = cache
        self.key: Optional[LoopKey] = None
        self.yaw: Optional[float] = None
        self.yaw_score: Optional[float] = None

        self.title = QLabel("Select a loop candidate in the table, the graph or the matrix")
        self.title.setWordWrap(True)
        self.canvas = pg.GraphicsLayoutWidget()
        self.canvas.setBackground("w")
        self.canvas.ci.setContentsMargins(2, 2, 2, 2)
        self.query_title = self.canvas.addLabel("Query", row=0, col=0, color="#222", size="9pt")
        self.query_view = panorama_view()
        self.canvas.addItem(self.query_view, row=1, col=0)
        self.cand_title = self.canvas.addLabel("Candidate", row=2, col=0, color="#222", size="9pt")
        self.cand_view = panorama_view()
        self.canvas.addItem(self.cand_view, row=3, col=0)
        self.query_image = pg.ImageItem()
        self.cand_image = pg.ImageItem()
        self.query_view.addItem(self.query_image)
        self.cand_view.addItem(self.cand_image)
        self.cand_view.setXLink(self.query_view)  # zoom and pan together

        self.confirm_button = QPushButton("✓ Confirm")
        self.confirm_button.setToolTip("This is the same place: keep the loop (C or Y)")
        self.reject_button = QPushButton("✗ Reject")
        self.reject_button.setToolTip("Not the same place: drop the loop from the export (R or N)")
        self.reset_button = QPushButton("↺ Reset")
        self.reset_button.setToolTip("Back to undecided (Backspace or U)")
        self.add_button = QPushButton("+ Manual")
        self.add_button.setToolTip("These two nodes are the same place: add a loop by hand (M opens a dialog for any two nodes)")
        self.remove_button = QPushButton("− Remove")
        self.remove_button.setToolTip("Delete this hand-made loop (Delete)")
        self.confirm_button.clicked.connect(lambda: self.decide.emit("confirmed"))
        self.reject_button.clicked.connect(lambda: self.decide.emit("rejected"))
        self.reset_button.clicked.connect(lambda: self.decide.emit("auto"))
        self.add_button.clicked.connect(lambda: self.key and self.addManual.emit(self.key))
        self.remove_button.clicked.connect(lambda: self.key and self.removeManual.emit(self.key))
        buttons = QHBoxLayout()
        buttons.setContentsMargins(0, 0, 0, 0)
        for b in (self.confirm_button, self.reject_button, self.reset_button, self.add_button, self.remove_button):
            b.setMinimumWidth(0)
            b.setStyleSheet("padding: 3px 6px")
            buttons.addWidget(b)
        buttons.addStretch(1)

        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.title)
        layout.addWidget(self.canvas, 1)
        layout.addLayout(buttons)
        self._update_buttons()

        doc.loopsChanged.connect(self._loops_changed)
        doc.labelsChanged.connect(self.refresh)
        doc.mapReplaced.connect(self._map_replaced)

    def show_pair(self, key: Optional[LoopKey]) -> None:
        """Show the two nodes at source frames ``key`` (a loop or any pair), or clear."""
        self.key = tuple(key) if key is not None else None
        self.refresh()

    def refresh(self) -> None:
        key = self.key
        if key is None or not self.doc.has_map or self.doc.nodes_of(key) is None:
            self.key = None
            self.query_image.clear()
            self.cand_image.clear()
            self.title.setText("Select a loop candidate in the table, the graph or the matrix")
            self.query_title.setText("Query")          # no caption of a pair no longer shown (defect 5)
            self.cand_title.setText("Candidate")
            self._update_buttons()
            return
        u, v = self.doc.nodes_of(key)
        du, dv = self.doc.node_data(u), self.doc.node_data(v)
        attrs = self.doc.loop_attrs(key)
        a, b = self.cache.get(key[0]), self.cache.get(key[1])
        self.yaw, self.yaw_score = None, None
        yaw_source = ""
        if attrs is not None and attrs.get("yaw") is not None and np.isfinite(attrs["yaw"]):
            self.yaw, yaw_source = float(attrs["yaw"]), "from the loop"
        elif a is not None and b is not None and a.rgb.shape == b.rgb.shape:
            from engine.shift import relative_yaw

            self.yaw, self.yaw_score = relative_yaw(a.rgb, b.rgb)
            yaw_source = f"estimated, score {self.yaw_score:.2f}"
            self.doc.note_estimated_yaw(key, self.yaw)
        self._show_images(a, b)

        sim = self.doc.pair_similarity(int(du["index"]), int(dv["index"]))
        status = attrs.get("status", "auto") if attrs else None
        state = (f"<span style='color:{STATUS_COLORS.get(status, '#000')}'><b>{status}</b></span>"
                 if status else "<i>not a loop</i>")
        yaw_text = f"yaw {self.yaw:+.1f}° ({yaw_source})" if self.yaw is not None else "yaw unknown"
        self.title.setText(f"<b>{u}</b> (frame {key[0]}) ↔ <b>{v}</b> (frame {key[1]}) &nbsp;·&nbsp; "
                           f"similarity {sim:.3f} &nbsp;·&nbsp; {yaw_text} &nbsp;·&nbsp; {state}")
        self.query_title.setText(_caption("Query", u, du))
        aligned = " (aligned)" if self.yaw is not None else ""
        self.cand_title.setText(_caption("Candidate", v, dv) + aligned)
        self._update_buttons()

    def _show_images(self, a, b) -> None:
        if a is None or b is None:
            self.query_image.clear()
            self.cand_image.clear()
            self.query_title.setText("Frames not available (recording not found)")
            return
        from engine.shift import apply_shift, yaw_to_columns

        cand = b.rgb
        if self.yaw is not None:
            cand = apply_shift(b.rgb, yaw_to_columns(self.yaw, b.rgb.shape[1]))
        self.query_image.setImage(a.rgb, autoLevels=False, levels=(0, 255))
        self.cand_image.setImage(cand, autoLevels=False, levels=(0, 255))
        h, w = a.rgb.shape[:2]
        for view in (self.query_view, self.cand_view):
            view.setRange(xRange=(0, w), yRange=(0, h), padding=0.01)

    def _update_buttons(self) -> None:
        attrs = self.doc.loop_attrs(self.key) if self.key is not None and self.doc.has_map else None
        is_loop = attrs is not None
        manual = is_loop and attrs.get("status") == "manual"
        for b in (self.confirm_button, self.reject_button, self.reset_button):
            b.setEnabled(is_loop and not manual)
        self.add_button.setEnabled(self.key is not None and not is_loop and self.key[0] != self.key[1])
        self.remove_button.setEnabled(manual)

    def _loops_changed(self) -> None:
        self.refresh()

    def _map_replaced(self) -> None:
        self.refresh()


def _caption(role: str, node: str, data: dict) -> str:
    label = f" “{data['label']}”" if data.get("label") else ""
    return f"{role}: {node}{label}, frame {data['frame']}, t = {float(data['stamp']):.1f} s"
