"""Decoded frames for the views, decoded on demand and kept in a small LRU cache.

The viewer, the pair view and the screenshots all ask for the same few frames;
decoding a video frame (a seek) costs milliseconds, so recently shown frames are
kept together with their canonical panorama shift. The viewer's background decoding
(``gui.frame_loader``) shares the cache, so every access holds its lock: a recording's
reader is not safe to use from two threads at once.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass(frozen=True)
class ShownFrame:
    index: int
    stamp: float
    rgb: np.ndarray       # original panorama
    shift: int            # canonical shift in columns


class FrameCache:
    def __init__(self, source=None, capacity: int = 48) -> None:
        self.source = source
        self.capacity = capacity
        self._items: "OrderedDict[int, ShownFrame]" = OrderedDict()
        self.known_shifts: dict[int, int] = {}   # source frame -> shift from the descriptors
        self.known_width = 0     # the frame width those shifts count in (0: each frame's own)
        self._lock = threading.RLock()

    def set_source(self, source) -> None:
        with self._lock:
            self.source = source
            self._items.clear()

    @property
    def frame_count(self) -> int:
        return 0 if self.source is None else int(self.source.frame_count)

    def peek(self, index: int) -> Optional[ShownFrame]:
        """The frame ``index`` if it is decoded already, else None (never decodes)."""
        with self._lock:
            item = self._items.get(index)
            if item is not None:
                self._items.move_to_end(index)
            return item

    def get(self, index: int) -> Optional[ShownFrame]:
        """The frame ``index`` or None when there is no recording (or it cannot be read)."""
        with self._lock:
            return self._get(index)

    def _get(self, index: int) -> Optional[ShownFrame]:
        if self.source is None or not (0 <= index < self.frame_count):
            return None
        item = self.peek(index)
        if item is not None:
            return item
        from engine.errors import InputError
        from engine.shift import canonical_shift

        try:
            frame = self.source.frame_at(int(index))
        except InputError:
            return None
        shift = self.known_shifts.get(int(index))
        width = int(frame.rgb.shape[1])
        if shift is not None and self.known_width and self.known_width != width:   # another recording's width
            shift = int(round(shift * width / self.known_width)) % width
        if shift is None:
            shift = int(canonical_shift(frame.rgb))
        item = ShownFrame(int(frame.index), float(frame.stamp), frame.rgb, shift)
        self._items[index] = item
        while len(self._items) > self.capacity:
            self._items.popitem(last=False)
        return item
