"""Which way the camera looked, from a bag's own orientation topic: headings for the shift.

A bag's ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped``,
``geometry_msgs/PoseWithCovarianceStamped`` or ``sensor_msgs/Imu`` topic (either spelling of
the type) gives the yaw of the robot; the camera, mounted on it, turns with it. Unless the
caller names a topic, the kinds are tried in ``TIERS`` order (odometry, often fused, before
poses before a bare IMU): a kind with one topic is tried, a kind with several is ambiguous
and ends the search (the image then decides the shift); a topic that gives no headings (see
below) passes on to the next kind. An Imu message whose ``orientation_covariance[0]`` is -1 (the
driver's "no orientation") or whose quaternion is zero is left out, and a topic whose every
message has the very same orientation (GPS-only odometry writes the identity quaternion) is
not a direction (``BagSource.headings``).

Odometry yaw is counted from where the recording started (unless the robot localises in a
map frame or has a compass): it aligns the frames of one recording with each other, and two
recordings only when they share that reference.

Headings come out as ``engine.frames.FrameSource.headings`` wants them: degrees clockwise
(``-yaw``), at the frame stamps, interpolated on the unwrapped yaw. A frame more than
``MAX_GAP_S`` from the nearest orientation sample, or outside the topic's time span by more
than that, has no trustworthy heading, and then no frame gets one: a shift partly from the
world and partly from the image would be the same for no two frames.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

POSE_TYPES = (   # engine.sources.rosbag.POSE_TYPES is this
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
)
IMU_TYPE = "sensor_msgs/msg/Imu"
ORIENTATION_TYPES = POSE_TYPES + (IMU_TYPE,)
TIERS = (("nav_msgs/msg/Odometry",), POSE_TYPES[1:], (IMU_TYPE,))
# Longest time (s) between a frame and an orientation sample it is interpolated from.
MAX_GAP_S = 0.5
# Orientation samples closer than this (s) to the last one kept are skipped unread: a robot's
# yaw is smooth at 20 Hz, and deserialising every message of a 100-200 Hz odometry or IMU
# topic cost 75-145 us each: 20,000 Odometry messages at 100 Hz took 2.9 s, 1.5 s so
# (reading the raw messages alone 0.26 s; the 2-core machine, shared).
MIN_STEP_S = 0.05


def orientation_topics(reader: Any) -> list[str]:
    """Topics of the bag whose messages carry an orientation, by name."""
    return sorted({c.topic for c in reader.connections if c.msgtype in ORIENTATION_TYPES})


def candidate_topics(reader: Any) -> tuple[list[str], str]:
    """(topics to try in order, a note when a kind had several topics) by ``TIERS``."""
    tried: list[str] = []
    for kinds in TIERS:
        topics = sorted({c.topic for c in reader.connections if c.msgtype in kinds})
        if len(topics) > 1:
            return tried, f"several orientation topics of one kind ({', '.join(topics)}), none chosen"
        tried += topics
    return tried, ""


def quaternion_yaw(q: Any) -> float:
    """Rotation about z (radians, counter-clockwise) of a unit quaternion (atan2 of the
    ZYX Euler formula: any positive scale of the quaternion gives the same angle)."""
    return float(np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)))


def _orientation(msg: Any, msgtype: str) -> Optional[Any]:
    if msgtype == IMU_TYPE:
        cov = np.asarray(msg.orientation_covariance, dtype=np.float64).reshape(-1)
        if cov.size and cov[0] == -1.0:
            return None
        q = msg.orientation
    elif msgtype == "geometry_msgs/msg/PoseStamped":
        q = msg.pose.orientation
    else:  # Odometry, PoseWithCovarianceStamped
        q = msg.pose.pose.orientation
    norm = float(np.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w))
    return q if np.isfinite(norm) and norm > 1e-6 else None


def thinned(reader: Any, conns: list, min_step: float = MIN_STEP_S):
    """(conn, header stamp ns, raw, keep) of ``conns``' messages, less those within ``min_step``
    s after the last one kept (their stamp read from the bytes, never deserialised). The caller
    calls ``keep(ns)`` on the messages it uses: one it leaves out (no orientation) sets no clock."""
    from .rosbag import header_stamp_ns   # rosbag imports this module

    last = [None]
    step_ns = int(min_step * 1e9)

    def keep(ns: int) -> None:
        last[0] = ns

    for conn, log_ns, raw in reader.messages(connections=conns):
        ns = header_stamp_ns(raw, reader.is2) or log_ns   # every kind starts with a Header
        if last[0] is None or not 0 <= ns - last[0] < step_ns:
            yield conn, ns, raw, keep


def read_yaw(reader: Any, topic: str, min_step: float = MIN_STEP_S) -> tuple[np.ndarray, np.ndarray, str]:
    """(stamps s, yaw rad, message type) of ``topic``: header stamps (log time when zero),
    sorted by stamp; messages without an orientation are left out, and messages within
    ``min_step`` s after the last one kept are not read (their stamp comes from the bytes)."""
    conns = [c for c in reader.connections if c.topic == topic and c.msgtype in ORIENTATION_TYPES]
    t, yaw = [], []
    for conn, ns, raw, keep in thinned(reader, conns, min_step):
        q = _orientation(reader.deserialize(raw, conn.msgtype), conn.msgtype)
        if q is None:
            continue
        keep(ns)
        t.append(ns * 1e-9)
        yaw.append(quaternion_yaw(q))
    order = np.argsort(np.asarray(t, dtype=np.float64), kind="stable")
    return (np.asarray(t, dtype=np.float64)[order], np.asarray(yaw, dtype=np.float64)[order],
            conns[0].msgtype if conns else "")


def headings_at(t: np.ndarray, yaw: np.ndarray, stamps: np.ndarray,
                max_gap: float = MAX_GAP_S) -> Optional[np.ndarray]:
    """Compass-style headings (degrees clockwise, [0, 360)) at ``stamps`` from yaw samples
    (radians counter-clockwise) at ``t``, interpolated on the unwrapped yaw; None unless every
    stamp is within ``max_gap`` s of its nearest sample."""
    t = np.asarray(t, dtype=np.float64)
    yaw = np.asarray(yaw, dtype=np.float64)
    stamps = np.asarray(stamps, dtype=np.float64)
    if t.size == 0 or stamps.size == 0 or not np.all(np.isfinite(yaw)):
        return None
    keep = np.concatenate([[True], np.diff(t) > 0])   # np.interp needs increasing times
    t, yaw = t[keep], np.unwrap(yaw[keep])
    i = np.searchsorted(t, stamps)
    left, right = t[np.clip(i - 1, 0, t.size - 1)], t[np.clip(i, 0, t.size - 1)]
    nearest = np.minimum(np.abs(stamps - left), np.abs(right - stamps))
    if np.any(nearest > max_gap):
        return None
    return (-np.degrees(np.interp(stamps, t, yaw))) % 360.0
