"""Write recordings in every format panotopo reads: video, image folder, ROS1/ROS2 bags, poses CSV.

Used by the tests and by the synthetic recording generator, so that each reader
is exercised on real files written by real libraries (OpenCV, rosbags).

Frames are RGB uint8 H x W x 3 arrays; stamps are seconds (float). In bags the
header stamp and the log time of a message are both the frame's stamp.
"""

from __future__ import annotations

import heapq
import math
import shutil
from pathlib import Path
from typing import Any, Iterator, Optional, Sequence

import cv2
import numpy as np

from ..errors import InputError
from ..poses import Poses

# Encodings the bag writers can produce from an RGB frame.
BAG_ENCODINGS = ("rgb8", "bgr8", "mono8", "mono16", "bayer_rggb8")


def write_video(path: str | Path, frames: Sequence[np.ndarray], fps: float) -> Path:
    """Write ``frames`` to an .mp4 (mp4v) or .avi (MJPG) file at ``fps``."""
    path = Path(path)
    codecs = {".mp4": "mp4v", ".avi": "MJPG"}
    if path.suffix.lower() not in codecs:
        raise InputError(f"{path}: video must end in .mp4 or .avi, not {path.suffix!r}")
    if not frames:
        raise InputError(f"{path}: no frames to write")
    h, w = frames[0].shape[:2]
    path.parent.mkdir(parents=True, exist_ok=True)
    fourcc = cv2.VideoWriter_fourcc(*codecs[path.suffix.lower()])
    writer = cv2.VideoWriter(str(path), fourcc, float(fps), (w, h))
    if not writer.isOpened():
        raise InputError(f"{path}: OpenCV cannot open a video writer for this file")
    try:
        for rgb in frames:
            _check_rgb(rgb, (h, w), path)
            writer.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    finally:
        writer.release()
    return path


