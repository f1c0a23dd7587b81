"""Recordings of the second world family, in the first family's ``Recording`` type."""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..errors import InputError
from ..poses import Poses
from ..progress import CancelToken, Progress, check, report
from ..synth.recording import Recording
from .camera import Camera, apply_camera
from .paths import Trajectory, drive
from .render import render_view
from .routes import ROUTES, route_spec
from .world import build_world

IMAGE_CONVENTION = "centre column = heading, columns increase clockwise"


def _check(route: str, fps: float, speed: float) -> None:
    if route not in ROUTES:
        raise InputError(f"unknown synth2 route {route!r}; choose from {', '.join(ROUTES)}")
    if not (fps > 0 and speed > 0):
        raise InputError(f"fps and speed must be positive, got fps={fps}, speed={speed}")


def _trajectory(route: str, seed: int, fps: float, speed: float):
    spec = route_spec(route, seed)
    return spec, drive(spec.waypoints, speed, fps)


def poses_for(route: str, seed: int = 0, fps: float = 1.0, speed: float = 0.8) -> Poses:
    """Ground-truth poses of ``make_recording(route, seed, fps=fps, speed=speed)``, unrendered."""
    _check(route, fps, speed)
    _, tr = _trajectory(route, seed, fps, speed)
    return Poses(t=tr.t.copy(), x=tr.x.copy(), y=tr.y.copy(), yaw=tr.yaw.copy())


def revisits_for(route: str, seed: int = 0) -> list[tuple[float, float]]:
    """The places (x, y) that ``route`` passes at least twice (empty for ``lookalike``)."""
    _check(route, 1.0, 1.0)
    return [tuple(map(float, p)) for p in route_spec(route, seed).revisits]


def _yaw_rate(tr: Trajectory, k: int) -> float:
    a, b = max(k - 1, 0), min(k + 1, tr.t.size - 1)
    return 0.0 if b == a else float((tr.yaw[b] - tr.yaw[a]) / (tr.t[b] - tr.t[a]))


def make_recording(route: str, seed: int = 0, width: int = 256, fps: float = 1.0,
                   speed: float = 0.8, max_frames: Optional[int] = None,
                   progress: Optional[Progress] = None, cancel: Optional[CancelToken] = None,
                   camera: Optional[Camera] = None) -> Recording:
    """Render ``route`` (see ``ROUTES``) for ``seed``; the same arguments give identical frames.

    ``width``: panorama width (height is half); ``max_frames``: keep only the first frames;
    ``camera``: override the seed's camera (e.g. ``Camera.plain()`` for geometry tests).
    """
    _check(route, fps, speed)
    if width < 16 or width % 2:
        raise InputError(f"panorama width must be even and at least 16, got {width}")
    spec, tr = _trajectory(route, seed, fps, speed)
    world = build_world(spec, seed, tr)
    laps = int(tr.lap.max()) + 1
    cam = camera or Camera.draw(np.random.default_rng([int(seed), 4]), laps, world.indoor)
    n = tr.t.size if max_frames is None else min(tr.t.size, int(max_frames))
    frames = np.empty((n, width // 2, width, 3), np.uint8)
    for k in range(n):
        check(cancel)
        report(progress, k, n, "rendering synthetic frames")
        view = render_view(world, tr.x[k], tr.y[k], tr.yaw[k], int(tr.lap[k]), width, cam.height)
        frames[k] = apply_camera(cam, view, float(tr.t[k]), int(tr.lap[k]), _yaw_rate(tr, k),
                                 [int(seed), 5, k])
    report(progress, n, n, "rendering synthetic frames")
    stamps = tr.t[:n].astype(np.float64)
    poses = Poses(t=stamps.copy(), x=tr.x[:n].copy(), y=tr.y[:n].copy(), yaw=tr.yaw[:n].copy())
    meta = {
        "generator": "panotopo.synth2", "layout": world.layout,
        "revisits": revisits_for(route, seed), "length_m": tr.length,
        "lookalikes": [[tuple(map(float, a)), tuple(map(float, b))] for a, b in spec.twins],
        "laps": laps, "speed": speed, "width": width, "height": width // 2,
        "camera_height": cam.height, "tilt_deg": cam.tilt_deg, "roll_deg": cam.roll_deg,
        "jpeg_quality": cam.jpeg_quality, "seam_column": int(round(cam.seam_col * width)),
        "things": int(world.things.size.size), "image_convention": IMAGE_CONVENTION,
    }
    return Recording(frames=frames, stamps=stamps, poses=poses, route=route,
                     look="indoor" if world.indoor else "outdoor", seed=int(seed), fps=float(fps),
                     meta=meta)
