"""Pair view: the evidence behind a loop, large enough to judge.

Both panoramas sit in one zoomable view (wheel zooms, drag pans, double-click
resets): the query on top and the candidate below, or side by side when the view is
wide and short (whichever shows them larger), the candidate rolled by the pair's relative yaw
so that the same directions line up. The yaw comes from the loop arc when it has
one, else from the two-view geometry, else from ``engine.shift.relative_yaw``. The
matched local features are drawn between them as RTAB-Map does: inliers of the
two-view model in green, outliers in red. The numbers behind the decision
(similarity, descriptor score, inliers/matches, sequence support) are written
above. A pair without geometry still shows aligned. Decision buttons sit below.
"""

from __future__ import annotations

from typing import Callable, Optional

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QEvent, Qt, Signal
from PySide6.QtWidgets import QCheckBox, QHBoxLayout, QLabel, QPushButton, QSizePolicy, QVBoxLayout, QWidget

from .document import Document, LoopKey
from .frame_cache import FrameCache
from .background import Worker
from .pair_evidence import MatchCache, PairMatches, evidence_lines, match_segments
from .style import INLIER_COLOR, OUTLIER_COLOR, STATUS_COLORS, panorama_view

# Most match lines drawn of each kind (inliers, outliers): beyond ~60 lines the images vanish
# under them (seen on the demo screenshots); every matched point is still marked.
MAX_LINES = 60
# Gap between the two panoramas, as a fraction of their height (stacked) or width (side by
# side): room for the match lines to be seen between them.
GAP_FRACTION = 0.12

MatchesFor = Callable[[LoopKey], Optional[PairMatches]]


