"""Any recording's frames converted to equirectangular: ``ProjectedSource``.

For readers that deliver frames of another projection as plain RGB (a ROS driver publishing
two fisheyes side by side as ``sensor_msgs/Image``, a folder of dual-fisheye photos): the
wrapper converts every frame it passes on with ``engine.sources.projection.Converter``, so
the reader itself needs no change. Indices and stamps are the reader's; frames come at the
panorama's native size (or shrunk to ``max_width``, ``Frame.source_width`` set).
"""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import Iterator, Optional

import numpy as np

from ..errors import InputError
from ..frames import Frame, FrameSource
from .projection import DEFAULT_FOV, Converter, Projection, native_size


class ProjectedSource(FrameSource):
    """``inner``'s frames, of projection ``projection`` (one stream), as equirectangular."""

    def __init__(self, inner: FrameSource, projection: Projection) -> None:
        if projection.streams != 1:
            raise InputError(f"{inner.path}: a {projection.name} ({projection.layout}) recording needs two "
                             f"video streams; this reader gives one picture per frame")
        if projection.name == "dual-fisheye" and not projection.fov:
            projection = replace(projection, fov=DEFAULT_FOV["generic"])
        self.inner, self.projection, self.path = inner, projection, inner.path
        self.reader_threads = inner.reader_threads
        w, h = inner.resolution
        try:
            self._resolution = native_size(projection, [(w, h)])
        except InputError as err:
            raise InputError(f"{inner.path}: {err}") from None
        self._converters: dict = {}
        self._lock = threading.Lock()

    def _convert(self, frame: Frame, max_width: Optional[int]) -> Frame:
        key = (threading.get_ident(), max_width, frame.rgb.shape)
        with self._lock:
            conv = self._converters.get(key)
            if conv is None:
                conv = self._converters[key] = Converter(self.projection, [frame.rgb.shape[1::-1]], max_width)
        rgb = conv([frame.rgb])
        return Frame(frame.index, frame.stamp, rgb, conv.native[0] if rgb.shape[1] < conv.native[0] else 0)

    @property
    def frame_count(self) -> int:
        return self.inner.frame_count

    @property
    def resolution(self) -> tuple[int, int]:
        return self._resolution

    def stamps(self) -> np.ndarray:
        return self.inner.stamps()

    def sample_indices(self, interval: float = 1.0) -> np.ndarray:
        return self.inner.sample_indices(interval)

    def expected_samples(self, interval: float = 1.0) -> int:
        return self.inner.expected_samples(interval)

    def headings(self) -> Optional[np.ndarray]:
        """The reader's headings (e.g. a bag's odometry): the panorama turns with the camera,
        and a fixed offset between the image centre and the robot's front does not matter."""
        headings = self.inner.headings()
        self.heading_note = getattr(self.inner, "heading_note", "")
        return headings

    def frame_at(self, index: int) -> Frame:
        return self._convert(self.inner.frame_at(index), None)

    def frames(self, interval: float = 1.0, max_width: Optional[int] = None) -> Iterator[Frame]:
        for frame in self.inner.frames(interval):
            yield self._convert(frame, max_width)

    def close(self) -> None:
        self.inner.close()
