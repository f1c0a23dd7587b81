"""The pose graph's factors in metres, from a recording's own odometry and GPS (``engine.metric``).

``engine.loops.pose_graph.solve`` builds its step factors from the two-view fits, in node
steps. Where the recording has metric data, ``in_metres`` turns them into metres: odometry
gives the step factors (the relative pose between consecutive nodes, its sigma
``odom_sigma_rate`` of the step's length and ``odom_turn_sigma_deg`` per metre); without
odometry the image steps are scaled to metres by the GPS distance over the image path's own
(``gps_scale_span_m``). GPS gives position factors (GTSAM's ``PoseTranslationPrior2D``: the
translation alone, heading free; a Pose2 prior with a huge heading sigma is not that, its
error mixes heading into position) at the key nodes and at least one every ``gps_spacing_m``
metres (``gps_nodes``), sigma from the fix's DOP (``gps_dop_sigma_m``) or ``gps_sigma_m``. A
loop's sigma in metres is ``loop_sigma_steps`` times the median metric step. The solver
starts from the dead reckoning moved onto the fixes (``anchored``, ``initial``). Without
metric data nothing of this runs: the image-only graph is the one it always was.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .metric import Metric
from .params import MapParams
from .planar import apply, chains, dead_reckoning, relative, rigid_fit, similarity_scale

# GPS factors at nodes that are not otherwise key nodes make the graph larger, and every
# graduated step solves it whole: at most this many, or as many as it has other key nodes.
# Measured (20,000 nodes, 800 loop key nodes, 2-core machine): image-only 3.8 s; 2,400 GPS
# key nodes more 12.7 s, 1,200 more 9.7 s, GPS factors on the loop key nodes alone 4.4 s.
MIN_GPS_KEYS = 2000


@dataclass
class StepFactors:
    """The pose graph's step factors, one entry per consecutive node pair (i, i + 1): the
    relative pose in node i's frame and its standard deviations. A pair across two
    recordings is no factor; its entry means nothing."""

    dx: np.ndarray
    dy: np.ndarray
    dt: np.ndarray          # radians
    sigma_xy: np.ndarray
    sigma_t: np.ndarray     # radians
    ambiguous: np.ndarray   # bool: robust, the loops may outvote it (a weak factor beside it)
    weak: np.ndarray        # position sigma of that weak factor (one node step)
    unit: float = 1.0       # length of one node step: 1, or the median metric step (metres)


def in_metres(f: StepFactors, metric: Metric, chain_starts: np.ndarray, params: MapParams) -> StepFactors:
    """The step factors in metres: odometry's relative pose where both nodes have it (never
    ambiguous); elsewhere the image step scaled by its metric length (``gps_scale``, or the
    median odometry step)."""
    n = f.dx.size
    scale = np.ones(n)
    odo = np.zeros(n, bool)
    floor = params.odom_min_step_m
    if metric.odometry is not None and n:
        o = np.asarray(metric.odometry, np.float64)
        rel = relative(o[:-1], o[1:])
        rel[:, 2] = (rel[:, 2] + np.pi) % (2 * np.pi) - np.pi
        odo = np.isfinite(rel).all(axis=1)
        odo[chain_starts[chain_starts > 0] - 1] = False
        length = np.hypot(rel[:, 0], rel[:, 1])
        moving = odo & (length >= floor)
        scale[:] = float(np.median(length[moving])) if moving.any() else floor
    elif metric.gps is not None:
        scale = gps_scale(f, metric.gps, chain_starts, params)
    out = replace(f, dx=f.dx * scale, dy=f.dy * scale, sigma_xy=f.sigma_xy * scale, weak=scale.copy(),
                  dt=f.dt.copy(), sigma_t=f.sigma_t.copy(), ambiguous=f.ambiguous.copy())
    if odo.any():
        base = np.maximum(length[odo], floor)
        out.dx[odo], out.dy[odo], out.dt[odo] = rel[odo, 0], rel[odo, 1], rel[odo, 2]
        out.sigma_xy[odo] = params.odom_sigma_rate * base
        out.sigma_t[odo] = np.radians(params.odom_turn_sigma_deg) * base
        out.ambiguous[odo] = False
    out.unit = median_step(out.dx, out.dy)
    return out


def median_step(dx, dy) -> float:
    """The length of one node step: the median of the steps that move (1 where none does)."""
    length = np.hypot(dx, dy)
    return float(np.median(length[length > 0])) if (length > 0).any() else 1.0


def keys_and_start(metric: Metric, keys: np.ndarray, dr: np.ndarray, f: StepFactors, chain_starts: np.ndarray,
                   params: MapParams):
    """(keys, dead reckoning, start, chain has GPS): the pose graph's key nodes with the GPS
    nodes (``gps_nodes``: at most as many as the other keys, or ``MIN_GPS_KEYS``), the dead
    reckoning ``dr`` on the fixes (``anchored``) and where the solver starts (``initial``)."""
    budget = max(MIN_GPS_KEYS, keys.size)
    keys = np.union1d(keys, gps_nodes(metric, f.dx, f.dy, chain_starts, params, dr.shape[0], budget))
    dr, has_gps = anchored(dr, metric, chain_starts)
    return keys.astype(np.int64), dr, initial(dr, metric, chain_starts, params), has_gps


def positions(metric: Metric, keys: np.ndarray, params: MapParams) -> list:
    """(node, (x, y) metres, sigma) of the GPS position factors: every key node with a fix,
    sigma from its DOP (``gps_dop_sigma_m``) or ``gps_sigma_m``."""
    if metric.gps is None:
        return []
    sigma = metric.gps_sigma(params.gps_sigma_m, params.gps_dop_sigma_m)
    return [(int(k), np.asarray(metric.gps[k], np.float64), float(sigma[k]))
            for k in keys[np.isfinite(metric.gps[keys]).all(axis=1)].tolist()]


def gps_scale(f: StepFactors, gps: np.ndarray, chain_starts: np.ndarray, params: MapParams) -> np.ndarray:
    """Metres per node step of every image step. Each chain is cut into stretches of equal node
    steps, as many as make a median GPS distance of ``gps_scale_span_m`` over a stretch (cut
    by node count, not where the fixes happen to lie far enough apart: that picks the noise
    which made them far); each stretch's image path (dead-reckoned in node steps) is fitted to
    its fixes by a similarity (least squares), and its scale is that fit's. A stretch with
    fixes too close together to say, or whose scale is over 3 times off the chain's median,
    takes the median. A chain with fewer than two fixes keeps 1."""
    m = f.dx.size + 1
    scale = np.ones(f.dx.size)
    dr = dead_reckoning(f.dx, f.dy, f.dt, m, chain_starts)
    have = np.isfinite(gps).all(axis=1)
    for s, e in chains(chain_starts, m):
        g = s + np.flatnonzero(have[s:e])
        if g.size < 2:
            continue
        size = piece_size(g, gps, e - s, params.gps_scale_span_m)
        piece = (np.arange(s, e) - s) // size
        found = np.full(int(piece[-1]) + 1, np.nan)
        for k in range(found.size):
            nodes = np.arange(s + k * size, min(s + (k + 1) * size + 1, e))   # and the next stretch's first
            inside = nodes[have[nodes]]
            value = similarity_scale(dr[inside, :2], gps[inside])
            found[k] = np.nan if value is None else value
        if not np.isfinite(found).any():
            continue
        mid = float(np.median(found[np.isfinite(found)]))
        found = np.where(np.isfinite(found) & (found <= 3 * mid) & (found >= mid / 3), found, mid)
        scale[s:e - 1] = found[piece[:-1]]
    return scale


def piece_size(g: np.ndarray, gps: np.ndarray, n: int, span_m: float) -> int:
    """Node steps (a power of two) over which the fixes at nodes ``g`` of an ``n``-node chain
    are ``span_m`` apart in the median."""
    size = 2
    while size < n - 1:
        later = np.searchsorted(g, g + size)
        ok = later < g.size
        if ok.any() and np.median(np.linalg.norm(gps[g[later[ok]]] - gps[g[ok]], axis=1)) >= span_m:
            break
        size *= 2
    return size


def gps_nodes(metric: Metric, dx, dy, chain_starts: np.ndarray, params: MapParams, m: int,
              budget: int = MIN_GPS_KEYS) -> np.ndarray:
    """Nodes that get a GPS factor besides the key nodes that have a fix: along each chain the
    first node with a fix in every ``gps_spacing_m`` of metric path, the spacing widened so
    that there are at most about ``budget`` of them."""
    if metric.gps is None:
        return np.zeros(0, np.int64)
    have = np.isfinite(metric.gps).all(axis=1)
    out = []
    length = np.hypot(dx, dy)
    crossing = chain_starts[chain_starts > 0] - 1
    spacing = max(params.gps_spacing_m, (float(length.sum()) - float(length[crossing].sum())) / max(budget, 1))
    for s, e in chains(chain_starts, m):
        along = np.concatenate([[0.0], np.cumsum(length[s:e - 1])])
        g = np.flatnonzero(have[s:e])
        if g.size == 0:
            continue
        bins = np.floor(along[g] / spacing)
        first = np.concatenate([[True], bins[1:] != bins[:-1]])
        out.append(s + g[first])
    return np.concatenate(out).astype(np.int64) if out else np.zeros(0, np.int64)


def anchored(dr: np.ndarray, metric: Metric, chain_starts: np.ndarray):
    """(poses, chain has GPS): each chain's dead reckoning ``dr`` moved onto its GPS fixes (the
    rotation and translation that fit best) or, without them, onto its odometry's first pose;
    the solution starts there (a pose graph far from the answer in heading may not find it)."""
    dr = dr.copy()
    has_gps = np.zeros(chain_starts.size, bool)
    m = dr.shape[0]
    have = np.isfinite(metric.gps).all(axis=1) if metric.gps is not None else np.zeros(m, bool)
    for c, (s, e) in enumerate(chains(chain_starts, m)):
        g = s + np.flatnonzero(have[s:e])
        if g.size:
            has_gps[c] = True
            turn, rot, shift = rigid_fit(dr[g, :2], np.asarray(metric.gps[g], np.float64))
            dr[s:e, :2] = dr[s:e, :2] @ rot.T + shift
            dr[s:e, 2] += turn
        elif metric.odometry is not None and np.isfinite(metric.odometry[s]).all():
            dr[s:e] = apply(np.asarray(metric.odometry[s], np.float64), dr[s:e])
    return dr, has_gps


def initial(dr: np.ndarray, metric: Metric, chain_starts: np.ndarray, params: MapParams) -> np.ndarray:
    """Where the solver starts: ``dr`` (``anchored``), each stretch of a chain with GPS
    (``piece_size``) moved onto its own fixes. Over a long recording the dead reckoning drifts
    far from the fixes (its heading wanders), and a start that far off costs many iterations
    or ends in a wrong minimum; a jump between stretches costs nothing (the steps close it)."""
    if metric.gps is None:
        return dr
    out = dr.copy()
    have = np.isfinite(metric.gps).all(axis=1)
    for s, e in chains(chain_starts, dr.shape[0]):
        g = s + np.flatnonzero(have[s:e])
        if g.size < 2:
            continue
        size = piece_size(g, metric.gps, e - s, params.gps_scale_span_m)
        for a in range(s, e, size):
            b = min(a + size, e)
            inside = g[(g >= a) & (g < b)]
            if inside.size < 2 or np.ptp(metric.gps[inside], axis=0).max() < 1.0:
                continue
            turn, rot, shift = rigid_fit(dr[inside, :2], np.asarray(metric.gps[inside], np.float64))
            out[a:b, :2] = dr[a:b, :2] @ rot.T + shift
            out[a:b, 2] = dr[a:b, 2] + turn
    return out