def write_image_folder(path: str | Path, frames: Sequence[np.ndarray], stamps: Sequence[float]) -> Path:
    """Write PNG files ``frame_000000.png``... and a ``filename,stamp`` stamps.csv."""
    path = Path(path)
    _check_lengths(frames, stamps)
    path.mkdir(parents=True, exist_ok=True)
    rows = ["filename,stamp"]
    for k, (rgb, stamp) in enumerate(zip(frames, stamps)):
        name = f"frame_{k:06d}.png"
        if not cv2.imwrite(str(path / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
            raise InputError(f"{path / name}: OpenCV cannot write this image")
        rows.append(f"{name},{float(stamp)!r}")
    (path / "stamps.csv").write_text("\n".join(rows) + "\n")
    return path


def write_poses_csv(path: str | Path, poses: Poses) -> Path:
    """Write ``t,x,y[,yaw]`` with a header (yaw in radians)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = [poses.t, poses.x, poses.y] + ([poses.yaw] if poses.yaw is not None else [])
    header = "t,x,y" + (",yaw" if poses.yaw is not None else "")
    lines = [header] + [",".join(repr(float(v)) for v in row) for row in zip(*cols)]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_ros1_bag(
    path: str | Path,
    frames: Sequence[np.ndarray],
    stamps: Sequence[float],
    *,
    topic: str = "/camera/image_raw",
    compressed: bool = False,
    encoding: str = "rgb8",
    poses: Optional[Poses] = None,
    pose_topic: str = "/odom",
    pose_type: str = "odometry",
    image_format: str = "jpeg",
    jpeg_quality: int = 95,
) -> Path:
    """Write a ROS1 .bag with an Image (or CompressedImage) topic and optional poses.

    ``encoding`` is one of BAG_ENCODINGS (raw images); ``compressed`` writes
    CompressedImage in ``image_format`` "jpeg" (``jpeg_quality``) or "png".
    ``poses`` go to ``pose_topic`` as nav_msgs/Odometry, or geometry_msgs/PoseStamped
    when ``pose_type == "posestamped"``.
    """
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    _check_lengths(frames, stamps)
    _remove(path)
    typestore = get_typestore(Stores.ROS1_NOETIC)
    messages = _messages(typestore, frames, stamps, topic, compressed, encoding,
                         poses, pose_topic, pose_type, image_format, jpeg_quality, ros1=True)
    with Writer(path) as writer:
        _write_messages(writer, typestore, messages, typestore.serialize_ros1)
    return path


def write_ros2_bag(
    path: str | Path,
    frames: Sequence[np.ndarray],
    stamps: Sequence[float],
    *,
    storage: str = "sqlite3",
    topic: str = "/camera/image_raw",
    compressed: bool = False,
    encoding: str = "rgb8",
    poses: Optional[Poses] = None,
    pose_topic: str = "/odom",
    pose_type: str = "odometry",
    image_format: str = "jpeg",
    jpeg_quality: int = 95,
) -> Path:
    """Write a ROS2 bag directory (storage "sqlite3" or "mcap"), format version 9.

    Options as for ``write_ros1_bag``.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    plugins = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
    if storage not in plugins:
        raise InputError(f"unknown ROS2 storage {storage!r} (use 'sqlite3' or 'mcap')")
    path = Path(path)
    _check_lengths(frames, stamps)
    _remove(path)
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    messages = _messages(typestore, frames, stamps, topic, compressed, encoding,
                         poses, pose_topic, pose_type, image_format, jpeg_quality, ros1=False)
    with Writer(path, version=9, storage_plugin=plugins[storage]) as writer:
        _write_messages(writer, typestore, messages, typestore.serialize_cdr)
    return path


# --- helpers -----------------------------------------------------------------


def _write_messages(writer: Any, typestore: Any, messages, serialize) -> None:
    """Write (t_ns, topic, msg) in order, one connection per topic (ROS1 and ROS2 writers alike)."""
    connections: dict[str, Any] = {}
    for t_ns, topic_name, msg in messages:
        if topic_name not in connections:
            connections[topic_name] = writer.add_connection(topic_name, msg.__msgtype__, typestore=typestore)
        writer.write(connections[topic_name], t_ns, serialize(msg, msg.__msgtype__))


def _check_lengths(frames: Sequence[np.ndarray], stamps: Sequence[float]) -> None:
    if len(frames) != len(stamps):
        raise InputError(f"{len(frames)} frames but {len(stamps)} stamps")


def _check_rgb(rgb: np.ndarray, hw: tuple[int, int], where: Path) -> None:
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[:2] != hw or rgb.shape[2] != 3:
        raise InputError(f"{where}: every frame must be {hw[1]}x{hw[0]} RGB uint8, got "
                         f"{rgb.shape} {rgb.dtype}")


def _remove(path: Path) -> None:
    """Writers refuse to overwrite; the caller asked for this path, so replace it."""
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()
    path.parent.mkdir(parents=True, exist_ok=True)


def _split_ns(stamp: float) -> tuple[int, int, int]:
    """(total ns, sec, nanosec) of a stamp in seconds, rounded to the nanosecond."""
    total = int(round(float(stamp) * 1e9))
    return total, total // 1_000_000_000, total % 1_000_000_000


def _header(typestore: Any, stamp: float, frame_id: str, ros1: bool) -> Any:
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    _, sec, nsec = _split_ns(stamp)
    if ros1:
        return Header(seq=0, stamp=Time(sec=sec, nanosec=nsec), frame_id=frame_id)
    return Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame_id)


def _raw_image_payload(rgb: np.ndarray, encoding: str) -> tuple[np.ndarray, int]:
    """Pixel bytes (flattened uint8) and row step for ``encoding`` made from an RGB frame."""
    if encoding == "rgb8":
        data = rgb
    elif encoding == "bgr8":
        data = rgb[:, :, ::-1]
    elif encoding == "mono8":
        data = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    elif encoding == "mono16":
        # 257 maps 0..255 onto the full 0..65535 range.
        data = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype("<u2") * np.uint16(257)
    elif encoding == "bayer_rggb8":
        # R G / G B mosaic sampled from the RGB frame.
        data = np.empty(rgb.shape[:2], dtype=np.uint8)
        data[0::2, 0::2] = rgb[0::2, 0::2, 0]
        data[0::2, 1::2] = rgb[0::2, 1::2, 1]
        data[1::2, 0::2] = rgb[1::2, 0::2, 1]
        data[1::2, 1::2] = rgb[1::2, 1::2, 2]
    else:
        raise InputError(f"cannot write image encoding {encoding!r} "
                         f"(supported: {', '.join(BAG_ENCODINGS)})")
    data = np.ascontiguousarray(data)
    step = data.strides[0]
    return data.view(np.uint8).reshape(-1), step


def _image_msg(typestore: Any, rgb: np.ndarray, header: Any, encoding: str) -> Any:
    Image = typestore.types["sensor_msgs/msg/Image"]
    data, step = _raw_image_payload(rgb, encoding)
    return Image(header=header, height=rgb.shape[0], width=rgb.shape[1], encoding=encoding,
                 is_bigendian=0, step=step, data=data)


def _compressed_msg(typestore: Any, rgb: np.ndarray, header: Any, image_format: str,
                    jpeg_quality: int) -> Any:
    CompressedImage = typestore.types["sensor_msgs/msg/CompressedImage"]
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    if image_format == "jpeg":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
    elif image_format == "png":
        ok, buf = cv2.imencode(".png", bgr)
    else:
        raise InputError(f"unknown compressed image format {image_format!r} (use jpeg or png)")
    if not ok:
        raise InputError(f"OpenCV cannot encode a {image_format} image")
    return CompressedImage(header=header, format=image_format, data=buf.reshape(-1))


def _pose(typestore: Any, x: float, y: float, yaw: float) -> Any:
    t = typestore.types
    quat = t["geometry_msgs/msg/Quaternion"](
        x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))
    return t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0), orientation=quat)