class PairView(QWidget):
    decide = Signal(str)          # "confirmed" | "rejected" | "auto"
    addManual = Signal(object)    # LoopKey of a pair that is not a loop yet
    removeManual = Signal(object)
    matchesReady = Signal(object)  # LoopKey whose matches the worker thread has computed

    def __init__(self, doc: Document, cache: FrameCache, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.cache = cache
        self.key: Optional[LoopKey] = None
        self.yaw: Optional[float] = None
        self.yaw_score: Optional[float] = None
        self.matches: Optional[PairMatches] = None
        # Where the matched features of a pair come from (None: no geometry).
        self.match_cache = MatchCache(doc, cache)
        self.matches_for: Optional[MatchesFor] = self.match_cache
        # The geometry of a new pair is computed off the UI thread (~0.2-0.8 s a pair) by the
        # app's one background mechanism; the newest pair asked for is computed next, and a
        # pair finished meanwhile is announced too (its matches are in the cache).
        self.match_worker = Worker(self, deliver_superseded=True)
        self._closed = False   # set by shutdown: no new background work
        self._pending: set = set()
        # Queued even when emitted in this thread: a pair finished before its done callback is
        # registered calls back at once, inside refresh, which would then overwrite the matches.
        self.matchesReady.connect(self._matches_arrived, Qt.QueuedConnection)
        self._image_size = (0, 0)
        self.side_by_side = False
        self.cand_offset = (0.0, 0.0)   # top-left corner of the candidate in view coordinates
        self._segments = (np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))

        self.title = QLabel("Select a loop candidate in the table, the graph or the matrix")
        self.title.setWordWrap(True)
        self.evidence = QLabel("")
        self.evidence.setWordWrap(True)
        self.evidence.setToolTip("The numbers behind the decision: descriptor similarity and score, "
                                 "inliers of the two-view geometry among the matched features, and how "
                                 "many neighbouring pairs support the loop")
        self.caption = QLabel("")
        self.caption.setWordWrap(True)
        for label in (self.title, self.evidence, self.caption):
            label.setTextFormat(Qt.RichText)
        self.canvas = pg.GraphicsLayoutWidget()
        self.canvas.setBackground("w")
        self.canvas.ci.setContentsMargins(0, 0, 0, 0)
        self.view = panorama_view()
        self.canvas.addItem(self.view, row=0, col=0)
        self.query_image = pg.ImageItem()
        self.cand_image = pg.ImageItem()
        self.view.addItem(self.query_image)
        self.view.addItem(self.cand_image)
        self.outlier_item = pg.PlotDataItem(pen=pg.mkPen(OUTLIER_COLOR, width=1), connect="pairs")
        self.outlier_item.setOpacity(0.6)
        self.inlier_item = pg.PlotDataItem(pen=pg.mkPen(INLIER_COLOR, width=1.2), connect="pairs")
        self.inlier_item.setOpacity(0.75)
        self.points_item = pg.ScatterPlotItem(size=5, pen=pg.mkPen("k", width=0.5))
        for item in (self.outlier_item, self.inlier_item, self.points_item):
            self.view.addItem(item)
        self.canvas.setToolTip("Query on top (or left), candidate below (or right), aligned by the yaw; "
                               "green: inlier matches, "
                               "red: outliers. Wheel: zoom, drag: pan, double-click: whole pair")
        self.canvas.viewport().installEventFilter(self)   # double-click: the whole pair again

        self.show_matches = QCheckBox("Matches")
        self.show_matches.setChecked(True)
        self.show_matches.setToolTip("Draw the matched local features between the two panoramas")
        self.show_matches.toggled.connect(self._draw_matches)
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
            b.setStyleSheet("padding: 3px 4px")
            buttons.addWidget(b)
        buttons.addStretch(1)
        # The texts above wrap; they never set the view's minimum width (1280-px screens, defect 4).
        for label in (self.title, self.evidence, self.caption):
            label.setMinimumWidth(0)
            label.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)

        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.setSpacing(2)
        top = QHBoxLayout()
        top.setContentsMargins(0, 0, 0, 0)
        top.addWidget(self.evidence, 1)
        top.addWidget(self.show_matches, 0, Qt.AlignTop)
        layout.addWidget(self.title)
        layout.addLayout(top)
        layout.addWidget(self.canvas, 1)
        layout.addWidget(self.caption)
        layout.addLayout(buttons)
        self._update_buttons()

        doc.loopsChanged.connect(self.refresh)
        doc.labelsChanged.connect(self.refresh)
        doc.mapReplaced.connect(self._map_replaced)
        doc.sourceChanged.connect(self.match_cache.clear)

    # -- public ------------------------------------------------------------------------
    def show_pair(self, key: Optional[LoopKey]) -> None:
        """Show the two nodes at source frames ``key`` (a loop or any pair), or clear."""
        self.key = tuple(key) if key is not None else None
        self.refresh()

    def refresh(self) -> None:
        key = self.key
        if key is None or not self.doc.has_map or self.doc.nodes_of(key) is None:
            self._clear()   # no caption of a pair no longer shown (defect 5)
            return
        u, v = self.doc.nodes_of(key)
        du, dv = self.doc.node_data(u), self.doc.node_data(v)
        attrs = self.doc.loop_attrs(key)
        a, b = self.cache.get(key[0]), self.cache.get(key[1])   # a site: each from its own recording
        b = _same_size(b, a)
        self.matches, waiting = self._matches_of(key)
        self.yaw, self.yaw_score = None, None
        yaw_source = ""
        if attrs is not None and attrs.get("yaw") is not None and np.isfinite(attrs["yaw"]):
            self.yaw, yaw_source = float(attrs["yaw"]), "from the loop"
        elif self.matches is not None and self.matches.yaw is not None:
            self.yaw, yaw_source = float(self.matches.yaw), "from the matched features"
            self.doc.note_estimated_yaw(key, self.yaw)
        elif a is not None and b is not None and a.rgb.shape == b.rgb.shape:
            from engine.shift import relative_yaw

            self.yaw, self.yaw_score = relative_yaw(a.rgb, b.rgb)
            yaw_source = f"estimated, score {self.yaw_score:.2f}"
            self.doc.note_estimated_yaw(key, self.yaw)
        shown = self._show_images(a, b)

        sim = self.doc.pair_similarity(int(du["index"]), int(dv["index"]))
        status = attrs.get("status", "auto") if attrs else None
        state = (f"<span style='color:{STATUS_COLORS.get(status, '#000')}'><b>{status}</b></span>"
                 if status else "<i>not a loop</i>")
        yaw_text = f"yaw {self.yaw:+.1f}° ({yaw_source})" if self.yaw is not None else "yaw unknown"
        self.title.setText(f"<b>{u}</b> ({self.doc.place_text(key[0])}) ↔ <b>{v}</b> ({self.doc.place_text(key[1])})"
                           f" &nbsp;·&nbsp; {state} &nbsp;·&nbsp; {yaw_text}")
        lines = evidence_lines(attrs, self.matches, sim)
        if self.matches is None and shown:
            failed = self.match_cache.errors.get(key)
            lines.append("matching features…" if waiting else
                         f"feature matching failed ({failed})" if failed else "no feature matches for this pair")
        self.evidence.setText(" &nbsp;·&nbsp; ".join(lines))
        aligned = " (rolled to align)" if self.yaw is not None else ""
        self.caption.setText(f"{_caption('Query', u, du)} &nbsp;·&nbsp; {_caption('Candidate', v, dv)}{aligned}"
                             if shown else "Frames not available (recording not found, or frames of different sizes)")
        self._update_buttons()

    def reset_zoom(self) -> None:
        """Show the whole pair (both panoramas and the gap between them)."""
        w, h = self._image_size
        if w and h:
            dx, dy = self.cand_offset
            self.view.setRange(xRange=(0, dx + w), yRange=(0, dy + h), padding=0.01)

    def match_segments_shown(self) -> tuple[np.ndarray, np.ndarray]:
        """(inlier, outlier) segments drawn now, in view coordinates (for tests)."""
        return self._segments

    # -- internals ------------------------------------------------------------------------
    def _clear(self) -> None:
        self.key = None
        self.matches = None
        self.query_image.clear()
        self.cand_image.clear()
        self._image_size = (0, 0)
        self._segments = (np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))
        self._draw_matches()
        self.title.setText("Select a loop candidate in the table, the graph or the matrix")
        self.evidence.setText("")
        self.caption.setText("")
        self._update_buttons()

    def _show_images(self, a, b) -> bool:
        self._segments = (np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))
        if a is None or b is None or a.rgb.shape != b.rgb.shape:
            self.query_image.clear()
            self.cand_image.clear()
            self._image_size = (0, 0)
            self._draw_matches()
            return False
        from engine.shift import apply_shift, yaw_to_columns

        h, w = a.rgb.shape[:2]
        roll = yaw_to_columns(self.yaw, b.rgb.shape[1]) if self.yaw is not None else 0
        cand = apply_shift(b.rgb, roll) if roll else b.rgb
        self.query_image.setImage(a.rgb, autoLevels=False, levels=(0, 255))
        self.cand_image.setImage(cand, autoLevels=False, levels=(0, 255))
        self._arrange(w, h, a.shift, b.shift, roll)
        return True

    def _arrange(self, w: int, h: int, shift_a: int = 0, shift_b: int = 0, roll: int = 0) -> None:
        """Candidate below or beside the query, whichever shows the panoramas larger here."""
        self._shown = (w, h, shift_a, shift_b, roll)
        cw, ch = max(self.canvas.width(), 1), max(self.canvas.height(), 1)
        stacked = min(cw / w, ch / (h * (2 + GAP_FRACTION)))
        beside = min(cw / (w * (2 + GAP_FRACTION)), ch / h)
        self.side_by_side = beside > stacked
        self.cand_offset = (w * (1 + GAP_FRACTION), 0.0) if self.side_by_side else (0.0, h * (1 + GAP_FRACTION))
        self.cand_image.setPos(*self.cand_offset)
        if self.matches is not None:
            self._segments = match_segments(self.matches, w, h, shift_a, shift_b, roll, self.cand_offset)
        self._draw_matches()
        self._image_size = (w, h)
        self.reset_zoom()

    def resizeEvent(self, event) -> None:
        super().resizeEvent(event)
        if self._image_size[0]:
            self._arrange(*self._shown)

    def _draw_matches(self) -> None:
        inl, out = self._segments
        on = self.show_matches.isChecked()
        for item, seg in ((self.inlier_item, inl), (self.outlier_item, out)):
            if len(seg) > MAX_LINES:   # evenly spread over the matches, the same ones every time
                seg = seg[np.linspace(0, len(seg) - 1, MAX_LINES).astype(int)]
            pts = seg.reshape(-1, 2) if on else np.zeros((0, 2))
            item.setData(pts[:, 0], pts[:, 1], connect="pairs")
        pts = np.concatenate([inl.reshape(-1, 2), out.reshape(-1, 2)]) if on else np.zeros((0, 2))
        colours = [INLIER_COLOR] * (2 * len(inl)) + [OUTLIER_COLOR] * (2 * len(out)) if on else []
        self.points_item.setData(x=pts[:, 0], y=pts[:, 1], brush=[pg.mkBrush(c) for c in colours])

    def _matches_of(self, key) -> tuple[Optional[PairMatches], bool]:
        """(matches of ``key`` known now, whether they are being computed in the background)."""
        if self.matches_for is None:
            return None, False
        if self.matches_for is not self.match_cache:   # a plain provider: ask it directly
            return self.matches_for(key), False
        if self.match_cache.has(key):
            return self.match_cache.peek(key), False
        if self._closed:
            return None, False
        if key not in self._pending:
            self._pending = {key}   # a pair still waiting is replaced by this one (newest wins)
            self.match_worker.submit(lambda k=key: self.match_cache(k), lambda _m, k=key: self._announce(k),
                                     lambda _exc, k=key: self._announce(k))
        return None, True

    def _announce(self, key) -> None:
        """On the UI thread: ``key``'s matches are in the cache (queued, so never inside refresh)."""
        if self._closed:
            return
        try:
            self.matchesReady.emit(key)
        except RuntimeError:   # the view was closed meanwhile
            pass

    def _matches_arrived(self, key) -> None:
        self._pending.discard(key)
        if self.key == key:
            self.refresh()

    def shutdown(self) -> None:
        """Stop the background matching (the window closes)."""
        self._closed = True
        self.match_worker.stop()

    def _map_replaced(self) -> None:
        self.match_cache.clear()
        self.refresh()

    def eventFilter(self, watched, event) -> bool:
        if (watched is self.canvas.viewport() and event.type() == QEvent.MouseButtonDblClick
                and event.button() == Qt.LeftButton):
            self.reset_zoom()
            return True
        return super().eventFilter(watched, event)

    def _update_buttons(self) -> None:
        attrs = self.doc.loop_attrs(self.key) if self.key is not None and self.doc.has_map else None
        is_loop = attrs is not None
        manual = is_loop and attrs.get("status") == "manual"
        for b in (self.confirm_button, self.reject_button, self.reset_button):
            b.setEnabled(is_loop and not manual)
        self.add_button.setEnabled(self.key is not None and not is_loop and self.key[0] != self.key[1])
        self.remove_button.setEnabled(manual)


def _caption(role: str, node: str, data: dict) -> str:
    label = f" “{data['label']}”" if data.get("label") else ""
    recording = f" of {data['session']}" if data.get("session") else ""
    return f"{role}: {node}{label}{recording}, frame {data['frame']}, t = {float(data['stamp']):.1f} s"


def _same_size(b, a):
    """Frame ``b`` at ``a``'s size (two recordings of a site may differ), its shift scaled along."""
    if a is None or b is None or a.rgb.shape == b.rgb.shape:
        return b
    from dataclasses import replace

    h, w = a.rgb.shape[:2]
    hb, wb = b.rgb.shape[:2]
    rows = (np.arange(h) * hb // h).clip(0, hb - 1)
    cols = (np.arange(w) * wb // w).clip(0, wb - 1)
    return replace(b, rgb=np.ascontiguousarray(b.rgb[rows][:, cols]), shift=int(round(b.shift * w / wb)) % w)
