"""Frames for the viewer decoded off the UI thread; the newest request wins.

Seeking in a long 4K H.264 video takes ~100 ms per frame: decoding on the UI thread
would freeze the window while the timeline slider is dragged or a recording plays.
``FrameLoader.request`` hands the index to the app's background mechanism
(``gui.background.Worker``), which decodes into the shared ``FrameCache``; ``loaded``
follows on the UI thread. Requests made meanwhile replace each other, so only the
frame the user stopped at is decoded next (a decode under way still finishes, and
its frame is announced too: it is in the cache). ``wait`` blocks until the current
decode is done (call it before the recording goes).
"""

from __future__ import annotations

from typing import Optional

from PySide6.QtCore import QObject, Signal

from .background import Worker
from .frame_cache import FrameCache


class FrameLoader(QObject):
    loaded = Signal(int)   # source frame now in the cache (on the UI thread)

    def __init__(self, cache: FrameCache, parent: Optional[QObject] = None) -> None:
        super().__init__(parent)
        self.cache = cache
        self.worker = Worker(self, deliver_superseded=True)

    def request(self, index: int) -> None:
        """Decode source frame ``index`` in the background (replacing any waiting request)."""
        index = int(index)
        self.worker.submit(lambda: self._decode(index), lambda item: self._decoded(index, item))

    def _decode(self, index: int):
        try:
            return self.cache.get(index)
        except Exception:   # a reader failing here must not stop the loader: no frame shown
            return None

    def _decoded(self, index: int, item) -> None:
        if item is not None:
            self.loaded.emit(index)

    def cancel(self) -> None:
        """Drop the waiting request (a decode under way still finishes)."""
        self.worker.cancel()

    def wait(self) -> None:
        """Drop the waiting request and block until this loader's thread has ended."""
        self.worker.stop()
