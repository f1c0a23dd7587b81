"""Drive a robot along waypoints: straight lines, rounded corners, turns on the spot.

A route is a list of waypoints (x, y, lap). Between waypoints the robot drives straight at
``speed``; at a waypoint it rounds the corner on an arc of radius up to ``RADIUS`` when the
turn is at most ``MAX_ARC_TURN`` (a wheeled robot in a street or corridor), and stops and
turns on the spot at ``SPIN_RATE`` for sharper turns (the U-turn of a reverse drive). The
pose is sampled every 1/fps s. ``lap`` of a sample is the lap of the waypoint its leg
started at: the world may change between laps (people, exposure).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RADIUS = 1.5             # m: tight but drivable for a small robot; fits a 3 m corridor
# Sharper turns than this are made on the spot: the arc of a sharper turn would need tangent
# points far back in both streets and cut through the wedge of wall between them.
MAX_ARC_TURN = np.radians(100.0)
SPIN_RATE = np.radians(45.0)   # rad/s on the spot: slow enough to keep frames apart by 45 deg at 1 fps


@dataclass
class Trajectory:
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray      # radians, continuous (unwrapped)
    lap: np.ndarray      # int per sample
    length: float        # metres driven


def _pieces(wp: np.ndarray, laps: np.ndarray):
    """Pieces (kind, lap, data) of the drive through waypoints ``wp`` (k, 2)."""
    d = np.diff(wp, axis=0)
    seg_len = np.hypot(d[:, 0], d[:, 1])
    keep = seg_len > 1e-9
    wp = np.concatenate([wp[:1], wp[1:][keep]])
    laps = np.concatenate([laps[:1], laps[1:][keep]])
    d = np.diff(wp, axis=0)
    seg_len = np.hypot(d[:, 0], d[:, 1])
    u = d / seg_len[:, None]
    heading = np.arctan2(u[:, 1], u[:, 0])
    n = len(u)
    trim_start = np.zeros(n)
    trim_end = np.zeros(n)
    corners = [None] * (n - 1)
    for i in range(n - 1):
        turn = float(np.angle(np.exp(1j * (heading[i + 1] - heading[i]))))
        if abs(turn) < 1e-6:
            continue
        if abs(turn) <= MAX_ARC_TURN:
            tan_half = np.tan(abs(turn) / 2)
            r = min(RADIUS, 0.45 * min(seg_len[i], seg_len[i + 1]) / tan_half)
            t_len = r * tan_half
            trim_end[i] = trim_start[i + 1] = t_len
            corners[i] = ("arc", r, turn)
        else:
            corners[i] = ("spin", 0.0, turn)
    pieces = []
    for i in range(n):
        a = wp[i] + u[i] * trim_start[i]
        b = wp[i + 1] - u[i] * trim_end[i]
        pieces.append(("line", int(laps[i]), (a, b, heading[i])))
        if i < n - 1 and corners[i] is not None:
            kind, r, turn = corners[i]
            lap = int(laps[i + 1])
            if kind == "arc":
                left = np.array([-u[i][1], u[i][0]]) * np.sign(turn)
                centre = b + left * r
                pieces.append(("arc", lap, (centre, r, b - centre, turn, heading[i])))
            else:
                pieces.append(("spin", lap, (wp[i + 1], heading[i], turn)))
    return pieces


def _duration(kind, data, speed):
    if kind == "line":
        a, b, _ = data
        return float(np.hypot(*(b - a))) / speed
    if kind == "arc":
        _, r, _, turn, _ = data
        return r * abs(turn) / speed
    return abs(data[2]) / SPIN_RATE


def _pose(kind, data, f):
    """Pose at fraction ``f`` in [0, 1] of a piece."""
    if kind == "line":
        a, b, h = data
        p = a + (b - a) * f
        return p[0], p[1], h
    if kind == "arc":
        centre, r, rad, turn, h0 = data
        ang = np.arctan2(rad[1], rad[0]) + turn * f
        return centre[0] + r * np.cos(ang), centre[1] + r * np.sin(ang), h0 + turn * f
    p, h0, turn = data
    return p[0], p[1], h0 + turn * f


def drive(waypoints, speed: float, fps: float) -> Trajectory:
    """Sample the drive through ``waypoints`` [(x, y, lap), ...] every 1/fps seconds."""
    arr = np.asarray(waypoints, float)
    pieces = _pieces(arr[:, :2], arr[:, 2].astype(int))
    durations = np.array([_duration(k, d, speed) for k, _, d in pieces])
    ends = np.cumsum(durations)
    total = float(ends[-1])
    t = np.arange(0.0, total + 1e-9, 1.0 / fps)
    starts = ends - durations
    idx = np.clip(np.searchsorted(ends, t, side="right"), 0, len(pieces) - 1)
    xs, ys, hs, laps = (np.empty(t.size) for _ in range(4))
    for k, (ti, i) in enumerate(zip(t, idx)):
        kind, lap, data = pieces[i]
        f = 0.0 if durations[i] <= 0 else min(1.0, (ti - starts[i]) / durations[i])
        xs[k], ys[k], hs[k] = _pose(kind, data, f)
        laps[k] = lap
    length = float(sum(d * speed for (k, _, _), d in zip(pieces, durations) if k != "spin"))
    return Trajectory(t, xs, ys, np.unwrap(hs), laps.astype(int), length)
