"""Recording readers: videos, ROS1/ROS2 bags, image folders; ground-truth poses.

``open_recording`` decides by what the path is:

- a file with a video suffix (.mp4, .avi, .mkv, .mov, ...)  -> VideoSource
- a ``.bag`` file (ROS1), a bare ``.db3`` or ``.mcap`` file  -> BagSource
- a directory with metadata.yaml or a .db3/.mcap file (ROS2) -> BagSource
- any other directory                                       -> FolderSource of images

``recording_poses`` gives the positions a recording carries itself: today the EXIF
GPS fixes of a photo folder (``folder.py``), as ``engine.poses.Poses`` on its stamps.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

from ..errors import InputError
from ..frames import FrameSource
from ..poses import Poses
from .folder import FolderSource, folder_layout
from .poses import read_poses
from .rosbag import BagSource, is_ros2_bag_dir, list_image_topics, list_pose_topics
from .video import VIDEO_SUFFIXES, VideoSource

__all__ = [
    "BagSource",
    "FolderSource",
    "VideoSource",
    "list_image_topics",
    "list_pose_topics",
    "open_recording",
    "recording_poses",
    "read_poses",
]


def open_recording(path: Path, topic: Optional[str] = None, interval: float = 1.0) -> FrameSource:
    """Open any supported recording; InputError with a one-line reason otherwise.

    ``topic`` chooses the image topic of a bag (needed when it has several);
    ``interval`` is the spacing of a folder's frames when it has no stamps.csv.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file or directory")
    suffix = path.suffix.lower()
    if suffix == ".zstd" and Path(path.stem).suffix.lower() in (".db3", ".mcap"):
        # ros2 bag record --compression-mode file: only the bag's metadata.yaml says so
        raise InputError(f"{path}: a ROS2 storage file compressed whole; open the bag directory "
                         f"with its metadata.yaml, or decompress it first with 'zstd -d {path}'")
    is_bag = is_ros2_bag_dir(path) if path.is_dir() else suffix in (".bag", ".db3", ".mcap")
    if is_bag:
        return BagSource(path, topic)
    if topic:  # a silently ignored topic would hide a mistyped input path
        raise InputError(f"{path}: a topic ({topic}) was given, but only ROS bags have topics")
    if path.is_dir():
        return FolderSource(path, interval=interval)
    if suffix in VIDEO_SUFFIXES:
        return VideoSource(path)
    raise InputError(
        f"{path}: unsupported file type {suffix or '(none)'!r}; expected a video, "
        f"a ROS1 .bag, a ROS2 bag (directory, .db3 or .mcap) or a folder of images"
    )


def recording_poses(path: Path, interval: float = 1.0) -> tuple[Optional[Poses], list[str]]:
    """(positions, warnings) of a photo folder with EXIF GPS on every photo; (None, [])
    for any other recording. Reads tags only, no pixels."""
    path = Path(path)
    if not path.is_dir() or is_ros2_bag_dir(path):
        return None, []
    layout = folder_layout(path, interval=interval)
    return layout.poses, layout.warnings
