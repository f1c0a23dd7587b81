"""Synthetic recordings: a route rendered frame by frame, and written in every input format."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Optional

import numpy as np

from ..errors import InputError
from ..poses import Poses
from ..progress import CancelToken, Progress, check, report
from .render import render
from .routes import make_route

FORMATS = ("video", "ros1", "ros2-sqlite3", "ros2-mcap", "folder", "poses")


@dataclass
class Recording:
    frames: np.ndarray          # (n, H, W, 3) uint8 equirectangular, W == 2 H
    stamps: np.ndarray          # float64 (n,) seconds from 0
    poses: Poses                # ground truth at the frame stamps (yaw in radians)
    route: str
    look: str
    seed: int
    fps: float
    meta: dict = field(default_factory=dict)   # revisits, length, rendering options

    def __len__(self) -> int:
        return int(self.stamps.size)


def make_recording(route: str = "demo", look: str = "indoor", seed: int = 0, width: int = 512,
                   height: int = 256, fps: float = 5.0, speed: float = 0.8, people: int = 0,
                   lighting_drift: float = 0.0, noise: float = 0.0,
                   max_frames: Optional[int] = None, progress: Optional[Progress] = None,
                   cancel: Optional[CancelToken] = None) -> Recording:
    """Render route ``route`` in ``look``; the same arguments give byte-identical frames.

    ``people``: number of walkers; ``lighting_drift`` 0..1: strength of slow global light
    changes; ``noise``: sensor noise standard deviation as a fraction of full scale (e.g. 0.02);
    ``max_frames``: keep only the first frames (for quick tests).
    """
    if width != 2 * height or height < 8:
        raise InputError(f"panorama size must be 2:1 and at least 16x8, got {width}x{height}")
    if people < 0 or noise < 0 or lighting_drift < 0:
        raise InputError("people, noise and lighting_drift must not be negative")
    r = make_route(route, look, seed, speed=speed, fps=fps, people=people,
                   lighting_drift=lighting_drift, noise=noise)
    tr = r.trajectory
    n = tr.t.size if max_frames is None else min(tr.t.size, int(max_frames))
    frames = np.empty((n, height, width, 3), np.uint8)
    for k in range(n):
        check(cancel)
        report(progress, k, n, "rendering synthetic frames")
        frames[k] = render(r.world, tr.x[k], tr.y[k], tr.yaw[k], tr.t[k], width, height)
    report(progress, n, n, "rendering synthetic frames")
    stamps = tr.t[:n].astype(np.float64)
    poses = Poses(t=stamps.copy(), x=tr.x[:n].copy(), y=tr.y[:n].copy(), yaw=tr.yaw[:n].copy())
    meta = {
        "generator": "panotopo.synth", "revisits": r.revisits, "length_m": r.length,
        "speed": speed, "people": people, "lighting_drift": lighting_drift, "noise": noise,
        "width": width, "height": height, "camera_height": r.world.camera_height,
        "image_convention": "centre column = heading, columns increase clockwise",
    }
    return Recording(frames=frames, stamps=stamps, poses=poses, route=route, look=look,
                     seed=seed, fps=float(fps), meta=meta)


def write_recording(rec: Recording, out_dir: str | Path,
                    formats: Iterable[str] = FORMATS) -> dict[str, Path]:
    """Write ``rec`` under ``out_dir``; returns {format: path written}.

    video -> <route>.mp4, ros1 -> <route>.bag, ros2-sqlite3 -> <route>_ros2_sqlite3/,
    ros2-mcap -> <route>_ros2_mcap/, folder -> frames/, poses -> poses.csv. The bags carry
    the images on /camera/image_raw and the poses on /odom (nav_msgs/Odometry).
    """
    from . import writers   # written by another module owner; imported only when needed

    formats = tuple(formats)
    unknown = [f for f in formats if f not in FORMATS]
    if unknown:
        raise InputError(f"unknown recording format {unknown[0]!r}; choose from {', '.join(FORMATS)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frames = list(rec.frames)
    stamps = [float(s) for s in rec.stamps]
    name = rec.route
    written: dict[str, Path] = {}
    for fmt in formats:
        if fmt == "video":
            written[fmt] = writers.write_video(out / f"{name}.mp4", frames, rec.fps)
        elif fmt == "ros1":
            written[fmt] = writers.write_ros1_bag(out / f"{name}.bag", frames, stamps, poses=rec.poses)
        elif fmt == "ros2-sqlite3":
            written[fmt] = writers.write_ros2_bag(out / f"{name}_ros2_sqlite3", frames, stamps,
                                                  storage="sqlite3", poses=rec.poses)
        elif fmt == "ros2-mcap":
            written[fmt] = writers.write_ros2_bag(out / f"{name}_ros2_mcap", frames, stamps,
                                                  storage="mcap", poses=rec.poses)
        elif fmt == "folder":
            written[fmt] = writers.write_image_folder(out / "frames", frames, stamps)
        else:
            written[fmt] = writers.write_poses_csv(out / "poses.csv", rec.poses)
    return written
