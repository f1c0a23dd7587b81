"""Frame viewer: the original panorama above its panorama-shifted version.

A timeline slider, step and play controls and the arrow keys move through the
source frames. The canonical column chosen by the panorama shift is marked on the
original. Frames are decoded on demand and cached; while the slider is dragged or a
recording plays they are decoded off the UI thread (``gui.frame_loader``), so a slow
seek never freezes the window: the frame the slider rests on is shown when it is ready.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtGui import QKeyEvent
from PySide6.QtWidgets import (QComboBox, QHBoxLayout, QLabel, QSizePolicy, QSlider, QStyle, QToolButton,
                               QVBoxLayout, QWidget)

from .document import Document
from .frame_cache import FrameCache, ShownFrame
from .frame_loader import FrameLoader
from .style import CANONICAL_COLOR, panorama_view

PLAY_SPEEDS = (("1×", 1.0), ("2×", 2.0), ("5×", 5.0), ("10×", 10.0), ("½×", 0.5))


class FrameViewer(QWidget):
    frameChanged = Signal(int)   # source frame now shown

    def __init__(self, doc: Document, cache: FrameCache, parent: Optional[QWidget] = None) -> None:
        super().__init__(parent)
        self.doc = doc
        self.cache = cache
        self._current = -1
        self.setFocusPolicy(Qt.StrongFocus)

        self.info = QLabel("No recording open")
        self.info.setTextInteractionFlags(Qt.TextSelectableByMouse)
        self.info.setToolTip("Source frame, stamp and the map node that represents this frame")
        # A longer header (a node "since frame …", a place name) must never widen the viewer and
        # squeeze the panels beside it (issue 14, defect 3): its width follows the viewer's.
        self.info.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self.info.setMinimumWidth(0)

        self.canvas = pg.GraphicsLayoutWidget()
        self.canvas.setBackground("w")
        self.canvas.ci.setContentsMargins(2, 2, 2, 2)
        self.original_title = self.canvas.addLabel("Original", row=0, col=0, color="#222", size="9pt")
        self.original_view = panorama_view()
        self.canvas.addItem(self.original_view, row=1, col=0)
        self.shifted_title = self.canvas.addLabel("Panorama-shifted", row=2, col=0, color="#222", size="9pt")
        self.shifted_view = panorama_view()
        self.canvas.addItem(self.shifted_view, row=3, col=0)
        self.original_image = pg.ImageItem()
        self.shifted_image = pg.ImageItem()
        self.original_view.addItem(self.original_image)
        self.shifted_view.addItem(self.shifted_image)
        # A segment over the image only (an InfiniteLine would cross the empty margins).
        self.canonical_line = pg.PlotDataItem(pen=pg.mkPen(CANONICAL_COLOR, width=2))
        self.canonical_line.setToolTip("Canonical column: it becomes the left edge of the shifted panorama")
        self.canonical_line.setVisible(False)
        self.original_view.addItem(self.canonical_line)

        self.slider = QSlider(Qt.Horizontal)
        self.slider.setToolTip("Timeline (Left/Right: one frame, PgUp/PgDn on the slider: ten)")
        self.slider.setEnabled(False)
        self.slider.valueChanged.connect(self._slider_moved)

        style = self.style()

        def button(icon, tip: str, slot) -> QToolButton:
            b = QToolButton()
            b.setIcon(style.standardIcon(icon))
            b.setToolTip(tip)
            b.setAutoRaise(True)
            b.clicked.connect(slot)
            return b

        SP = QStyle.StandardPixmap
        self.first_button = button(SP.SP_MediaSkipBackward, "First frame (Home)", lambda: self.show_frame(0))
        self.prev_node_button = button(SP.SP_MediaSeekBackward, "Previous node (Shift+Left)",
                                       lambda: self.step_node(-1))
        self.prev_button = button(SP.SP_ArrowLeft, "Previous frame (Left)", lambda: self.step(-1))
        self.play_button = button(SP.SP_MediaPlay, "Play / pause (Space)", self.toggle_play)
        self.next_button = button(SP.SP_ArrowRight, "Next frame (Right)", lambda: self.step(1))
        self.next_node_button = button(SP.SP_MediaSeekForward, "Next node (Shift+Right)", lambda: self.step_node(1))
        self.last_button = button(SP.SP_MediaSkipForward, "Last frame (End)",
                                  lambda: self.show_frame(self.cache.frame_count - 1))
        self.speed = QComboBox()
        self.speed.setToolTip("Playback speed relative to the recording")
        for text, value in PLAY_SPEEDS:
            self.speed.addItem(text, value)

        # The timeline has a row of its own: on a narrow column (1280-px screens) the buttons
        # would squeeze it to nothing.
        controls = QHBoxLayout()
        controls.setContentsMargins(0, 0, 0, 0)
        for w in (self.first_button, self.prev_node_button, self.prev_button, self.play_button,
                  self.next_button, self.next_node_button, self.last_button):
            controls.addWidget(w)
        controls.addStretch(1)
        controls.addWidget(self.speed)

        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.info)
        layout.addWidget(self.canvas, 1)
        layout.addWidget(self.slider)
        layout.addLayout(controls)
        layout.addStretch(0)
        self._aspect = 2.0  # width / height of the frames: the canvas is sized to fit them

        # Decoding starts after the slider rests for a moment (debounce), in the background.
        self.loader = FrameLoader(cache, self)
        self.loader.loaded.connect(self._frame_loaded)
        self._decode_timer = QTimer(self)
        self._decode_timer.setSingleShot(True)
        self._decode_timer.setInterval(15)
        self._decode_timer.timeout.connect(self._decode_pending)
        self._pending = -1
        self._play_timer = QTimer(self)
        self._play_timer.timeout.connect(self._play_tick)

        doc.sourceChanged.connect(self._source_changed)
        doc.mapReplaced.connect(self._refresh_info)
        doc.labelsChanged.connect(self._refresh_info)

    # -- public -------------------------------------------------------------------
    @property
    def current_frame(self) -> int:
        return self._current

    def show_frame(self, index: int, immediate: bool = True) -> None:
        """Show source frame ``index`` (clamped); ``immediate`` decodes now, else in the background."""
        n = self.cache.frame_count
        if n == 0:
            return
        index = int(np.clip(index, 0, n - 1))
        self.slider.blockSignals(True)
        self.slider.setValue(index)
        self.slider.blockSignals(False)
        self._pending = index
        if immediate:
            self._decode_timer.stop()
            self.loader.cancel()
            item = self.cache.get(index)
            if item is not None:
                self._display(index, item)
        else:
            self._decode_timer.start()

    def step(self, delta: int) -> None:
        self.show_frame(max(self._current, 0) + delta)

    def step_node(self, delta: int) -> None:
        frames = self.doc.node_frames()
        if frames.size == 0:
            return self.step(delta)
        cur = max(self._current, 0)
        if delta > 0:
            later = frames[frames > cur]
            target = int(later[0]) if later.size else int(frames[-1])
        else:
            earlier = frames[frames < cur]
            target = int(earlier[-1]) if earlier.size else int(frames[0])
        self.show_frame(target)

    def toggle_play(self) -> None:
        if self._play_timer.isActive():
            self.stop_play()
            return
        if self.cache.frame_count == 0:
            return
        stamps = self.cache.source.stamps()
        fps = (len(stamps) - 1) / max(stamps[-1] - stamps[0], 1e-6) if len(stamps) > 1 else 5.0
        rate = fps * float(self.speed.currentData())
        # Skip frames when the requested rate is faster than ~25 redraws per second.
        self._play_step = max(1, int(round(rate / 25.0)))
        self._play_timer.start(int(max(40, 1000.0 * self._play_step / max(rate, 1e-6))))
        self.play_button.setIcon(self.style().standardIcon(QStyle.StandardPixmap.SP_MediaPause))

    def stop_play(self) -> None:
        self._play_timer.stop()
        self.play_button.setIcon(self.style().standardIcon(QStyle.StandardPixmap.SP_MediaPlay))

    def shutdown(self) -> None:
        """Stop playback and background decoding (before the recording is closed)."""
        self.stop_play()
        self._decode_timer.stop()
        self.loader.wait()

    # -- internals ------------------------------------------------------------------
    def _source_changed(self) -> None:
        self.shutdown()
        self.cache.set_source(self.doc.source)
        n = self.cache.frame_count
        self.slider.setEnabled(n > 0)
        self.slider.setRange(0, max(n - 1, 0))
        self.slider.setPageStep(10)
        self._current = -1
        if n:
            self.show_frame(0)
        else:
            self.original_image.clear()
            self.shifted_image.clear()
            self.canonical_line.setVisible(False)
            self.info.setText("No frames: the recording is not available" if self.doc.has_map
                              else "No recording open")

    def _slider_moved(self, value: int) -> None:
        self.show_frame(value, immediate=False)

    def _play_tick(self) -> None:
        if self._current >= self.cache.frame_count - 1:
            self.stop_play()
            return
        self.show_frame(self._current + self._play_step, immediate=False)

    def _decode_pending(self) -> None:
        """The slider rested (or playback moved on): show the frame, decoding it in the background."""
        item = self.cache.peek(self._pending)
        if item is not None:
            self._display(self._pending, item)
        else:
            self.loader.request(self._pending)

    def _frame_loaded(self, index: int) -> None:
        item = self.cache.peek(index) if index == self._pending else None
        if item is not None:   # else the user has moved on, or the cache dropped it
            self._display(index, item)

    def _display(self, index: int, item: ShownFrame) -> None:
        self._current = index
        self.original_image.setImage(item.rgb, autoLevels=False, levels=(0, 255))
        shifted = np.roll(item.rgb, -item.shift, axis=1) if item.shift else item.rgb
        self.shifted_image.setImage(shifted, autoLevels=False, levels=(0, 255))
        h, w = item.rgb.shape[:2]
        if abs(self._aspect - w / h) > 1e-6:
            self._aspect = w / h
            self._fit_canvas()
        for view in (self.original_view, self.shifted_view):
            if view.viewRect().width() < 2 or getattr(view, "_shown_size", None) != (w, h):
                view.setRange(xRange=(0, w), yRange=(0, h), padding=0.01)
                view._shown_size = (w, h)
        self.canonical_line.setData([item.shift + 0.5] * 2, [0, h])
        self.canonical_line.setVisible(True)
        self.original_title.setText(f"Original — canonical column {item.shift} marked")
        self.shifted_title.setText(f"Panorama-shifted (rolled left by {item.shift} columns)")
        self._refresh_info()
        self.frameChanged.emit(index)

    def _refresh_info(self) -> None:
        if self._current < 0:
            return
        item = self.cache.get(self._current)
        if item is None:
            return
        site = self.doc.site
        stamp = f" &nbsp; · &nbsp; t = {item.stamp:.2f} s"
        if site is None:
            text, stamp = f"<b>frame {item.index}</b> / {self.cache.frame_count - 1}" + stamp, ""
        else:   # a site: the recording the frame belongs to and its own frame number; the time last
            name, frame = site.local(item.index)
            first, end = site.span_of(name)
            text = f"<b>{name}</b> &nbsp; <b>frame {frame}</b> / {end - first - 1}"
        k = self.doc.node_at_or_before(item.index)
        if k is not None:
            node = self.doc.node_id(k)
            data = self.doc.node_data(node)
            exact = self.doc.node_place(k) == item.index
            text += f" &nbsp; · &nbsp; node <b>{node}</b>" + ("" if exact else f" (since frame {data['frame']})")
            if data.get("label"):
                text += f" &nbsp; · &nbsp; “{data['label']}”"
        text += stamp
        self.info.setText(text)
        self.info.setToolTip(text)  # the whole header, where the panel is too narrow for it

    def resizeEvent(self, event) -> None:
        super().resizeEvent(event)
        self._fit_canvas()

    def _fit_canvas(self) -> None:
        """As tall as two panoramas at the current width (plus titles): no empty bands."""
        m = self.layout().contentsMargins()
        width = max(self.width() - m.left() - m.right(), 50)  # the canvas spans the viewer's width
        self.canvas.setMaximumHeight(int(2 * width / self._aspect + 70))

    def keyPressEvent(self, event: QKeyEvent) -> None:
        key, mods = event.key(), event.modifiers()
        if key in (Qt.Key_Left, Qt.Key_Right):
            delta = -1 if key == Qt.Key_Left else 1
            self.step_node(delta) if mods & Qt.ShiftModifier else self.step(delta)
        elif key == Qt.Key_Home:
            self.show_frame(0)
        elif key == Qt.Key_End:
            self.show_frame(self.cache.frame_count - 1)
        elif key == Qt.Key_Space:
            self.toggle_play()
        else:
            super().keyPressEvent(event)
