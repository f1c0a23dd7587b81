"""The routes of the second world family: each builds its own floor plan and waypoints.

Every route function takes a seeded ``rng`` and returns a ``RouteSpec``: the ``Plan``
(layout), the waypoints (x, y, lap) and the revisit places, each a point the route passes at
least twice (for an offset return: the middle between the two lanes). Seeds vary sizes,
widths, angles and the offset; the shapes are the point of each route:

- ``figure_eight``: two street loops joined at an X crossing (60-120 deg), driven as an 8;
  back at the start the net turning is zero.
- ``block_laps``: three laps around a building block, with a plaza on one side.
- ``offset_return``: two laps around a block, the second 0.5-2 m further out.
- ``reverse``: from a room along a corridor of changing width into rooms at the far end,
  turn on the spot and come back the same way (doors, T-junctions, repeated rooms).
- ``crossing``: two corridors cross at 60-120 deg; the route drives along one, round a
  connector and back through the crossing along the other.
- ``junction``: a 5-way junction (even seeds) or a T-junction (odd seeds) entered from
  different arms, each arm a dead end with a small room to turn in.
- ``lookalike``: one drive along a street that passes two identical facade sections
  (a copied building) and never returns: a correct map has no loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .plan import Plan


@dataclass
class RouteSpec:
    plan: Plan
    waypoints: list          # [(x, y, lap)]
    revisits: list           # [(x, y)]
    path_kind: str = "floor"  # floor texture: "floor" (asphalt/indoor floor) or "path"
    twins: list = field(default_factory=list)   # [((x, y), (x, y))]: look-alike places


def _u(deg: float) -> np.ndarray:
    return np.array([np.cos(np.radians(deg)), np.sin(np.radians(deg))])


def figure_eight(rng: np.random.Generator) -> RouteSpec:
    a = rng.uniform(60.0, 120.0)             # angle between the two diagonal streets
    w = rng.uniform(4.5, 6.0)
    L = rng.uniform(17.0, 20.0)
    t = np.tan(np.radians(a / 2))
    ne, se, nw, sw = (L, L * t), (L, -L * t), (-L, L * t), (-L, -L * t)
    p = Plan("hourglass", indoor=False)
    p.corridor([sw, ne], w).corridor([nw, se], w).corridor([se, ne], w).corridor([sw, nw], w)
    # Small squares at the four corners, so the turns have room.
    for cx, cy in (ne, se, nw, sw):
        p.rect(cx - w * 0.8, cy - w * 0.8, cx + w * 0.8, cy + w * 0.8)
    s = tuple(-6.0 * _u(a / 2))
    end = tuple(8.0 * _u(a / 2))
    wp = [(*s, 0), (0, 0, 0), (*ne, 0), (*se, 0), (0, 0, 1), (*nw, 1), (*sw, 1), (0, 0, 2), (*end, 2)]
    return RouteSpec(p, wp, [(0.0, 0.0), s])


def _block(rng: np.random.Generator, ws: float) -> tuple[Plan, float, float]:
    bx, by = rng.uniform(7.0, 9.0), rng.uniform(5.0, 7.0)
    p = Plan("town", indoor=False)
    p.rect(-bx - ws, -by - ws, bx + ws, by + ws)
    p.rect(-bx, -by, bx, by, free=False)                       # the block
    side = rng.uniform(14.0, 18.0)                             # the plaza on the east side
    p.rect(bx + ws - 0.1, -side / 2, bx + ws + side, side / 2)
    # Two dead-end side streets at odd angles, for variety in the view.
    for corner, ang in (((-bx - ws / 2, by + ws / 2), rng.uniform(110, 150)),
                        ((-bx - ws / 2, -by - ws / 2), rng.uniform(200, 250))):
        c = np.array(corner)
        p.corridor([c, c + 12.0 * _u(ang)], rng.uniform(3.5, 5.0))
    return p, bx, by


def _lap(bx: float, by: float, d: float, lap: int) -> list:
    """One counter-clockwise lap at distance ``d`` from the block, from the south side."""
    X, Y = bx + d, by + d
    return [(0.0, -Y, lap), (X, -Y, lap), (X, Y, lap), (-X, Y, lap), (-X, -Y, lap)]


def block_laps(rng: np.random.Generator) -> RouteSpec:
    ws = rng.uniform(6.0, 8.0)
    p, bx, by = _block(rng, ws)
    d = ws / 2
    wp = _lap(bx, by, d, 0) + _lap(bx, by, d, 1) + _lap(bx, by, d, 2) + [(0.0, -by - d, 2)]
    rv = [(0.0, -by - d), (bx + d, 0.0), (0.0, by + d), (-bx - d, 0.0)]
    return RouteSpec(p, wp, rv)


def offset_return(rng: np.random.Generator) -> RouteSpec:
    ws = rng.uniform(6.5, 8.0)
    p, bx, by = _block(rng, ws)
    off = rng.uniform(0.5, 2.0)
    d0 = ws / 2 - off / 2
    d1 = d0 + off
    wp = _lap(bx, by, d0, 0) + [(3.0, -by - d1, 1)] + _lap(bx, by, d1, 1)[1:] + [(0.0, -by - d1, 1)]
    dm = (d0 + d1) / 2
    rv = [(bx + dm, 0.0), (0.0, by + dm), (-bx - dm, 0.0)]
    return RouteSpec(p, wp, rv)


def reverse(rng: np.random.Generator) -> RouteSpec:
    n = int(rng.integers(10, 12))
    rw = rng.uniform(5.5, 6.5)               # room width along the corridor
    depth = rng.uniform(4.5, 5.5)
    w1, w2 = rng.uniform(1.6, 2.2), rng.uniform(2.4, 3.2)
    length = n * rw
    p = Plan("rooms", indoor=True)
    p.corridor([(0, 0), (length / 2, 0)], w1).corridor([(length / 2, 0), (length, 0)], w2)
    wall = 0.2
    y0 = max(w1, w2) / 2 + wall
    doors = []
    for i in range(n):
        x0 = i * rw + wall / 2
        p.rect(x0, y0, x0 + rw - wall, y0 + depth)
        door = x0 + rng.uniform(1.2, rw - 2.2)
        dw = rng.uniform(1.0, 1.3)
        p.rect(door, -0.1, door + dw, y0 + 0.1)                   # door into the corridor
        doors.append(door + dw / 2)
        if i < n - 1:                                            # door to the next room
            # The last one is where the route turns round: centred on the route's line.
            dy = y0 + (depth / 2 - 0.6 if i == n - 2 else rng.uniform(1.0, depth - 2.0))
            p.rect(x0 + rw - wall - 0.1, dy, x0 + rw + 0.1, dy + 1.2)
    # Rooms 1 and n-3 are the same room (same walls and pictures): a deliberate look-alike.
    for i in (1, n - 3):
        x0 = i * rw
        p.lookalike([(x0, y0 - 0.3), (x0 + rw, y0 - 0.3), (x0 + rw, y0 + depth + 0.3), (x0, y0 + depth + 0.3)],
                    key=int(rng.integers(1 << 30)) if i == 1 else p.zones[-1].key, origin=(x0, y0))
    ry = y0 + depth / 2
    a, b = doors[0], doors[-1]
    out = [(a - 1.0, ry, 0), (a, ry - 1.0, 0), (a, 0.0, 0), (b, 0.0, 0), (b, ry, 0),
           ((n - 1.5) * rw, ry, 0)]
    back = [(x, y, 1) for x, y, _ in out[::-1][1:]]
    rv = [(length / 2, 0.0), (a, 0.0), (b, 0.0), (b, ry)]
    twins = [((1.5 * rw, ry), ((n - 2.5) * rw, ry))]
    return RouteSpec(p, out + back, rv, twins=twins)


def crossing(rng: np.random.Generator) -> RouteSpec:
    th = rng.uniform(60.0, 120.0)
    la, lb = rng.uniform(26.0, 30.0), rng.uniform(26.0, 30.0)
    wa, wb = rng.uniform(1.8, 2.4), rng.uniform(2.2, 3.0)
    ub = _u(th)
    a_end, b_end = np.array([la, 0.0]), lb * ub
    p = Plan("corridors", indoor=True)
    p.corridor([(-la, 0), (0, 0)], wa).corridor([(0, 0), a_end], wa + 0.8)   # width changes at the crossing
    p.corridor([-lb * ub, b_end], wb)
    p.corridor([a_end, b_end], rng.uniform(1.6, 2.0))
    for c in (a_end, b_end, np.array([-la, 0.0]), -lb * ub):
        s = rng.uniform(1.8, 2.4)
        p.rect(c[0] - s, c[1] - s, c[0] + s, c[1] + s)
    start = (-la + 1.0, 0.0)
    end = tuple(-lb * ub + 1.0 * ub)
    wp = [(*start, 0), (*a_end, 0), (*b_end, 1), (0.0, 0.0, 1), (*end, 1)]
    return RouteSpec(p, wp, [(0.0, 0.0)])


def junction(rng: np.random.Generator, seed: int) -> RouteSpec:
    if seed % 2 == 0:
        angles = [72.0 * k + rng.uniform(-12, 12) for k in range(5)]
        order = [0, 2, 4, 1, 3]
    else:
        angles = [0.0 + rng.uniform(-8, 8), 90.0 + rng.uniform(-8, 8), 180.0 + rng.uniform(-8, 8)]
        order = [0, 2, 1, 0]
    p = Plan("junction5" if seed % 2 == 0 else "junction_t", indoor=True)
    ends = []
    for ang in angles:
        ln = rng.uniform(15.0, 18.0) if seed % 2 == 0 else rng.uniform(19.0, 22.0)
        e = ln * _u(ang)
        p.corridor([(0, 0), e], rng.uniform(1.6, 3.0))
        s = rng.uniform(1.8, 2.3)
        p.rect(e[0] - s, e[1] - s, e[0] + s, e[1] + s)
        ends.append(e)
    wp = []
    for k, arm in enumerate(order):
        e = ends[arm]
        if k > 0:
            wp.append((0.0, 0.0, k - 1))
        wp.append((e[0], e[1], k))
    rv = [(0.0, 0.0)] + [tuple(0.5 * ends[a]) for a in order[1:-1]]
    return RouteSpec(p, wp, rv)


def lookalike(rng: np.random.Generator) -> RouteSpec:
    w = rng.uniform(5.0, 6.5)
    section = rng.uniform(12.0, 15.0)
    # Zig-zag street: straight parts at 0 deg, bends of +-20-35 deg between them.
    pts = [np.zeros(2)]
    heads = [0.0, rng.uniform(20, 35), 0.0, -rng.uniform(20, 35), 0.0, rng.uniform(20, 35), 0.0]
    lens = [section + 8.0, 20.0, section + 14.0, 20.0, section + 8.0, 18.0, 16.0]
    for h, ln in zip(heads, lens):
        pts.append(pts[-1] + ln * _u(h))
    p = Plan("street", indoor=False)
    p.corridor(pts, w)
    key = int(rng.integers(1 << 30))
    # The copied building: the straight parts 0 and 4 get the same facades over ``section`` m,
    # each with the same nook (a small square set back on the north side).
    for i in (0, 4):
        o = pts[i] + np.array([3.0, 0.0])
        p.rect(o[0] + 4.0, o[1] + w / 2 - 0.1, o[0] + 8.0, o[1] + w / 2 + 3.0)
        p.lookalike([(o[0], o[1] - w), (o[0] + section, o[1] - w), (o[0] + section, o[1] + w + 4.0),
                     (o[0], o[1] + w + 4.0)], key, tuple(o))
    wp = [(pts[0][0] + 1.0, pts[0][1], 0)] + [(q[0], q[1], 0) for q in pts[1:-1]] + [
        (pts[-1][0] - 1.0, pts[-1][1], 0)]
    twins = [(tuple(pts[0] + (3.0 + section / 2, 0.0)), tuple(pts[4] + (3.0 + section / 2, 0.0)))]
    return RouteSpec(p, wp, [], path_kind="path", twins=twins)


ROUTE_FUNCS = {
    "figure_eight": lambda rng, seed: figure_eight(rng),
    "block_laps": lambda rng, seed: block_laps(rng),
    "offset_return": lambda rng, seed: offset_return(rng),
    "reverse": lambda rng, seed: reverse(rng),
    "crossing": lambda rng, seed: crossing(rng),
    "junction": junction,
    "lookalike": lambda rng, seed: lookalike(rng),
}
ROUTES = tuple(ROUTE_FUNCS)


def route_spec(route: str, seed: int) -> RouteSpec:
    from ..errors import InputError
    if route not in ROUTE_FUNCS:
        raise InputError(f"unknown synth2 route {route!r}; choose from {', '.join(ROUTES)}")
    return ROUTE_FUNCS[route](np.random.default_rng([int(seed), 2]), int(seed))
