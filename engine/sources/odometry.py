"""A bag's odometry: the robot's own metric poses at the image stamps, for the pose graph.

A ``nav_msgs/Odometry`` or ``geometry_msgs/PoseStamped`` topic (either spelling of the type,
``pkg/msg/Type`` or ROS1's ``pkg/Type``; a named topic may also be
``geometry_msgs/PoseWithCovarianceStamped``) gives x, y (metres) and yaw (from the
orientation quaternion) in its own frame. Unless a topic is named, the one topic of those two
types is used; with none the map stays image-only, with several none is chosen (one note says
which to name). A message's stamp is its header stamp (its log time when that is zero).

``at(stamps)`` interpolates the poses linearly in time (yaw on the unwrapped angle). It
refuses, in one line, stamps the topic does not cover: before its first or after its last
message by more than ``MAX_GAP_S``, or further than that from the nearest message. Messages
within ``MIN_STEP_S`` of the last one kept are skipped unread (``orientation.MIN_STEP_S``:
a robot's pose is smooth at 20 Hz, and deserialising a 100 Hz topic dominated the reading).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..errors import InputError
from .orientation import MIN_STEP_S, POSE_TYPES, quaternion_yaw, thinned

ODOMETRY_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped")
# Longest time (s) between an image and the odometry message nearest to it. Odometry runs at
# 10-100 Hz and a SLAM pose topic at 1 Hz or more; over a second a robot's path is close to a
# straight line at constant speed, which is what the interpolation assumes.
MAX_GAP_S = 1.0
# The value that turns odometry off (``--odom-topic none``).
NO_TOPIC = "none"


@dataclass
class Odometry:
    """Poses of one topic, sorted by stamp: t (s), x, y (m), yaw (rad, unwrapped)."""

    topic: str
    msgtype: str
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray

    def line(self) -> str:
        """One line saying which topic was used."""
        return (f"odometry from {self.topic} ({self.msgtype}, {self.t.size} poses used, "
                f"{self.t[-1] - self.t[0]:.1f} s)")

    def at(self, stamps: np.ndarray, where: str = "") -> np.ndarray:
        """(n, 3) x, y (m), yaw (rad, wrapped to [-pi, pi)) at ``stamps``; InputError in one
        line when the topic does not cover them (module notes)."""
        stamps = np.asarray(stamps, np.float64)
        if stamps.size == 0:
            return np.zeros((0, 3))
        i = np.searchsorted(self.t, stamps)
        left = self.t[np.clip(i - 1, 0, self.t.size - 1)]
        right = self.t[np.clip(i, 0, self.t.size - 1)]
        nearest = np.minimum(np.abs(stamps - left), np.abs(right - stamps))
        bad = np.flatnonzero(nearest > MAX_GAP_S)
        if bad.size:
            k = int(bad[0])
            raise InputError(
                f"{where + ': ' if where else ''}odometry topic {self.topic} does not cover the images: it spans "
                f"{self.t[0]:.3f}-{self.t[-1]:.3f} s, the images {stamps.min():.3f}-{stamps.max():.3f} s, and "
                f"{bad.size} of {stamps.size} images are more than {MAX_GAP_S:g} s from an odometry message "
                f"(first at {stamps[k]:.3f} s); name another with --odom-topic, or --odom-topic {NO_TOPIC}")
        yaw = np.interp(stamps, self.t, self.yaw)
        return np.stack([np.interp(stamps, self.t, self.x), np.interp(stamps, self.t, self.y),
                         (yaw + np.pi) % (2 * np.pi) - np.pi], axis=1)


def odometry_topics(reader: Any, msgtypes=ODOMETRY_TYPES) -> list[tuple[str, str]]:
    """(topic, message type) of every topic of ``msgtypes``, by name."""
    return sorted({(c.topic, c.msgtype) for c in reader.connections if c.msgtype in msgtypes})


def read_odometry(path: Path, topic: Optional[str] = None) -> tuple[Optional[Odometry], str]:
    """(odometry, note) of the bag at ``path``: ``topic`` when named (InputError when the bag
    has no such pose topic), else its one Odometry / PoseStamped topic; (None, note) when it
    has none (note "") or several (the note names them)."""
    from .rosbag import _one_line, open_bag

    path = Path(path)
    reader = open_bag(path)
    try:
        if topic is None:
            found = odometry_topics(reader)
            names = sorted({t for t, _ in found})
            if not names:
                return None, ""
            if len(names) > 1:
                return None, (f"{path}: several odometry topics ({', '.join(names)}), none used; "
                              f"choose one with --odom-topic")
            topic = names[0]
        else:
            names = sorted({t for t, _ in odometry_topics(reader, POSE_TYPES)})
            if topic not in names:
                raise InputError(f"{path}: no odometry topic {topic!r}; Odometry / PoseStamped topics: "
                                 f"{', '.join(names) or 'none'}")
        try:
            odometry = _read(reader, topic)
        except InputError:
            raise
        except Exception as err:
            raise InputError(f"{path}: cannot read odometry topic {topic} ({_one_line(err)})") from None
    finally:
        reader.close()
    if odometry.t.size == 0:
        raise InputError(f"{path}: odometry topic {topic} has no messages")
    return odometry, odometry.line()


def _read(reader: Any, topic: str, min_step: float = MIN_STEP_S) -> Odometry:
    from .poses import MAX_POSE_COORD_M

    conns = [c for c in reader.connections if c.topic == topic and c.msgtype in POSE_TYPES]
    t, x, y, yaw = [], [], [], []
    for conn, ns, raw, keep in thinned(reader, conns, min_step):
        msg = reader.deserialize(raw, conn.msgtype)
        pose = msg.pose if conn.msgtype == "geometry_msgs/msg/PoseStamped" else msg.pose.pose
        px, py = float(pose.position.x), float(pose.position.y)
        if not (np.isfinite(px) and np.isfinite(py)) or max(abs(px), abs(py)) > MAX_POSE_COORD_M:
            raise InputError(f"odometry topic {topic}: a pose at {ns * 1e-9:.3f} s has position "
                             f"({px:.6g}, {py:.6g}); are the poses in metres?")
        keep(ns)
        t.append(ns * 1e-9)
        x.append(px)
        y.append(py)
        yaw.append(quaternion_yaw(pose.orientation))
    t_arr = np.asarray(t, np.float64)
    order = np.argsort(t_arr, kind="stable")
    t_arr = t_arr[order]
    keep = np.concatenate([[True], np.diff(t_arr) > 0]) if t_arr.size else np.zeros(0, bool)
    yaw_arr = np.asarray(yaw, np.float64)[order][keep]
    yaw_arr = np.unwrap(np.nan_to_num(yaw_arr)) if yaw_arr.size else yaw_arr
    return Odometry(topic=topic, msgtype=conns[0].msgtype if conns else "", t=t_arr[keep],
                    x=np.asarray(x, np.float64)[order][keep], y=np.asarray(y, np.float64)[order][keep],
                    yaw=yaw_arr)
