"""Test data shared by the source and writer tests (no tests here).

Frames are a smooth random colour field, rolled a few columns per frame, plus
a frame-number code (a bright bar whose column depends on the frame number), so frames are distinguishable even
after lossy coding.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

W, H = 128, 64


def make_frames(n: int, w: int = W, h: int = H, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    coarse = rng.integers(30, 220, size=(h // 16, w // 16, 3)).astype(np.uint8)
    base = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    frames = []
    for k in range(n):
        # The view turns a little each frame, as a panorama does when the robot turns.
        rgb = np.roll(base, 3 * k, axis=1)
        col = (k * 7) % (w - 8)
        rgb[:, col:col + 8] = 255 - rgb[:, col:col + 8] // 4
        frames.append(rgb)
    return frames


def make_stamps(n: int, fps: float = 10.0, start: float = 0.0) -> np.ndarray:
    return start + np.arange(n, dtype=np.float64) / fps


def mean_abs_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.abs(a.astype(np.float64) - b.astype(np.float64))))


def write_messages_bag(path: Path, messages: Sequence[tuple[str, float, Any]]) -> Path:
    """ROS1 bag of arbitrary (topic, log time s, message) built with ``ros1_types()``."""
    from rosbags.rosbag1 import Writer

    typestore = ros1_types()
    with Writer(path) as writer:
        conns: dict[str, Any] = {}
        for topic, t, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=typestore)
            writer.write(conns[topic], int(round(t * 1e9)),
                         typestore.serialize_ros1(msg, msg.__msgtype__))
    return path


def ros1_types() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC)


def ros1_header(t: float) -> Any:
    ts = ros1_types().types
    ns = int(round(t * 1e9))
    return ts["std_msgs/msg/Header"](
        seq=0, stamp=ts["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
        frame_id="cam")


def ros1_image(rgb: np.ndarray, t: float) -> Any:
    Image = ros1_types().types["sensor_msgs/msg/Image"]
    h, w = rgb.shape[:2]
    return Image(header=ros1_header(t), height=h, width=w, encoding="rgb8", is_bigendian=0,
                 step=3 * w, data=np.ascontiguousarray(rgb).reshape(-1))


def ros1_compressed(data: bytes, t: float) -> Any:
    CompressedImage = ros1_types().types["sensor_msgs/msg/CompressedImage"]
    return CompressedImage(header=ros1_header(t), format="jpeg",
                           data=np.frombuffer(data, dtype=np.uint8))
