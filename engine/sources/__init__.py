"""Recording readers: videos, ROS1/ROS2 bags, image folders; ground-truth poses.

``open_recording`` decides by what the path is:

- a file with a video suffix (.mp4, .avi, .mkv, .mov, ...)  -> VideoSource
- a ``.bag`` file (ROS1), a bare ``.db3`` or ``.mcap`` file  -> BagSource
- a directory with metadata.yaml or a .db3/.mcap file (ROS2) -> BagSource
- any other directory                                       -> FolderSource of images

Frames of another projection than equirectangular (``projection.py``) are converted as
they are read: a dual-fisheye or GoPro EAC video by ``Video360Source`` (detected from the
container: stream count and sizes, ``.insv``), anything else given ``projection`` (a bag of
side-by-side fisheyes) by the ``ProjectedSource`` wrapper.

``recording_poses`` gives the positions a recording carries itself: the EXIF GPS fixes of a
photo folder (``folder.py``), the GPMF GPS track of a GoPro video (``gpmf.py``), as
``engine.poses.Poses`` on its stamps; ``recording_headings`` the camera's own heading
(GPMF CORI) at given stamps.
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
from .projected import ProjectedSource
from .projection import detect_projection, looks_like_dual_fisheye, parse_projection
from .video import VIDEO_SUFFIXES, VideoSource
from .video_360 import Video360Source

__all__ = [
    "BagSource",
    "FolderSource",
    "VideoSource",
    "list_image_topics",
    "list_pose_topics",
    "open_recording",
    "recording_headings",
    "recording_poses",
    "read_poses",
]


def open_recording(path: Path, topic: Optional[str] = None, interval: float = 1.0,
                   projection: Optional[str] = None, keyframes_only: bool = False,
                   skip_bad_frames: bool = False) -> FrameSource:
    """Open any supported recording; InputError with a one-line reason otherwise.

    ``topic`` chooses the image topic of a bag (needed when it has several);
    ``interval`` is the spacing of a folder's frames when it has no stamps.csv;
    ``projection`` is the ``--projection`` option (``projection.parse_projection``; None: what
    the file says, else equirectangular); ``keyframes_only`` samples a video at its key frames
    only; ``skip_bad_frames`` lets a video cut short be read as far as it goes.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file or directory")
    given = parse_projection(projection)
    suffix = path.suffix.lower()
    if suffix == ".zstd" and Path(path.stem).suffix.lower() in (".db3", ".mcap"):
        # ros2 bag record --compression-mode file: only the bag's metadata.yaml says so
        raise InputError(f"{path}: a ROS2 storage file compressed whole; open the bag directory "
                         f"with its metadata.yaml, or decompress it first with 'zstd -d {path}'")
    is_bag = is_ros2_bag_dir(path) if path.is_dir() else suffix in (".bag", ".db3", ".mcap")
    is_video = not is_bag and not path.is_dir() and suffix in VIDEO_SUFFIXES
    if keyframes_only and not is_video:
        raise InputError(f"{path}: only videos have key frames; use a sampling interval in seconds")
    if topic and not is_bag:  # a silently ignored topic would hide a mistyped input path
        raise InputError(f"{path}: a topic ({topic}) was given, but only ROS bags have topics")
    if is_video:
        found = detect_projection(path, given)
        if found.converts:
            return Video360Source(path, found, keyframes_only=keyframes_only, allow_truncated=skip_bad_frames)
        try:
            video = VideoSource(path, keyframes_only=keyframes_only, allow_truncated=skip_bad_frames)
        except InputError as err:
            if "not an equirectangular" not in str(err):
                raise
            raise InputError(f"{err}; if it is a 360 camera's own layout, name it with --projection "
                             f"(dual-fisheye or eac)") from None
        return _not_fisheyes(video, path, given)
    if is_bag:
        source: FrameSource = BagSource(path, topic)
    elif path.is_dir():
        source = FolderSource(path, interval=interval)
    else:
        raise InputError(
            f"{path}: unsupported file type {suffix or '(none)'!r}; expected a video, "
            f"a ROS1 .bag, a ROS2 bag (directory, .db3 or .mcap) or a folder of images")
    if given is not None and given.converts:
        try:
            return ProjectedSource(source, given)
        except InputError:
            source.close()
            raise
    return _not_fisheyes(source, path, given)


def _not_fisheyes(source: FrameSource, path: Path, given) -> FrameSource:
    """``source``, unless nothing said what its frames are and the first one is two fisheye
    images side by side (``projection.looks_like_dual_fisheye``): mapped as a panorama it would
    be a wrong picture, so it is refused with the option that says what it is."""
    if given is not None:
        return source
    try:
        first = source.frame_at(0).rgb if source.frame_count else None
    except (InputError, IndexError):
        return source   # the reader reports its own damage when the frame is read for real
    if first is not None and looks_like_dual_fisheye(first):
        source.close()
        raise InputError(f"{path}: its frames look like two fisheye images side by side (black corners "
                         f"around two image circles), not an equirectangular panorama; say which with "
                         f"--projection dual-fisheye (or --projection equirect)")
    return source


def recording_poses(path: Path, interval: float = 1.0) -> tuple[Optional[Poses], list[str]]:
    """(positions, warnings) a recording carries itself: the EXIF GPS of a photo folder with a
    fix on every photo, the GPMF GPS track of a GoPro video (``gpmf.gps_poses``: good fixes
    only); (None, []) for any other recording. Reads tags and telemetry only, no pixels."""
    path = Path(path)
    if path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES:
        from . import gpmf

        telemetry = gpmf.read_telemetry(path)
        return gpmf.gps_poses(telemetry) if telemetry is not None else (None, [])
    if not path.is_dir() or is_ros2_bag_dir(path):
        return None, []
    layout = folder_layout(path, interval=interval)
    return layout.poses, layout.warnings


def recording_headings(path: Path, stamps) -> Optional["np.ndarray"]:
    """The camera's own yaw (radians about its z axis, relative to its orientation at the
    start) at ``stamps`` (seconds on the recording's clock): the raw GPMF CORI track of a
    GoPro video; None for recordings without one. The panorama shift does not read this:
    it uses ``FrameSource.headings()``, which for videos gives this track only where the
    pictures confirm it and its sign (``camera_heading.checked_headings``)."""
    path = Path(path)
    if not (path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES):
        return None
    from . import gpmf

    telemetry = gpmf.read_telemetry(path)
    return None if telemetry is None else gpmf.headings_at(telemetry, stamps)


def open_source(path: str | Path, topic: Optional[str] = None, interval: float = 1.0,
                projection: Optional[str] = None, keyframes_only: bool = False,
                skip_bad_frames: bool = False) -> FrameSource:
    """Open any supported recording; raises InputError with a clear reason.

    ``interval`` spaces the stamps of an image folder that has no stamps.csv; ``projection``,
    ``keyframes_only`` and ``skip_bad_frames``: see ``engine.sources.open_recording``.
    """
    return open_recording(Path(path), topic=topic, interval=interval, projection=projection,
                          keyframes_only=keyframes_only, skip_bad_frames=skip_bad_frames)
