"""Routes with the revisit types of the paper, each a world plus a timed trajectory.

A route is built from waypoints: straight lines at constant speed, corners rounded by arcs
(the heading follows the path smoothly), and turns of ~180 degrees done on the spot (the
paper's robot is a wheelchair base). Every route knows the places it revisits on purpose
(``revisits``), so an evaluation can cross-check its own ground-truth loop finder.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .world import LOOKS, Corridor, World, build_world

TURN_RADIUS = 1.0        # metres, corner fillets
SPIN_RATE = np.radians(60.0)  # rad/s when turning on the spot


@dataclass
class Trajectory:
    t: np.ndarray     # float64 (n,) seconds from 0 at the frame rate
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray   # radians, counter-clockwise from +x, unwrapped


@dataclass
class Route:
    name: str
    look: str
    seed: int
    world: World
    trajectory: Trajectory
    revisits: list[tuple[float, float]]   # places (x, y) the route passes more than once on purpose
    length: float                         # metres driven


def _pieces(waypoints: np.ndarray, radius: float):
    """Lines, arcs and spins along the waypoints: (kind, params, duration at unit speed)."""
    pieces = []
    n = len(waypoints)
    dirs = np.diff(waypoints, axis=0)
    lens = np.hypot(dirs[:, 0], dirs[:, 1])
    if np.any(lens < 1e-9):
        raise ValueError("repeated waypoint")
    units = dirs / lens[:, None]
    start = waypoints[0].astype(float)
    for i in range(1, n - 1):
        u_in, u_out = units[i - 1], units[i]
        turn = np.arctan2(u_in[0] * u_out[1] - u_in[1] * u_out[0], u_in @ u_out)
        corner = waypoints[i]
        if abs(turn) > np.radians(170):              # U-turn: stop and spin on the spot
            pieces.append(("line", (start, corner.astype(float))))
            pieces.append(("spin", (corner.astype(float), np.arctan2(*u_in[::-1]), turn)))
            start = corner.astype(float)
            continue
        d = radius * np.tan(abs(turn) / 2)
        d = min(d, 0.5 * lens[i - 1], 0.5 * lens[i])
        r = d / np.tan(abs(turn) / 2) if abs(turn) > 1e-9 else 0.0
        p_in, p_out = corner - u_in * d, corner + u_out * d
        pieces.append(("line", (start, p_in)))
        if r > 0:
            left = np.array([-u_in[1], u_in[0]]) * np.sign(turn)
            centre = p_in + left * r
            a0 = np.arctan2(*(p_in - centre)[::-1])
            pieces.append(("arc", (centre, r, a0, turn)))
        start = p_out
    pieces.append(("line", (start, waypoints[-1].astype(float))))
    return pieces


def trajectory_from_waypoints(waypoints, speed: float, fps: float,
                              radius: float = TURN_RADIUS) -> tuple[Trajectory, float]:
    """Poses at ``fps`` along the waypoints at ``speed`` m/s; also the path length (m)."""
    waypoints = np.asarray(waypoints, dtype=np.float64)
    pieces = _pieces(waypoints, radius)
    durations, length = [], 0.0
    for kind, p in pieces:
        if kind == "line":
            seg = float(np.hypot(*(p[1] - p[0])))
            durations.append(seg / speed)
            length += seg
        elif kind == "arc":
            seg = abs(p[1] * p[3])
            durations.append(max(seg / speed, abs(p[3]) / SPIN_RATE))   # tight arcs: turn rate cap
            length += seg
        else:
            durations.append(abs(p[2]) / SPIN_RATE)
    ends = np.cumsum(durations)
    t = np.arange(0.0, ends[-1] + 1e-9, 1.0 / fps)
    x, y, yaw = np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
    which = np.minimum(np.searchsorted(ends, t, side="right"), len(pieces) - 1)
    begins = ends - np.asarray(durations)
    for k, (kind, p) in enumerate(pieces):
        m = which == k
        if not m.any():
            continue
        f = np.clip((t[m] - begins[k]) / max(durations[k], 1e-12), 0.0, 1.0)
        if kind == "line":
            a, b = p
            x[m], y[m] = a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f
            yaw[m] = np.arctan2(b[1] - a[1], b[0] - a[0])
        elif kind == "arc":
            centre, r, a0, turn = p
            ang = a0 + turn * f
            x[m], y[m] = centre[0] + r * np.cos(ang), centre[1] + r * np.sin(ang)
            yaw[m] = ang + np.sign(turn) * np.pi / 2
        else:
            pos, yaw0, turn = p
            x[m], y[m] = pos[0], pos[1]
            yaw[m] = yaw0 + turn * f
    return Trajectory(t=t, x=x, y=y, yaw=np.unwrap(yaw)), length


# ------------------------------------------------------------------ the routes

def _along(points, step: float) -> list[tuple[float, float]]:
    """Points every ``step`` metres along a polyline (for revisit lists)."""
    pts = np.asarray(points, float)
    out = []
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(1, int(np.hypot(*(b - a)) // step))
        for k in range(n):
            out.append(tuple(a + (b - a) * k / n))
    out.append(tuple(pts[-1]))
    return [(float(px), float(py)) for px, py in out]


def _scale(look: str) -> float:
    return 1.0 if look == "indoor" else 1.3


def _crossing(look: str):
    L = 15.0 * _scale(look)
    corridors = [Corridor(-L, 0, L, 0), Corridor(0, -L, 0, L), Corridor(L, 0, L, L), Corridor(0, L, L, L)]
    wps = [(-L, 0), (L, 0), (L, L), (0, L), (0, -L)]
    return corridors, wps, [(0.0, 0.0)]


def _reverse(look: str):
    L, M = 30.0 * _scale(look), 12.0 * _scale(look)
    corridors = [Corridor(0, 0, L, 0), Corridor(L, 0, L, M)]
    wps = [(0, 0), (L, 0), (L, M), (L, 0), (0, 0)]
    return corridors, wps, _along([(2, 0), (L, 0), (L, M - 4)], 5.0)   # not at the turn itself


def _offset(look: str):
    L = 40.0 * _scale(look)
    off = 0.8
    corridors = [Corridor(0, 0, L, 0)]
    wps = [(0, -off / 2), (L - 1.5, -off / 2), (L - 1.5, off / 2), (0, off / 2)]
    return corridors, wps, _along([(1, 0), (L - 5, 0)], 5.0)


def _loop(look: str):
    W, H = 16.0 * _scale(look), 10.0 * _scale(look)
    corridors = [Corridor(0, 0, W, 0), Corridor(W, 0, W, H), Corridor(W, H, 0, H), Corridor(0, H, 0, 0)]
    lap = [(W, 0), (W, H), (0, H), (0, 0)]
    wps = [(2, 0)] + lap + lap + [(W - 2, 0)]
    return corridors, wps, _along([(2, 0), (W, 0), (W, H), (0, H), (0, 0), (W - 2, 0)], 4.0)


def _demo(look: str):
    L = 12.0 if look == "indoor" else 14.0   # streets are wider: keep the blocks > 2 m
    corridors = [Corridor(-L, 0, L, 0), Corridor(0, -L, 0, L), Corridor(L, 0, L, L), Corridor(0, L, L, L)]
    wps = [(-L, 0), (L, 0), (L, L), (0, L), (0, -L), (0, -L / 3)]
    revisits = [(0.0, 0.0)] + _along([(0, -L / 3 - 0.5), (0, -L + 4)], 2.0)
    return corridors, wps, revisits


_BUILDERS = {"crossing": _crossing, "reverse": _reverse, "offset": _offset, "loop": _loop, "demo": _demo}
ROUTES = tuple(_BUILDERS)


def make_route(name: str = "demo", look: str = "indoor", seed: int = 0, *, speed: float = 0.8,
               fps: float = 5.0, people: int = 0, lighting_drift: float = 0.0,
               noise: float = 0.0) -> Route:
    """The world and trajectory of route ``name`` (see ``ROUTES``) in ``look`` (see ``LOOKS``)."""
    if name not in _BUILDERS:
        raise InputError(f"unknown route {name!r}; choose one of {', '.join(ROUTES)}")
    if look not in LOOKS:
        raise InputError(f"unknown look {look!r}; choose one of {', '.join(LOOKS)}")
    if not (speed > 0 and fps > 0):
        raise InputError(f"speed and fps must be positive, got speed={speed}, fps={fps}")
    corridors, wps, revisits = _BUILDERS[name](look)
    world = build_world(corridors, look, seed, people=people, lighting_drift=lighting_drift, noise=noise)
    traj, length = trajectory_from_waypoints(wps, speed, fps)
    return Route(name=name, look=look, seed=seed, world=world, trajectory=traj,
                 revisits=[(float(a), float(b)) for a, b in revisits], length=length)


def crossing(seed: int = 0, look: str = "indoor", **kw) -> Route:
    """Two corridors crossing at 90 degrees, passed once eastwards and later southwards."""
    return make_route("crossing", look, seed, **kw)


def reverse(seed: int = 0, look: str = "indoor", **kw) -> Route:
    """An L-shaped corridor driven to its end, turned on the spot and driven back."""
    return make_route("reverse", look, seed, **kw)


def offset(seed: int = 0, look: str = "indoor", **kw) -> Route:
    """Out along a corridor and back on a parallel line 0.8 m to the side."""
    return make_route("offset", look, seed, **kw)


def loop(seed: int = 0, look: str = "indoor", **kw) -> Route:
    """A rectangular loop driven twice in the same direction."""
    return make_route("loop", look, seed, **kw)


def demo(seed: int = 0, look: str = "indoor", **kw) -> Route:
    """A short mixed route (~80 m indoors) with a crossing and a reversed stretch."""
    return make_route("demo", look, seed, **kw)
