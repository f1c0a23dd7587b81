"""What a recording says in metres about where it was: the metric factors of the pose graph.

``Metric`` holds, per descriptor row (and, taken at the nodes, per node):

- ``odometry``: the robot's own poses (x, y in metres, yaw in radians, in the odometry's
  frame) from a bag's Odometry / PoseStamped topic (``engine.sources.odometry``);
- ``gps``: positions in local metres (east, north) from a photo folder's EXIF GPS or a GoPro
  video's GPMF track (``engine.sources.recording_poses``), NaN where there is no fix near;
- ``gps_dop``: the fix's dilution of precision where the recording gives one (GPMF), NaN
  elsewhere; the pose graph's sigma is ``gps_dop_sigma_m`` per unit of it, or ``gps_sigma_m``.

``engine.metric_factors`` turns these into the pose graph's step and position factors, solved
in metres; without them (``Metric.empty``) it stays image-only, in node steps.
``read_metric`` reads them from a recording (``engine.run`` calls it); nothing here is ground
truth, and none of it is used for evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from .poses import Poses

# A row further than this (s) from the nearest GPS sample has no GPS position (a GoPro loses
# its fix for seconds under trees or in a tunnel; interpolating across the gap would invent
# a straight path). GPMF samples at 10-18 Hz, EXIF once per photo (one every 1-2 s). Nor has a
# row before the first fix or after the last (more than a millisecond): no extrapolation.
GPS_MAX_GAP_S = 2.0


@dataclass
class Metric:
    """Metric data per row or node (module notes); None: the recording has none of that kind."""

    odometry: Optional[np.ndarray] = None   # (n, 3) x, y metres, yaw radians
    gps: Optional[np.ndarray] = None        # (n, 2) x east, y north, metres (NaN: no fix)
    gps_dop: Optional[np.ndarray] = None    # (n,) dilution of precision (NaN: unknown)
    odometry_topic: str = ""                # the bag topic the odometry came from
    notes: list = field(default_factory=list)      # where each came from, one line each
    warnings: list = field(default_factory=list)   # what was there but not used, one line each

    @property
    def rows(self) -> int:
        """How many rows (or nodes) it holds."""
        for a in (self.odometry, self.gps, self.gps_dop):
            if a is not None:
                return int(np.asarray(a).shape[0])
        return 0

    @property
    def empty(self) -> bool:
        return self.odometry is None and (self.gps is None or not np.isfinite(self.gps).all(axis=1).any())

    def take(self, rows) -> "Metric":
        """The data at ``rows`` (the nodes' rows of the recording)."""
        rows = np.asarray(rows, np.int64)

        def pick(a):
            return None if a is None else np.asarray(a)[rows]

        return Metric(pick(self.odometry), pick(self.gps), pick(self.gps_dop), self.odometry_topic,
                      list(self.notes), list(self.warnings))

    def gps_sigma(self, default_m: float, per_dop_m: float) -> np.ndarray:
        """(n,) metres: ``per_dop_m`` x the fix's DOP where known, else ``default_m``."""
        n = 0 if self.gps is None else self.gps.shape[0]
        dop = np.full(n, np.nan) if self.gps_dop is None else np.asarray(self.gps_dop, np.float64)
        return np.where(np.isfinite(dop) & (dop > 0), dop * per_dop_m, default_m)


def gps_at(poses: Poses, stamps: np.ndarray, max_gap: float = GPS_MAX_GAP_S) -> np.ndarray:
    """(n, 2) GPS positions at ``stamps``, linearly interpolated; NaN for a stamp outside the
    track's time span or further than ``max_gap`` s from the nearest fix (in a gap of it)."""
    stamps = np.asarray(stamps, np.float64)
    t = np.asarray(poses.t, np.float64)
    out = np.full((stamps.size, 2), np.nan)
    if t.size == 0 or stamps.size == 0:
        return out
    i = np.searchsorted(t, stamps)
    left, right = t[np.clip(i - 1, 0, t.size - 1)], t[np.clip(i, 0, t.size - 1)]
    near = np.minimum(np.abs(stamps - left), np.abs(right - stamps)) <= max_gap
    near &= (stamps >= t[0] - 1e-3) & (stamps <= t[-1] + 1e-3)
    x, y = poses.at(stamps[near])
    out[near, 0], out[near, 1] = x, y
    return out


def gpmf_dop_at(path: Path, stamps: np.ndarray) -> Optional[np.ndarray]:
    """The dilution of precision of a GoPro video's good GPS fixes at ``stamps`` (nearest
    fix's value), or None for any other recording."""
    from .sources import gpmf
    from .sources.video import VIDEO_SUFFIXES

    path = Path(path)
    if not (path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES):
        return None
    tel = gpmf.read_telemetry(path)
    if tel is None or tel.gps_t.size == 0:
        return None
    ok = gpmf.good_fixes(tel)
    t, dop = tel.gps_t[ok], tel.dop[ok]
    if t.size == 0:
        return None
    order = np.argsort(t, kind="stable")
    t, dop = t[order], dop[order]
    s = np.asarray(stamps, np.float64)
    i = np.searchsorted(t, s)
    lo, hi = np.clip(i - 1, 0, t.size - 1), np.clip(i, 0, t.size - 1)
    return dop[np.where(np.abs(s - t[lo]) <= np.abs(t[hi] - s), lo, hi)].astype(np.float64)


class BagOdometry:
    """A bag's odometry as ``bag_odometry`` found it: the topic's poses (None: none used) and
    one line saying which was used, or why none was."""

    def __init__(self, odometry=None, note: str = "", warning: str = "") -> None:
        self.odometry, self.note, self.warning = odometry, note, warning


def bag_odometry(path: Path, odom_topic: Optional[str] = None, *, image_topic: Optional[str] = None,
                 interval: Optional[float] = None) -> BagOdometry:
    """The odometry of the recording at ``path``, read before it is described: ``odom_topic``
    (None: the bag's one Odometry / PoseStamped topic; "none": no odometry); nothing for a
    recording that is not a bag (InputError when a topic was named for one). With
    ``interval``, the frames that will be described (``image_topic``, sampled as describing
    samples them) must be covered: a long recording is refused before it is described, not after."""
    from .errors import InputError
    from .sources.odometry import NO_TOPIC, read_odometry
    from .sources.rosbag import BagSource, is_ros2_bag_dir

    path = Path(path)
    is_bag = is_ros2_bag_dir(path) if path.is_dir() else path.suffix.lower() in (".bag", ".db3", ".mcap")
    if odom_topic is not None and odom_topic != NO_TOPIC and not is_bag:
        raise InputError(f"{path}: an odometry topic ({odom_topic}) was given, but only ROS bags have topics")
    if not is_bag or odom_topic == NO_TOPIC:
        return BagOdometry()
    odometry, note = read_odometry(path, odom_topic)
    if odometry is None:
        return BagOdometry(warning=note)
    if interval is not None:
        with BagSource(path, image_topic) as source:
            odometry.at(np.asarray(source.stamps(), np.float64)[source.sample_indices(interval)], str(path))
    return BagOdometry(odometry, note=note)


def read_metric(path: Path, stamps: np.ndarray, *, gps: Optional[Poses] = None,
                odometry: Optional[BagOdometry] = None) -> Metric:
    """The metric data of the recording at ``path`` at its descriptor ``stamps``: ``gps`` (the
    recording's own positions, ``engine.sources.recording_poses``, when it has them) and a
    bag's ``odometry`` (``bag_odometry``). InputError when the odometry does not cover the
    stamps."""
    path = Path(path)
    stamps = np.asarray(stamps, np.float64)
    metric = Metric()
    if gps is not None and len(gps):
        xy = gps_at(gps, stamps)
        if np.isfinite(xy).all(axis=1).any():
            metric.gps = xy
            metric.gps_dop = gpmf_dop_at(path, stamps)
            known = "its DOP" if metric.gps_dop is not None else "a default sigma"
            metric.notes.append(f"GPS positions on {int(np.isfinite(xy).all(axis=1).sum())} of {stamps.size} "
                                f"frames, each with {known}, in the pose graph")
    if odometry is not None and odometry.odometry is not None:
        metric.odometry = odometry.odometry.at(stamps, str(path))
        metric.odometry_topic = odometry.odometry.topic
        metric.notes.append(odometry.note)
    elif odometry is not None and odometry.warning:
        metric.warnings.append(odometry.warning)
    return metric
