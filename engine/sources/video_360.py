"""Videos whose frames are not equirectangular: dual fisheye (.insv), GoPro EAC (.360).

``Video360Source`` reads through PyAV only (OpenCV sees one stream and no projection):
sampling, stamps and random access all go through ``engine.sources.video_av.AvSampler``,
which converts each decoded frame (or pair of frames, one per stream) to an equirectangular
panorama with ``engine.sources.projection.Converter`` as it is decoded. An Insta360 recording written one file
per lens (``VID_..._00_n.insv`` and ``..._10_n.insv``) opens from either file. Frame indices
and stamps are those of the first video stream (position in presentation order, pts from the
first frame); ``resolution`` is the panorama's at the camera's own resolution.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Iterator, Optional

import numpy as np

from .camera_heading import CameraHeadings
from ..errors import InputError
from ..frames import Frame, FrameSource
from ..validate import frame_size
from . import video_av
from .projection import Projection, lens_inputs


class Video360Source(CameraHeadings, FrameSource):
    """A dual-fisheye or EAC video, delivered as equirectangular frames."""

    def __init__(self, path: str | Path, projection: Projection, keyframes_only: bool = False,
                 allow_truncated: bool = False) -> None:
        self.path = Path(path)
        self.projection = projection
        if video_av.av is None:
            raise InputError(f"{self.path}: reading {projection.name} video needs PyAV (pip install av)")
        try:
            self.sampler = video_av.AvSampler(self.path, projection=projection, keyframes_only=keyframes_only,
                                              allow_truncated=allow_truncated,
                                              inputs=lens_inputs(self.path, projection))
        except video_av.AvUnavailable as err:
            raise InputError(f"{self.path}: cannot read this {projection.name} video ({err})") from None
        try:
            self._resolution = self.sampler.resolution
        except InputError as err:
            raise InputError(f"{self.path}: {err}") from None
        frame_size(*self._resolution, str(self.path))
        self.reader_threads = video_av.DECODE_THREADS
        self.notes: list[str] = []
        if self.sampler.missing:
            self.notes.append(video_av.truncation_message(self.path, self.sampler.index) +
                              f"; read the first {len(self.sampler.index)}")
        self._lock = threading.Lock()
        self._last: Optional[Frame] = None

    @property
    def frame_count(self) -> int:
        return len(self.sampler.index)

    @property
    def resolution(self) -> tuple[int, int]:
        return self._resolution

    def stamps(self) -> np.ndarray:
        return self.sampler.index.stamps.copy()

    def sample_indices(self, interval: float = 1.0) -> np.ndarray:
        return self.sampler.plan(interval).indices.copy()

    def expected_samples(self, interval: float = 1.0) -> int:
        return int(self.sampler.plan(interval).indices.size)

    def frame_at(self, index: int) -> Frame:
        with self._lock:
            if self._last is None or self._last.index != index:
                self._last = self.sampler.frame_at(int(index))
            return self._last

    def frames(self, interval: float = 1.0, max_width: Optional[int] = None) -> Iterator[Frame]:
        yield from self.sampler.frames(interval, max_width=max_width)

