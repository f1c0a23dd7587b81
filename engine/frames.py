"""Frames and the one interface every recording reader implements.

A ``FrameSource`` is a recording (video, ROS1/ROS2 bag, folder of images).
``index`` is always the frame's position in the whole recording (source frame),
``stamp`` is seconds (from the start for videos and folders, ROS time for bags).
Sampling at ``interval`` seconds picks, for t_k = first_stamp + k * interval, the
first frame whose stamp is >= t_k (each source frame at most once). The PyAV video reader
takes the nearest key frame instead when every t_k has one within max(0.25 s, interval / 4)
(``engine.sources.video_av``); delivered stamps are always those of the delivered frame.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional

import numpy as np

from .errors import InputError


@dataclass(frozen=True)
class Frame:
    index: int          # source frame index in the recording
    stamp: float        # seconds
    rgb: np.ndarray     # H x W x 3 uint8, equirectangular (W == 2 H)
    source_width: int = 0   # the recording's frame width when ``rgb`` was delivered shrunk (0: rgb's own)

    @property
    def width(self) -> int:
        """Columns of the frame in the recording (shifts and yaws are counted in these)."""
        return self.source_width or int(self.rgb.shape[1])


def sample_indices(stamps: np.ndarray, interval: float) -> np.ndarray:
    """Indices of the frames sampled every ``interval`` seconds from ``stamps``.

    For each target time t_k = stamps[0] + k * interval the first frame with
    stamp >= t_k is taken; a frame is never taken twice (gaps in the recording
    are skipped, not filled). ``interval <= 0`` keeps every frame.
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    if stamps.size == 0:
        return np.zeros(0, dtype=np.int64)
    if interval <= 0:
        return np.arange(stamps.size, dtype=np.int64)
    # Tolerance so that 30 fps video sampled at 1.0 s hits frame 30 exactly.
    eps = 1e-6
    targets = np.arange(stamps[0], stamps[-1] + eps, interval)
    idx = np.searchsorted(stamps, targets - eps, side="left")
    idx = idx[idx < stamps.size]
    return np.unique(idx).astype(np.int64)


def check_equirectangular(rgb: np.ndarray, where: str) -> None:
    """Raise InputError unless ``rgb`` is an H x 2H x 3 image."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"{where}: expected a colour image, got shape {rgb.shape}")
    check_equirectangular_size(int(rgb.shape[1]), int(rgb.shape[0]), where)


def check_equirectangular_size(w: int, h: int, where: str) -> None:
    """Raise InputError unless a ``w`` x ``h`` frame is a 2:1 panorama within the size limits."""
    if w != 2 * h:
        raise InputError(
            f"{where}: frame is {w}x{h}, not an equirectangular 2:1 panorama"
        )
    from .validate import frame_size

    frame_size(w, h, where)  # too small to shift, or past the limits


class FrameSource(ABC):
    """A recording: random access for the GUI, sampled iteration for the engine."""

    path: Path
    # Threads the reader keeps busy decoding while ``frames()`` is read, besides the read-ahead
    # thread (which mostly waits for the describing: 0 for most readers). The cores left over
    # go to the descriptor's network (``engine.prefetch.cores_left``).
    reader_threads: int = 0

    @property
    @abstractmethod
    def frame_count(self) -> int:
        """Number of frames in the whole recording."""

    @property
    @abstractmethod
    def resolution(self) -> tuple[int, int]:
        """(width, height) of the frames."""

    @abstractmethod
    def stamps(self) -> np.ndarray:
        """float64 stamps (seconds) of all ``frame_count`` frames, increasing."""

    @abstractmethod
    def frame_at(self, index: int) -> Frame:
        """The source frame ``index`` (0 <= index < frame_count)."""

    @property
    def duration(self) -> float:
        s = self.stamps()
        return float(s[-1] - s[0]) if s.size else 0.0

    def sample_indices(self, interval: float = 1.0) -> np.ndarray:
        return sample_indices(self.stamps(), interval)

    def expected_samples(self, interval: float = 1.0) -> int:
        """How many frames ``frames(interval)`` yields (an estimate where knowing it
        exactly costs a pass over the recording; used for progress only)."""
        return int(self.sample_indices(interval).size)

    def frames(self, interval: float = 1.0, max_width: Optional[int] = None) -> Iterator[Frame]:
        """Frames sampled every ``interval`` seconds, in order.

        ``max_width``: the caller will shrink frames to this many columns anyway; a reader
        that can deliver them smaller more cheaply than at full size does (no narrower than
        ``max_width``, ``Frame.source_width`` set), the others ignore it.
        """
        for i in self.sample_indices(interval):
            yield self.frame_at(int(i))

    # Where ``headings()`` come from, in words (e.g. "/odom (nav_msgs/msg/Odometry)").
    heading_note: str = ""

    def headings(self) -> Optional[np.ndarray]:
        """The heading of every frame's image centre, float64 (frame_count,), in degrees
        clockwise from north (or from any fixed direction), where the recording says which way
        the camera looked; None where it does not. The panorama shift uses it when present
        (``engine.shift.shift_from_heading``) and the image otherwise."""
        return None

    def close(self) -> None:
        pass

    def __enter__(self) -> "FrameSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class IndexedSource(FrameSource):
    """A source that learns every stamp and the resolution when it opens (folders, bags)."""

    _stamps: np.ndarray
    _resolution: tuple[int, int]

    @property
    def frame_count(self) -> int:
        return int(self._stamps.size)

    @property
    def resolution(self) -> tuple[int, int]:
        return self._resolution

    def stamps(self) -> np.ndarray:
        return self._stamps.copy()
