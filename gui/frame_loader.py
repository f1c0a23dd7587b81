"""Frames for the viewer decoded off the UI thread; the newest request wins.

Seeking in a long 4K H.264 video takes ~100 ms per frame: decoding on the UI thread
would freeze the window while the timeline slider is dragged or a recording plays.
``FrameLoader.request`` hands the index to a QThread that decodes into the shared
``FrameCache`` and emits ``loaded``; requests made meanwhile replace each other, so
only the frame the user stopped at is decoded next. A thread runs only while there is
work and ends when there is none, so nothing is left running when a window closes;
``wait`` blocks until the current decode is done (call it before the recording goes).
"""

from __future__ import annotations

import threading
from typing import Optional

from PySide6.QtCore import QObject, QThread, Signal

from .frame_cache import FrameCache

# Decode threads are kept here until they have finished: a QThread object collected
# while it runs aborts the process.
_THREADS: set = set()


class _DecodeThread(QThread):
    def __init__(self, loader: "FrameLoader") -> None:
        super().__init__()
        self.loader = loader

    def run(self) -> None:
        while (index := self.loader._take()) is not None:
            try:
                item = self.loader.cache.get(index)
            except Exception:   # a reader failing here must not stop the loader: no frame shown
                item = None
            if item is not None:
                self.loader.loaded.emit(index)


class FrameLoader(QObject):
    loaded = Signal(int)   # source frame now in the cache (emitted from the decode thread)

    def __init__(self, cache: FrameCache, parent: Optional[QObject] = None) -> None:
        super().__init__(parent)
        self.cache = cache
        self._lock = threading.Lock()
        self._pending: Optional[int] = None
        self._busy = False

    def request(self, index: int) -> None:
        """Decode source frame ``index`` in the background (replacing any waiting request)."""
        with self._lock:
            self._pending = int(index)
            if self._busy:
                return
            self._busy = True
        for done in [t for t in _THREADS if t.isFinished()]:
            _THREADS.discard(done)
        thread = _DecodeThread(self)
        _THREADS.add(thread)
        thread.start()

    def cancel(self) -> None:
        """Drop the waiting request (a decode under way still finishes)."""
        with self._lock:
            self._pending = None

    def wait(self) -> None:
        """Drop the waiting request and block until this loader's threads have ended."""
        self.cancel()
        for thread in [t for t in _THREADS if t.loader is self]:
            thread.wait()
            _THREADS.discard(thread)

    def _take(self) -> Optional[int]:
        """The next index to decode, or None: then the thread ends (called in the thread)."""
        with self._lock:
            index, self._pending = self._pending, None
            if index is None:
                self._busy = False
            return index