def _pose_stamped_msg(typestore: Any, header: Any, x: float, y: float, yaw: float) -> Any:
    return typestore.types["geometry_msgs/msg/PoseStamped"](
        header=header, pose=_pose(typestore, x, y, yaw))


def _odometry_msg(typestore: Any, header: Any, x: float, y: float, yaw: float) -> Any:
    t = typestore.types
    pose = _pose(typestore, x, y, yaw)
    zero3 = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return t["nav_msgs/msg/Odometry"](
        header=header,
        child_frame_id="base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=pose, covariance=np.zeros(36, dtype=np.float64)),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](linear=zero3, angular=zero3),
            covariance=np.zeros(36, dtype=np.float64)),
    )


def _messages(typestore: Any, frames: Sequence[np.ndarray], stamps: Sequence[float],
              topic: str, compressed: bool, encoding: str, poses: Optional[Poses],
              pose_topic: str, pose_type: str, image_format: str, jpeg_quality: int,
              ros1: bool) -> Iterator[tuple[int, str, Any]]:
    """All messages as (log time ns, topic, message) in log-time order, built lazily
    so that long recordings never sit in memory as messages."""
    if pose_type not in ("odometry", "posestamped"):
        raise InputError(f"unknown pose message type {pose_type!r} (use odometry or posestamped)")
    hw = frames[0].shape[:2] if len(frames) else (0, 0)

    def images() -> Iterator[tuple[int, str, Any]]:
        for rgb, stamp in zip(frames, stamps):
            _check_rgb(rgb, hw, Path(topic))
            header = _header(typestore, stamp, "camera", ros1)
            msg = (_compressed_msg(typestore, rgb, header, image_format, jpeg_quality)
                   if compressed else _image_msg(typestore, rgb, header, encoding))
            yield _split_ns(stamp)[0], topic, msg

    def pose_msgs() -> Iterator[tuple[int, str, Any]]:
        if poses is None:
            return
        yaw = poses.yaw if poses.yaw is not None else np.zeros_like(poses.t)
        make = _odometry_msg if pose_type == "odometry" else _pose_stamped_msg
        for t, x, y, a in zip(poses.t, poses.x, poses.y, yaw):
            header = _header(typestore, t, "map", ros1)
            yield _split_ns(t)[0], pose_topic, make(typestore, header, x, y, a)

    # Both streams are in time order; merge keeps images first at equal times.
    return heapq.merge(images(), pose_msgs(), key=lambda m: m[0])
