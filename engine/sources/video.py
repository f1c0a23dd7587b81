"""Equirectangular video files: sampled through PyAV, random access and fallback through OpenCV.

Sampling (``frames(interval)``, ``stamps()``, ``expected_samples``) goes through
``engine.sources.video_av.AvSampler`` when PyAV is installed and can demux the file:
it decodes only the frames the samples need (key frames when every sample time has
one nearby, else the exact frames; see that module), and its stamps are the frames'
presentation times from one demux pass without decoding. ``frame_at`` (the GUI's
random access) reads through OpenCV; a frame's index is the same in both (its
position in presentation order, ``round(stamp * fps)`` at a constant frame rate).

Without PyAV, or for a container PyAV cannot read, OpenCV does everything. Its
stamps are the container's presentation times (``CAP_PROP_POS_MSEC`` read after
each ``grab()``), shifted so that the first frame is at 0 s; when the container
gives no usable times they are ``index / fps``. Knowing all stamps needs one
pass over the video, done lazily once and cached. Skipped frames are only
grabbed (decoded, not converted to RGB); ``frames(interval)`` picks the sampled
frames in a single forward pass with the same rule as
``engine.frames.sample_indices``.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Iterator, Optional

import cv2
import numpy as np

from .camera_heading import CameraHeadings
from ..errors import InputError
from ..frames import Frame, FrameSource, check_equirectangular
from ..validate import frame_size
from .video_av import DECODE_THREADS, AvSampler, AvUnavailable

# FFmpeg prints its own line for a broken file ("moov atom not found") before our one-line
# error; keep it quiet (read when the first video is opened; set the variable to override).
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov", ".m4v", ".webm", ".mpg", ".mpeg",
                  ".wmv", ".flv", ".ts", ".mts", ".3gp", ".ogv",
                  ".insv", ".360")  # Insta360 and GoPro MAX: MP4 inside (engine/sources/video_360.py)

# Forward gaps up to this many frames are grabbed through; larger ones seek
# (a seek decodes from the previous key frame, so small gaps are cheaper to walk).
SEEK_GAP = 48
# Same tolerance as engine.frames.sample_indices.
EPS = 1e-6


def _open_capture(path: Path) -> cv2.VideoCapture:
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        cap.release()
        raise InputError(f"{path}: unreadable or unsupported video container")
    return cap


class VideoSource(CameraHeadings, FrameSource):
    """A video file; random access for the GUI and a single pass for sampling."""

    def __init__(self, path: str | Path, use_pyav: bool = True, keyframes: bool = True,
                 keyframes_only: bool = False, allow_truncated: bool = False) -> None:
        """``use_pyav=False`` forces the OpenCV reader; ``keyframes=False`` makes the
        PyAV sampler deliver the exact frames (``engine.frames.sample_indices``);
        ``keyframes_only``: ``frames`` delivers every key frame, whatever the interval
        (``--interval keyframes``; needs PyAV); ``allow_truncated``: a file cut short is read
        as far as it goes, with a note in ``notes`` (``--skip-bad-frames``)."""
        self.path = Path(path)
        self._use_pyav = use_pyav
        self._keyframes = keyframes
        self._keyframes_only = keyframes_only
        self._allow_truncated = allow_truncated
        self.notes: list[str] = []
        self._sampler: Optional[AvSampler] = None
        if not self.path.is_file():
            raise InputError(f"{self.path}: no such file")
        self._cap = _open_capture(self.path)
        size = (int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        if size[0] > 0 and size[1] > 0:  # from the container's header: refuse before decoding
            try:
                frame_size(*size, str(self.path))
            except InputError:
                self._cap.release()
                raise
        self._lock = threading.Lock()
        self.fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self._stamps: Optional[np.ndarray] = None
        self._next = 0  # index the next grab() of self._cap returns
        self._last: Optional[Frame] = None
        if not self._cap.grab():
            self._cap.release()
            raise InputError(f"{self.path}: video has no decodable frame")
        self._first_ms = float(self._cap.get(cv2.CAP_PROP_POS_MSEC))
        self._next = 1
        ok, bgr = self._cap.retrieve()
        if not ok or bgr is None:
            self._cap.release()
            raise InputError(f"{self.path}: first frame cannot be decoded")
        rgb = self._to_rgb(bgr)
        check_equirectangular(rgb, str(self.path))
        self._resolution = (rgb.shape[1], rgb.shape[0])
        self._last = Frame(0, 0.0, rgb)

    # --- PyAV sampler -----------------------------------------------------------

    def _av(self) -> Optional[AvSampler]:
        """The PyAV sampler, made on first use; None when PyAV cannot read this file."""
        if self._use_pyav and self._sampler is None:
            try:
                self._sampler = AvSampler(self.path, use_keyframes=self._keyframes,
                                          keyframes_only=self._keyframes_only,
                                          allow_truncated=self._allow_truncated)
            except AvUnavailable as err:
                if self._keyframes_only:
                    raise InputError(f"{self.path}: sampling at key frames needs PyAV to read this "
                                     f"video ({err}); use a sampling interval in seconds") from None
                self._use_pyav = False
            else:
                if self._sampler.missing:
                    self.notes.append(f"{self.path}: video is truncated or damaged: "
                                      f"{len(self._sampler.index)} of the {self._sampler.index.declared} "
                                      f"frames it declares can be read; read those")
        if self._keyframes_only and not self._use_pyav:
            raise InputError(f"{self.path}: sampling at key frames needs PyAV; use a sampling interval in seconds")
        return self._sampler if self._use_pyav else None

    @property
    def sampler(self) -> Optional[AvSampler]:
        """The PyAV sampler in use (None on the OpenCV path): its ``last_stats`` tell
        what the last ``frames()`` decoded."""
        return self._av()

    @property
    def reader_threads(self) -> int:
        """The PyAV sampler's decoding threads, each busy with 4K key frames; 0 on the OpenCV path."""
        return DECODE_THREADS if self._av() is not None else 0

    def sample_indices(self, interval: float = 1.0) -> np.ndarray:
        """The frames ``frames(interval)`` delivers (key frames where the sampler uses them)."""
        sampler = self._av()
        if sampler is not None:
            return sampler.plan(interval).indices.copy()
        return super().sample_indices(interval)

    # --- stamps -----------------------------------------------------------------

    def _stamp_from(self, cap: cv2.VideoCapture, index: int, prev: Optional[float]) -> float:
        """Stamp of the frame just grabbed: container time, or index / fps when the
        container time is missing or does not increase."""
        t = (float(cap.get(cv2.CAP_PROP_POS_MSEC)) - self._first_ms) * 1e-3
        if index == 0:
            return 0.0
        if prev is not None and t > prev:
            return round(t, 9)
        if self.fps > 0:
            return index / self.fps
        raise InputError(f"{self.path}: video has neither frame times nor a frame rate")

    def stamps(self) -> np.ndarray:
        if self._stamps is None and self._av() is not None:
            self._stamps = self._av().index.stamps.copy()
        if self._stamps is None:
            cap = _open_capture(self.path)
            try:
                out: list[float] = []
                while cap.grab():
                    out.append(self._stamp_from(cap, len(out), out[-1] if out else None))
            finally:
                cap.release()
            self._stamps = self._consistent(np.asarray(out, dtype=np.float64))
        return self._stamps.copy()

    def _consistent(self, stamps: np.ndarray) -> np.ndarray:
        """Use container times only when they increase throughout; else index / fps."""
        if stamps.size > 1 and not np.all(np.diff(stamps) > 0):
            if self.fps <= 0:
                raise InputError(f"{self.path}: video has neither frame times nor a frame rate")
            stamps = np.arange(stamps.size, dtype=np.float64) / self.fps
        return stamps

    def expected_samples(self, interval: float = 1.0) -> int:
        """From the container's frame count and rate while the stamps are unknown,
        so that describing a video decodes it once, not twice."""
        if self._av() is not None:
            return int(self._av().plan(interval).indices.size)
        frames = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        if self._stamps is not None or frames <= 0 or self.fps <= 0:
            return super().expected_samples(interval)
        if interval <= 0:
            return frames
        return int(((frames - 1) / self.fps + EPS) // interval) + 1

    @property
    def frame_count(self) -> int:
        return int(self.stamps().size)

    @property
    def resolution(self) -> tuple[int, int]:
        return self._resolution

    # --- frames -----------------------------------------------------------------

    def _to_rgb(self, bgr: np.ndarray) -> np.ndarray:
        if bgr.ndim == 2:
            return cv2.cvtColor(bgr, cv2.COLOR_GRAY2RGB)
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)

    def frame_at(self, index: int) -> Frame:
        stamps = self.stamps()
        if not 0 <= index < stamps.size:
            raise IndexError(f"frame {index} outside 0..{stamps.size - 1}")
        with self._lock:
            if self._last is not None and self._last.index == index:
                return self._last
            if index < self._next or index - self._next > SEEK_GAP:
                self._cap.set(cv2.CAP_PROP_POS_FRAMES, index)
                self._next = index
            while self._next < index:
                if not self._cap.grab():
                    break
                self._next += 1
            ok = self._cap.grab()
            bgr = self._cap.retrieve()[1] if ok else None
            if bgr is None:
                self._next = stamps.size  # position unknown: seek next time
                raise InputError(f"{self.path}: frame {index} cannot be decoded")
            self._next = index + 1
            rgb = self._to_rgb(bgr)
            check_equirectangular(rgb, f"{self.path}: frame {index}")
            self._last = Frame(index, float(stamps[index]), rgb)
            return self._last

    def frames(self, interval: float = 1.0, max_width: Optional[int] = None) -> Iterator[Frame]:
        """Sampled frames in one forward pass on a capture of its own.

        Picks, for t_k = k * interval, the first frame with stamp >= t_k (each
        frame once), like ``sample_indices``; also fills the stamp cache when the
        pass reaches the end. With PyAV, the sampler's frames instead (module doc),
        shrunk by FFmpeg to ``max_width`` columns; OpenCV's are full size.
        """
        sampler = self._av()
        if sampler is not None:
            self._stamps = sampler.index.stamps.copy()
            yield from sampler.frames(interval, max_width=max_width)
            return
        if self._stamps is not None:
            yield from self._frames_known(interval)
            return
        cap = _open_capture(self.path)
        try:
            seen: list[float] = []
            k = 0  # next target time index
            while cap.grab():
                index = len(seen)
                stamp = self._stamp_from(cap, index, seen[-1] if seen else None)
                seen.append(stamp)
                take = interval <= 0 or stamp >= k * interval - EPS
                if interval > 0:
                    while k * interval - EPS <= stamp:
                        k += 1
                if take:
                    ok, bgr = cap.retrieve()
                    if not ok or bgr is None:
                        raise InputError(f"{self.path}: frame {index} cannot be decoded")
                    rgb = self._to_rgb(bgr)
                    check_equirectangular(rgb, f"{self.path}: frame {index}")
                    yield Frame(index, stamp, rgb)
            self._stamps = self._consistent(np.asarray(seen, dtype=np.float64))
        finally:
            cap.release()

    def _frames_known(self, interval: float) -> Iterator[Frame]:
        """Single pass when the stamps are already known."""
        wanted = set(int(i) for i in self.sample_indices(interval))
        stamps = self._stamps
        assert stamps is not None
        cap = _open_capture(self.path)
        try:
            index = 0
            while wanted and cap.grab():
                if index in wanted:
                    wanted.discard(index)
                    ok, bgr = cap.retrieve()
                    if not ok or bgr is None:
                        raise InputError(f"{self.path}: frame {index} cannot be decoded")
                    rgb = self._to_rgb(bgr)
                    check_equirectangular(rgb, f"{self.path}: frame {index}")
                    yield Frame(index, float(stamps[index]), rgb)
                index += 1
        finally:
            cap.release()

    def close(self) -> None:
        with self._lock:
            self._cap.release()
