"""The same world on another day: two recordings of one synthetic world (first family).

``day_pair(route, seed)`` returns ``DayPair(day1, day2, poses1, poses2)``. Day 1 is exactly
``make_recording(route, look, seed, ...)`` (byte-identical, so caches of it stay valid). Day 2
drives through the SAME world (same seed: the same walls, textures, floor plan) on another
day, with every knob of ``DayTwo``:

- other light: the whole image ``exposure`` times darker or brighter, a ``white_balance``
  per channel, and the light turned by ``sun_turn`` radians (walls facing it are brighter:
  ``world.wall_shade``);
- other people: ``people`` walkers drawn from another seed (``people_seed``);
- another start and partly the other direction: day 2 starts ``start_frac`` of day 1's path
  length along it, follows day 1's path forward to its end, turns on the spot and drives the
  last ``back_frac`` of the path back the other way (``day_two_path``);
- another line and pace: ``lane`` metres to the right of the direction of travel (so the
  forward and the returning stretch are 2 x lane apart), at ``speed`` m/s.

Both recordings' poses are in ONE world frame (the world's metres), each on its own clock
from 0 s. ``close_pairs`` gives the ground truth of the places they share.

Where the defaults come from: they are choices, not measurements. ``exposure`` 0.65 is a
little more than half a stop darker (an overcast afternoon after a sunny morning); the
second family's camera jumps by up to +-25 % between laps, this is a larger change on
purpose. ``white_balance`` (1.08, 1.0, 0.86): warmer light, twice the second family's
+-6 % per channel. ``sun_turn`` 2.4 rad (about 140 degrees): the light from the other side.
``people`` 4: as the first family's busiest seed (``bench_methods.DISTURBANCES[4]``).
``start_frac`` 0.35 and ``back_frac`` 0.3: a third of day 1 is never driven on day 2, a
third is driven both days in the same direction and about a third the other way (how much
depends on the route's shape). ``lane`` 0.25 m: well inside the 1 m truth, a tenth of the
indoor corridor's 2.5 m width. ``speed`` 0.9 m/s against day 1's 0.8: nodes fall elsewhere.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import NamedTuple, Optional

import numpy as np

from ..errors import InputError
from ..poses import Poses
from ..progress import CancelToken, Progress, check, report
from .recording import Recording, make_recording
from .render import render
from .routes import _BUILDERS, make_route, trajectory_from_waypoints
from .world import LIGHT_ANGLE, make_people, wall_shade


@dataclass(frozen=True)
class DayTwo:
    """How the second day differs from the first (module notes: where each default comes from)."""

    exposure: float = 0.65                       # gain on the whole image
    white_balance: tuple = (1.08, 1.0, 0.86)     # per channel R, G, B
    sun_turn: float = 2.4                        # radians the light direction turns
    people: int = 4                              # walkers on day 2
    people_seed: int = 1000                      # added to the world seed for day 2's walkers
    start_frac: float = 0.35                     # where along day 1's path day 2 starts
    back_frac: float = 0.3                       # how much of the path's end is driven back
    lane: float = 0.25                           # metres right of the direction of travel
    speed: float = 0.9                           # m/s

    def check(self) -> None:
        if not (self.exposure > 0 and all(w > 0 for w in self.white_balance) and len(self.white_balance) == 3):
            raise InputError("exposure and white balance must be positive (three channels)")
        if not (0.0 <= self.start_frac < 1.0 and 0.0 <= self.back_frac < 1.0):
            raise InputError("start_frac and back_frac must lie in [0, 1)")
        if self.people < 0 or self.speed <= 0 or self.lane < 0:
            raise InputError("people and lane must not be negative, speed must be positive")


class DayPair(NamedTuple):
    day1: Recording
    day2: Recording
    poses1: Poses
    poses2: Poses


# ------------------------------------------------------------------ paths (shared with synth2)

def _dedupe(points: np.ndarray) -> np.ndarray:
    keep = np.r_[True, np.hypot(*np.diff(points, axis=0).T) > 1e-6]
    return points[keep]


def cut_path(points, s0: float, s1: float) -> np.ndarray:
    """The part of polyline ``points`` (k, 2) from arc length ``s0`` to ``s1`` (s0 < s1)."""
    pts = _dedupe(np.asarray(points, float))
    seg = np.hypot(*np.diff(pts, axis=0).T)
    cum = np.r_[0.0, np.cumsum(seg)]
    s0, s1 = float(np.clip(s0, 0, cum[-1])), float(np.clip(s1, 0, cum[-1]))
    if not s1 > s0:
        raise ValueError("empty cut")

    def at(s):
        i = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        f = (s - cum[i]) / seg[i]
        return pts[i] + (pts[i + 1] - pts[i]) * f

    inner = pts[(cum > s0) & (cum < s1)]
    return _dedupe(np.vstack([at(s0), inner, at(s1)]))


def offset_path(points, lane: float, reversal_deg: float = 120.0) -> np.ndarray:
    """Polyline ``points`` moved ``lane`` metres to the right of the direction of travel.

    Corners get the mitred point of the two moved lines; a turn sharper than ``reversal_deg``
    (a U-turn) gets both moved end points instead, so the robot steps across the way."""
    pts = _dedupe(np.asarray(points, float))
    if lane == 0 or len(pts) < 2:
        return pts
    d = np.diff(pts, axis=0)
    u = d / np.hypot(*d.T)[:, None]
    right = np.stack([u[:, 1], -u[:, 0]], 1) * lane
    out = [pts[0] + right[0]]
    for i in range(1, len(pts) - 1):
        cos_t = float(np.clip(u[i - 1] @ u[i], -1, 1))
        if np.degrees(np.arccos(cos_t)) > reversal_deg:
            out += [pts[i] + right[i - 1], pts[i] + right[i]]
            continue
        bis = right[i - 1] + right[i]
        n = np.hypot(*bis)
        # The mitre point lies on the bisector, lane / cos(turn / 2) from the corner.
        out.append(pts[i] + bis / n * lane / np.sqrt((1 + cos_t) / 2) if n > 1e-9 else pts[i] + right[i])
    out.append(pts[-1] + right[-1])
    return _dedupe(np.array(out))


def day_two_path(points, start_frac: float, back_frac: float, lane: float) -> tuple[np.ndarray, int]:
    """Day 2's waypoints from day 1's polyline: from ``start_frac`` of its length forward to
    its end, then back along the last ``back_frac`` of it, each leg ``lane`` m to the right of
    travel. Returns (waypoints (k, 2), index of the first waypoint of the return leg)."""
    pts = _dedupe(np.asarray(points, float))
    total = float(np.hypot(*np.diff(pts, axis=0).T).sum())
    fwd = offset_path(cut_path(pts, start_frac * total, total), lane)
    if back_frac <= 0:
        return fwd, len(fwd)
    back = offset_path(cut_path(pts, (1.0 - back_frac) * total, total)[::-1], lane)
    return _dedupe(np.vstack([fwd, back])), len(fwd)


def close_pairs(p1: Poses, p2: Poses, dist_th: float = 1.0) -> np.ndarray:
    """(i, j) index pairs of ``p1`` and ``p2`` samples within ``dist_th`` metres (one frame)."""
    d2 = (p1.x[:, None] - p2.x[None, :]) ** 2 + (p1.y[:, None] - p2.y[None, :]) ** 2
    return np.argwhere(d2 <= dist_th ** 2)


# ------------------------------------------------------------------ the pair

def _poses(tr, n=None) -> Poses:
    n = tr.t.size if n is None else n
    return Poses(t=tr.t[:n].astype(np.float64), x=tr.x[:n].copy(), y=tr.y[:n].copy(), yaw=tr.yaw[:n].copy())


def day_two_trajectory(route: str, look: str = "indoor", day2: DayTwo = DayTwo(), fps: float = 1.0):
    """Day 2's trajectory of ``route`` (routes.Trajectory), its length (m), its waypoints and
    the index of the first waypoint of the return leg."""
    if route not in _BUILDERS:
        raise InputError(f"unknown route {route!r}; choose one of {', '.join(_BUILDERS)}")
    _, wps, _ = _BUILDERS[route](look)
    path, back_at = day_two_path(wps, day2.start_frac, day2.back_frac, day2.lane)
    tr, length = trajectory_from_waypoints(path, day2.speed, fps)
    return tr, length, path, back_at


def poses_pair(route: str = "loop", seed: int = 0, look: str = "indoor", *, fps: float = 1.0,
               speed: float = 0.8, day2: DayTwo = DayTwo()) -> tuple[Poses, Poses]:
    """The ground truth of ``day_pair`` with the same arguments, unrendered (the first family's
    routes do not depend on the seed; it is taken for symmetry with the second family)."""
    day2.check()
    tr2 = day_two_trajectory(route, look, day2, fps)[0]
    _, wps, _ = _BUILDERS[route](look)
    tr1, _ = trajectory_from_waypoints(wps, speed, fps)
    return _poses(tr1), _poses(tr2)


def _expose(frame: np.ndarray, gain: np.ndarray) -> np.ndarray:
    return np.clip(frame.astype(np.float32) * gain + 0.5, 0, 255).astype(np.uint8)


def day_pair(route: str = "loop", seed: int = 0, look: str = "indoor", *, width: int = 256,
             height: int = 128, fps: float = 1.0, speed: float = 0.8, people: int = 0,
             lighting_drift: float = 0.0, noise: float = 0.0, day2: DayTwo = DayTwo(),
             max_frames: Optional[int] = None, progress: Optional[Progress] = None,
             cancel: Optional[CancelToken] = None) -> DayPair:
    """Two recordings of route ``route``'s world for ``seed`` (module notes).

    Day 1's arguments are ``make_recording``'s; ``day2`` says how day 2 differs. The same
    arguments give byte-identical frames. ``max_frames`` keeps the first frames of each day."""
    day2.check()
    if route not in _BUILDERS:
        raise InputError(f"unknown route {route!r}; choose one of {', '.join(_BUILDERS)}")
    rec1 = make_recording(route, look, seed, width=width, height=height, fps=fps, speed=speed,
                          people=people, lighting_drift=lighting_drift, noise=noise,
                          max_frames=max_frames, cancel=cancel)
    r = make_route(route, look, seed, speed=speed, fps=fps, people=0, lighting_drift=lighting_drift,
                   noise=noise)
    world = r.world
    world.people = make_people(world.walk_lines, day2.people, seed + day2.people_seed)
    world.seg_shade = wall_shade(world.seg_a, world.seg_b, look, LIGHT_ANGLE + day2.sun_turn).astype(np.float32)
    tr, length, path, back_at = day_two_trajectory(route, look, day2, fps)
    n = tr.t.size if max_frames is None else min(tr.t.size, int(max_frames))
    gain = (day2.exposure * np.asarray(day2.white_balance, np.float32)).astype(np.float32)
    frames = np.empty((n, height, width, 3), np.uint8)
    for k in range(n):
        check(cancel)
        report(progress, k, n, "rendering day 2")
        frames[k] = _expose(render(world, tr.x[k], tr.y[k], tr.yaw[k], tr.t[k], width, height), gain)
    report(progress, n, n, "rendering day 2")
    poses2 = _poses(tr, n)
    stamps = poses2.t.copy()
    meta = {k: v for k, v in rec1.meta.items() if k != "revisits"}   # day 1's own revisits
    meta.update({"generator": "panotopo.synth.sessions", "day": 2, "day2": asdict(day2),
                 "length_m": length, "speed": day2.speed, "people": day2.people,
                 "waypoints": path.tolist(), "return_from_waypoint": int(back_at)})
    rec2 = Recording(frames=frames, stamps=stamps, poses=poses2, route=route, look=look, seed=seed,
                     fps=float(fps), meta=meta)
    return DayPair(rec1, rec2, rec1.poses, poses2)
