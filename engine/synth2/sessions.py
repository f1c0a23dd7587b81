"""The same world on another day: two recordings of one second-family world.

``day_pair(route, seed)`` returns ``DayPair(day1, day2, poses1, poses2)`` as
``engine.synth.sessions.day_pair`` does for the first family, with the same ``DayTwo``
knobs. Day 1 is exactly ``make_recording(route, seed, ...)`` (byte-identical). Day 2 drives
through the same world (same seed: plan, walls, photo tiles, heights) with:

- other light: the camera's exposure times ``exposure`` and its white balance times
  ``white_balance`` for the whole drive (day 1's camera otherwise: same mount, seam, lens;
  its slow exposure drift half a period on), and the sun turned by ``sun_turn`` radians;
- other things: ``people`` people and bins/boxes (the family's own kinds and tiles) beside
  day 2's path, placed from another seed (``people_seed``), moved or gone on the return leg;
- another start, partly the other direction, another line and pace: day 1's waypoints
  through ``engine.synth.sessions.day_two_path`` (from ``start_frac`` of the path to its end,
  back along the last ``back_frac``, ``lane`` m right of travel), at ``speed`` m/s.

Defaults (``DAY_TWO``): the first family's (see ``engine.synth.sessions``), except
``people`` 8, the middle of the 6-10 things the family puts beside a route.
Both recordings' poses are in the world's one frame, each on its own clock from 0 s.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from typing import Optional

import numpy as np

from ..errors import InputError
from ..poses import Poses
from ..progress import CancelToken, Progress, check, report
from ..synth.recording import Recording
from ..synth.sessions import DayPair, DayTwo, day_two_path
from .camera import Camera, apply_camera
from .paths import Trajectory, drive
from .recording import make_recording, poses_for
from .render import render_view
from .routes import ROUTES, RouteSpec, route_spec
from .world import Things, World, build_world

DAY_TWO = DayTwo(people=8)


def _yaw_rate(tr: Trajectory, k: int) -> float:
    a, b = max(k - 1, 0), min(k + 1, tr.t.size - 1)
    return 0.0 if b == a else float((tr.yaw[b] - tr.yaw[a]) / (tr.t[b] - tr.t[a]))


def _things_again(spec: RouteSpec, tr: Trajectory, day1: Things, count: int,
                  rng: np.random.Generator) -> Things:
    """``count`` things 1-2 m beside ``tr``, of day 1's kinds and tiles, moved or gone on later
    laps (as the family's own ``world._things`` places them)."""
    laps = int(tr.lap.max()) + 1
    people = [int(t) for t, p in zip(day1.tile, day1.person) if p]
    boxes = sorted({int(t) for t, p in zip(day1.tile, day1.person) if not p})
    path = np.stack([tr.x, tr.y], 1)
    pos, size, height, tile, person, angle = [], [], [], [], [], []
    tries = 0
    while len(size) < count and tries < 400 and (people or boxes):
        tries += 1
        i = int(rng.integers(len(path)))
        d = path[min(i + 1, len(path) - 1)] - path[max(i - 1, 0)]
        if np.hypot(*d) < 1e-6:
            continue
        nrm = np.array([-d[1], d[0]]) / np.hypot(*d)
        lap_pos = np.full((laps, 2), np.nan)
        for lap in range(laps):
            if lap > 0 and rng.random() < 0.3:
                continue
            p = path[i] + nrm * rng.choice([-1.0, 1.0]) * rng.uniform(1.0, 2.0) + rng.normal(0, 0.6, 2) * (lap > 0)
            if spec.plan.free_at(p[None], 0.4)[0] and np.hypot(*(path - p).T).min() >= 0.7:
                lap_pos[lap] = p
        if np.isnan(lap_pos).all():
            continue
        is_person = bool(people) and (not boxes or rng.random() < 0.6)
        pos.append(lap_pos)
        person.append(is_person)
        size.append(rng.uniform(0.45, 0.6) if is_person else rng.uniform(0.5, 0.9))
        height.append(rng.uniform(1.6, 1.85) if is_person else rng.uniform(0.6, 1.1))
        tile.append(people[0] if is_person else boxes[int(rng.integers(len(boxes)))])
        angle.append(rng.uniform(0, np.pi))
    if not size:
        return Things(np.zeros((laps, 0, 2)), np.zeros(0), np.zeros(0), np.zeros(0, int),
                      np.zeros(0, bool), np.zeros(0))
    return Things(np.stack(pos, 1), np.array(size), np.array(height), np.array(tile),
                  np.array(person), np.array(angle))


def day_two_trajectory(route: str, seed: int = 0, day2: DayTwo = DAY_TWO, fps: float = 1.0):
    """Day 2's trajectory (paths.Trajectory: lap 0 forward, lap 1 the return leg), its
    waypoints and the index of the first waypoint of the return leg."""
    if route not in ROUTES:
        raise InputError(f"unknown synth2 route {route!r}; choose from {', '.join(ROUTES)}")
    spec = route_spec(route, seed)
    path, back_at = day_two_path([w[:2] for w in spec.waypoints], day2.start_frac, day2.back_frac, day2.lane)
    wps = [(x, y, 0 if k < back_at else 1) for k, (x, y) in enumerate(path)]
    return drive(wps, day2.speed, fps), path, back_at


def poses_pair(route: str, seed: int = 0, *, fps: float = 1.0, speed: float = 0.8,
               day2: DayTwo = DAY_TWO) -> tuple[Poses, Poses]:
    """The ground truth of ``day_pair`` with the same arguments, unrendered."""
    day2.check()
    tr, _, _ = day_two_trajectory(route, seed, day2, fps)
    return poses_for(route, seed, fps, speed), Poses(t=tr.t.copy(), x=tr.x.copy(), y=tr.y.copy(), yaw=tr.yaw.copy())


def day_pair(route: str, seed: int = 0, *, width: int = 256, fps: float = 1.0, speed: float = 0.8,
             day2: DayTwo = DAY_TWO, max_frames: Optional[int] = None,
             progress: Optional[Progress] = None, cancel: Optional[CancelToken] = None) -> DayPair:
    """Two recordings of route ``route``'s world for ``seed`` (module notes); the same
    arguments give byte-identical frames. ``max_frames`` keeps the first frames of each day."""
    day2.check()
    if route not in ROUTES:
        raise InputError(f"unknown synth2 route {route!r}; choose from {', '.join(ROUTES)}")
    rec1 = make_recording(route, seed, width=width, fps=fps, speed=speed, max_frames=max_frames,
                          cancel=cancel)
    spec = route_spec(route, seed)
    tr1 = drive(spec.waypoints, speed, fps)
    world: World = build_world(spec, seed, tr1)                   # day 1's world, as rendered
    cam1 = Camera.draw(np.random.default_rng([int(seed), 4]), int(tr1.lap.max()) + 1, world.indoor)

    tr, path, back_at = day_two_trajectory(route, seed, day2, fps)
    rng = np.random.default_rng([int(seed) + day2.people_seed, 41])
    c, s = np.cos(day2.sun_turn), np.sin(day2.sun_turn)
    world2 = replace(world, things=_things_again(spec, tr, world.things, day2.people, rng),
                     sun=np.array([c * world.sun[0] - s * world.sun[1], s * world.sun[0] + c * world.sun[1]]))
    laps = int(tr.lap.max()) + 1
    wb = tuple(float(v) for v in day2.white_balance)
    cam2 = replace(cam1, lap_gain=(cam1.lap_gain[0] * day2.exposure,) * laps,
                   lap_wb=(tuple(a * b for a, b in zip(cam1.lap_wb[0], wb)),) * laps,
                   phase=cam1.phase + np.pi)

    n = tr.t.size if max_frames is None else min(tr.t.size, int(max_frames))
    frames = np.empty((n, width // 2, width, 3), np.uint8)
    for k in range(n):
        check(cancel)
        report(progress, k, n, "rendering day 2")
        view = render_view(world2, tr.x[k], tr.y[k], tr.yaw[k], int(tr.lap[k]), width, cam2.height)
        frames[k] = apply_camera(cam2, view, float(tr.t[k]), int(tr.lap[k]), _yaw_rate(tr, k),
                                 [int(seed), 6, k])
    report(progress, n, n, "rendering day 2")
    stamps = tr.t[:n].astype(np.float64)
    poses2 = Poses(t=stamps.copy(), x=tr.x[:n].copy(), y=tr.y[:n].copy(), yaw=tr.yaw[:n].copy())
    meta = {k: v for k, v in rec1.meta.items() if k not in ("revisits", "lookalikes")}
    meta.update({"generator": "panotopo.synth2.sessions", "day": 2, "day2": asdict(day2),
                 "length_m": tr.length, "speed": day2.speed, "laps": laps,
                 "things": int(world2.things.size.size), "waypoints": path.tolist(),
                 "return_from_waypoint": int(back_at)})
    rec2 = Recording(frames=frames, stamps=stamps, poses=poses2, route=route, look=rec1.look,
                     seed=int(seed), fps=float(fps), meta=meta)
    return DayPair(rec1, rec2, rec1.poses, poses2)
