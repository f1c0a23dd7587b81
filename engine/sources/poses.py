"""Ground-truth poses for evaluation: a CSV file or a pose topic of a ROS bag.

CSV: a header ``t,x,y`` or ``t,x,y,yaw`` (seconds, metres, radians), then one
pose per line. Bags: a ``nav_msgs/msg/Odometry``, ``geometry_msgs/msg/PoseStamped``
or ``geometry_msgs/msg/PoseWithCovarianceStamped`` topic; t is the header stamp
(log time when it is zero), yaw comes from the orientation quaternion.
Poses are returned sorted by time.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..errors import InputError
from ..poses import Poses
from .orientation import quaternion_yaw
from .rosbag import POSE_TYPES, _one_line, choose_topic, message_stamp, open_bag


def read_poses(path: str | Path, topic: Optional[str] = None) -> Poses:
    """Poses from a ``t,x,y[,yaw]`` CSV or from a bag's pose topic."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file or directory")
    if path.is_file() and path.suffix.lower() in (".csv", ".txt"):
        return read_poses_csv(path)
    return read_poses_bag(path, topic)


def read_poses_csv(path: Path) -> Poses:
    try:
        lines = [ln.strip() for ln in path.read_text().splitlines()]
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: cannot read ({err})") from None
    lines = [ln for ln in lines if ln]
    if not lines:
        raise InputError(f"{path}: empty poses file (expected a 't,x,y[,yaw]' header)")
    header = [c.strip().lower() for c in lines[0].split(",")]
    if header not in (["t", "x", "y"], ["t", "x", "y", "yaw"]):
        raise InputError(f"{path}: header must be 't,x,y' or 't,x,y,yaw', got {lines[0]!r}")
    if len(lines) < 2:
        raise InputError(f"{path}: no poses after the header")
    rows = []
    for n, line in enumerate(lines[1:], start=2):
        cells = line.split(",")
        if len(cells) != len(header):
            raise InputError(f"{path}: line {n} has {len(cells)} values, expected {len(header)}")
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            raise InputError(f"{path}: line {n} is not numbers: {line!r}") from None
    table = np.asarray(rows, dtype=np.float64)
    if not np.all(np.isfinite(table)):
        raise InputError(f"{path}: contains non-finite values")
    return _sorted_poses(table[:, 0], table[:, 1], table[:, 2],
                         table[:, 3] if table.shape[1] == 4 else None, where=str(path))


def read_poses_bag(path: Path, topic: Optional[str] = None) -> Poses:
    reader = open_bag(path)
    try:
        topic, connections = choose_topic(reader, path, topic, POSE_TYPES, "pose")
        t, x, y, yaw = [], [], [], []
        for conn, log_ns, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, conn.msgtype)
            pose = _pose_of(msg, conn.msgtype)
            t.append(message_stamp(msg, log_ns))
            x.append(float(pose.position.x))
            y.append(float(pose.position.y))
            yaw.append(quaternion_yaw(pose.orientation))
    except InputError:
        raise
    except Exception as err:
        raise InputError(f"{path}: cannot read poses ({_one_line(err)})") from None
    finally:
        reader.close()
    if not t:
        raise InputError(f"{path}: pose topic {topic} has no messages")
    return _sorted_poses(np.array(t, np.float64), np.array(x, np.float64), np.array(y, np.float64),
                         np.array(yaw, np.float64), where=f"{path} ({topic})")


def _pose_of(msg: Any, msgtype: str) -> Any:
    if msgtype == "geometry_msgs/msg/PoseStamped":
        return msg.pose
    return msg.pose.pose  # Odometry and PoseWithCovarianceStamped


# The largest position coordinate accepted, in metres: ten times the Earth's radius, beyond
# any map frame, UTM or Earth-centred coordinate; larger values are a unit or scale error
# (and squared distances of 1e300 overflow to infinity: every pair "far", silently).
MAX_POSE_COORD_M = 6.4e7
# The largest time accepted, in seconds: about 3,000 years of ROS (Unix) time; larger
# stamps are nanoseconds or garbage, and a float64 second there is coarser than 1 ms.
MAX_POSE_TIME_S = 1e11


def _check_values(where: str, t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: Optional[np.ndarray]) -> None:
    """Refuse poses that are not finite, or whose positions or times are out of range."""
    for name, values in (("t", t), ("x", x), ("y", y), ("yaw", yaw)):
        if values is None:
            continue
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise InputError(f"{where}: pose {int(bad[0]) + 1} has a non-finite {name} ({values[bad[0]]})")
    for name, values, limit, unit in (("x", x, MAX_POSE_COORD_M, "m"), ("y", y, MAX_POSE_COORD_M, "m"),
                                      ("t", t, MAX_POSE_TIME_S, "s")):
        bad = np.flatnonzero(np.abs(values) > limit)
        if bad.size:
            raise InputError(f"{where}: pose {int(bad[0]) + 1} has {name} = {values[bad[0]]:.6g} {unit}, beyond "
                             f"{limit:g} {unit}; are the poses in metres and seconds?")


def _sorted_poses(t: np.ndarray, x: np.ndarray, y: np.ndarray,
                  yaw: Optional[np.ndarray], where: str = "poses") -> Poses:
    _check_values(where, t, x, y, yaw)
    # Interpolation needs increasing times; recorders sometimes write out of order.
    order = np.argsort(t, kind="stable")
    return Poses(t=t[order].astype(np.float64), x=x[order].astype(np.float64),
                 y=y[order].astype(np.float64),
                 yaw=None if yaw is None else yaw[order].astype(np.float64))
