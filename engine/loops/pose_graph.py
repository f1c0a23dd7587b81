"""Stage 7 of ``verified``: consistency as one robust pose graph (GTSAM, graduated non-convexity).

Every node has a planar pose (x, y in node steps, heading). Consecutive nodes are joined by
step factors from their two-view fit (``geometry.Steps``: the turn, the direction of motion,
one node step long, each with its uncertainty); loops by loop factors (the two views are one
place: no translation beyond ``loop_sigma_steps``, the two-view yaw). The loops are robust:
GTSAM's ``GncLMOptimizer`` with a truncated least-squares cost rejects the loops the path and
the other loops cannot hold (as Kimera-RPGO does). A step that turns more than a quarter turn
is ``ambiguous`` (a corridor alike both ways reads a straight step as a half turn): its
measured factor is robust too, so the loops across it can outvote it, and a weak factor
(one step, any turn) keeps the chain joined.

Only the nodes the loops touch matter to the solution: the steps between two of them are
composed into one factor with its propagated covariance, so 100,000 nodes cost what their
loops cost. The other nodes' poses are then read off the path, the mismatch at each key node
spread along the stretch. Several recordings are several chains joined only by loops.

Metric factors (``engine.metric.Metric``, where the recording has them): the graph is then
solved in metres. Odometry gives the step factors (the relative pose between consecutive
nodes, its sigma ``odom_sigma_rate`` of the step's length and ``odom_turn_sigma_deg`` per
metre); without odometry the image steps are scaled to metres by the GPS distance over the
image path's own (``gps_scale_span_m``). GPS gives position factors (GTSAM's
``PoseTranslationPrior2D``: the translation alone, heading free, with the exact Jacobian; a
Pose2 prior with a huge heading sigma is not that, its error mixes heading into position) at
the key nodes and at least one every ``gps_spacing_m`` metres, sigma from the fix's DOP
(``gps_dop_sigma_m``) or ``gps_sigma_m``. A loop's sigma in metres is ``loop_sigma_steps``
times the median metric step. Without metric data nothing of this runs: the image-only graph
is the one it always was.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional, Sequence

import numpy as np

from ..params import MapParams
from .pairs import Steps

if TYPE_CHECKING:
    from ..metric import Metric

# A turn or position this uncertain says nothing (a weak factor): the chain stays joined.
_FREE_TURN = 1e3
_FREE_STEP = 1e3
# Solver effort per graduated step: each starts from the last solution, which is close, so a
# looser tolerance and fewer iterations than GTSAM's defaults (1e-5, 100) suffice; with the
# defaults Levenberg-Marquardt took 45 iterations per solve (20,000 nodes, 800 loops: 23 s).
_BASE_ITERATIONS = 15
_RELATIVE_TOL = 1e-3
# An odometry step shorter than this (metres) is as uncertain as one this long (a turn on the
# spot or a stop still has noise): odom_sigma_rate and odom_turn_sigma_deg apply to it.
_ODOM_MIN_STEP_M = 0.1
# GPS factors at nodes that are not otherwise key nodes make the graph larger, and every
# graduated step solves it whole: at most this many, or as many as it has other key nodes.
# Measured (20,000 nodes, 800 loop key nodes, 2-core machine): image-only 3.8 s; 2,400 GPS
# key nodes more 12.7 s, 1,200 more 9.7 s, GPS factors on the loop key nodes alone 4.4 s.
_MIN_GPS_KEYS = 2000


@dataclass
class Loops:
    """Loop factors: node pairs with the relative heading of b to a (degrees, NaN unknown)."""

    a: np.ndarray
    b: np.ndarray
    yaw: np.ndarray


@dataclass
class Solution:
    """The robust solution: every node's pose and what it kept."""

    poses: np.ndarray           # (m, 3) x, y (node steps), heading (degrees)
    kept: np.ndarray            # bool per loop: the solution holds it
    outvoted_steps: np.ndarray  # indices i of ambiguous steps (i, i + 1) the loops outvoted
    hops: object = None         # callable (a, b) -> node steps along the solved graph
    unit: float = 1.0           # length of poses' x, y per node step: 1, or metres (metric factors)


def _step_motion(steps: Steps, chain_starts: np.ndarray, params: MapParams):
    """(dx, dy, dtheta, sigma_xy, sigma_theta) of every step in its first node's frame. A step
    without a direction of motion keeps the direction of the step before it (a robot keeps
    moving the way it moved) with a step's worth of uncertainty."""
    n = steps.yaw.size
    motion = steps.motion.copy()
    known = np.isfinite(motion)
    idx = np.arange(n)
    starts = np.zeros(n, bool)
    starts[chain_starts[(chain_starts > 0) & (chain_starts <= n)] - 1] = True   # a step into a new chain
    last = np.maximum.accumulate(np.where(known | starts, idx, -1))
    carried = np.where(last >= 0, motion[np.maximum(last, 0)], np.nan)
    motion = np.where(np.isfinite(carried), carried, 0.0)
    length = np.where(steps.still, 0.0, 1.0)
    rad = np.radians(motion)
    dtheta = np.radians(np.nan_to_num(steps.yaw, nan=0.0))
    sigma_xy = np.where(known, params.step_sigma_steps, 1.0)
    sigma_t = np.where(np.isfinite(steps.yaw), np.radians(params.step_turn_sigma_deg), _FREE_TURN)
    return length * np.cos(rad), length * np.sin(rad), dtheta, sigma_xy, sigma_t


def _compose(dx, dy, dt, sxy, st):
    """One relative pose and its covariance (in the end's frame) for steps applied in order."""
    x = y = th = 0.0
    cov = np.zeros((3, 3))
    for i in range(dx.size):
        c, s = np.cos(dt[i]), np.sin(dt[i])
        # Adjoint of the inverse step: how the pose so far looks from the new end.
        px, py = dx[i], dy[i]
        ad = np.array([[c, s, s * px - c * py], [-s, c, c * px + s * py], [0.0, 0.0, 1.0]])
        cov = ad @ cov @ ad.T + np.diag([sxy[i] ** 2, sxy[i] ** 2, st[i] ** 2])
        ct, sn = np.cos(th), np.sin(th)
        x, y, th = x + ct * px - sn * py, y + sn * px + ct * py, th + dt[i]
    return (x, y, th), cov


def _dead_reckoning(dx, dy, dt, m: int, chain_starts: np.ndarray) -> np.ndarray:
    """(m, 3) poses summed along each chain from its first node (at the origin)."""
    poses = np.zeros((m, 3))
    bounds = list(chain_starts) + [m]
    for s, e in zip(bounds[:-1], bounds[1:]):
        th = np.concatenate([[0.0], np.cumsum(dt[s:e - 1])])
        wx = np.cos(th[:-1]) * dx[s:e - 1] - np.sin(th[:-1]) * dy[s:e - 1]
        wy = np.sin(th[:-1]) * dx[s:e - 1] + np.cos(th[:-1]) * dy[s:e - 1]
        poses[s:e, 0] = np.concatenate([[0.0], np.cumsum(wx)])
        poses[s:e, 1] = np.concatenate([[0.0], np.cumsum(wy)])
        poses[s:e, 2] = th
    return poses


def _relative(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Pose q seen from pose p (rows x, y, theta in radians)."""
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    dx, dy = q[..., 0] - p[..., 0], q[..., 1] - p[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, q[..., 2] - p[..., 2]], axis=-1)


def _apply(p: np.ndarray, rel: np.ndarray) -> np.ndarray:
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    return np.stack([p[..., 0] + c * rel[..., 0] - s * rel[..., 1],
                     p[..., 1] + s * rel[..., 0] + c * rel[..., 1], p[..., 2] + rel[..., 2]], axis=-1)


def solve(m: int, steps: Steps, loops: Loops, params: MapParams,
          chain_starts: Sequence[int] = (0,), extra_keys: Sequence[int] = (),
          metric: Optional["Metric"] = None) -> Solution:
    """Stage 7: the robust pose graph of ``m`` nodes (chains starting at ``chain_starts``;
    ``steps`` has one entry per consecutive node pair, those across chains unused), with
    ``loops`` robust. ``extra_keys``: nodes whose distances along the solved graph will be
    asked (``Solution.hops``). ``metric``: the nodes' odometry and GPS (module notes), or
    None: image-only, in node steps."""
    import gtsam

    chain_starts = np.unique(np.concatenate([[0], np.asarray(chain_starts, np.int64)]))
    metric = None if metric is None or metric.empty else metric
    dx, dy, dt, sxy, st = _step_motion(steps, chain_starts, params)
    amb = np.asarray(steps.ambiguous, bool).copy()
    weak = np.ones(dx.size)       # position sigma of the weak factor beside an ambiguous step
    unit = 1.0
    if metric is not None:
        dx, dy, dt, sxy, st, amb, weak, unit = _metric_steps(dx, dy, dt, sxy, st, amb, metric, chain_starts, params, m)
    cross = chain_starts[chain_starts > 0] - 1                          # steps between chains
    amb[cross] = False
    chain_of = np.searchsorted(chain_starts, np.arange(m), side="right") - 1
    keys = np.unique(np.concatenate([chain_starts, chain_starts[1:] - 1, [m - 1], loops.a, loops.b,
                                     np.flatnonzero(amb), np.flatnonzero(amb) + 1,
                                     np.asarray(extra_keys, np.int64)])).astype(np.int64)
    if metric is not None:
        budget = max(_MIN_GPS_KEYS, keys.size)
        keys = np.union1d(keys, _gps_nodes(metric, dx, dy, chain_starts, params, m, budget)).astype(np.int64)
    dr = _dead_reckoning(dx, dy, dt, m, chain_starts)
    has_gps = np.zeros(chain_starts.size, bool)
    start = dr
    if metric is not None:
        dr, has_gps = _anchored(dr, metric, chain_starts, m)
        start = _initial(dr, metric, chain_starts, params, m)

    graph, initial = gtsam.NonlinearFactorGraph(), gtsam.Values()
    inliers: list[int] = []
    robust_steps: dict[int, int] = {}

    def add(factor, known: bool) -> int:
        graph.add(factor)
        if known:
            inliers.append(graph.size() - 1)
        return graph.size() - 1

    for c, first in enumerate(chain_starts):   # each chain a prior; the first fixes the map (unless GPS does)
        sigma = 1e-3 if c == 0 and not has_gps[c] else _FREE_STEP
        p = start[first]
        add(gtsam.PriorFactorPose2(int(first), gtsam.Pose2(float(p[0]), float(p[1]), float(p[2])),
                                   gtsam.noiseModel.Isotropic.Sigma(3, sigma)), True)
    for k in keys:
        p = start[k]
        initial.insert(int(k), gtsam.Pose2(float(p[0]), float(p[1]), float(p[2])))
    segments = []   # (i, j) consecutive keys on one chain, joined by composed steps
    for i, j in zip(keys[:-1], keys[1:]):
        if chain_of[i] != chain_of[j]:
            continue
        segments.append((int(i), int(j)))
        if j - i == 1 and amb[i]:
            noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sxy[i], sxy[i], st[i]]))
            robust_steps[i] = add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(dx[i], dy[i], dt[i]), noise), False)
            loose = gtsam.noiseModel.Isotropic.Sigmas(np.array([weak[i], weak[i], _FREE_TURN]))
            add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(0.0, 0.0, 0.0), loose), True)
            continue
        rel, cov = _compose(dx[i:j], dy[i:j], dt[i:j], sxy[i:j], st[i:j])
        add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(*rel),
                                     gtsam.noiseModel.Gaussian.Covariance(cov + 1e-9 * np.eye(3))), True)
    loop_factors = []
    loop_sigma = params.loop_sigma_steps * unit
    for a, b, yaw in zip(loops.a.tolist(), loops.b.tolist(), loops.yaw.tolist()):
        turn = np.radians(yaw) if np.isfinite(yaw) else 0.0
        st_loop = np.radians(params.loop_turn_sigma_deg) if np.isfinite(yaw) else _FREE_TURN
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([loop_sigma, loop_sigma, st_loop]))
        loop_factors.append(add(gtsam.BetweenFactorPose2(int(a), int(b), gtsam.Pose2(0.0, 0.0, turn), noise), False))
    if metric is not None and metric.gps is not None:   # position factors, heading free
        sigma_gps = metric.gps_sigma(params.gps_sigma_m, params.gps_dop_sigma_m)
        for k in keys[np.isfinite(metric.gps[keys]).all(axis=1)].tolist():
            add(gtsam.PoseTranslationPrior2D(int(k), np.asarray(metric.gps[k], np.float64),
                                             gtsam.noiseModel.Isotropic.Sigma(2, float(sigma_gps[k]))), True)

    if loop_factors or robust_steps:
        base = gtsam.LevenbergMarquardtParams()
        base.setMaxIterations(_BASE_ITERATIONS)
        base.setRelativeErrorTol(_RELATIVE_TOL)
        gnc = gtsam.GncLMParams(base)
        gnc.setKnownInliers(inliers)
        optimizer = gtsam.GncLMOptimizer(graph, initial, gnc)
        optimizer.setInlierCostThresholdsAtProbability(params.graph_inlier_probability)
        result = optimizer.optimize()
        weights = np.asarray(optimizer.getWeights(), np.float64)
    else:
        result = gtsam.LevenbergMarquardtOptimizer(graph, initial).optimize()
        weights = np.ones(graph.size())
    solved = np.array([[result.atPose2(int(k)).x(), result.atPose2(int(k)).y(), result.atPose2(int(k)).theta()]
                       for k in keys]).reshape(-1, 3)
    poses = _spread(dr, keys, solved, segments, m)
    kept = weights[np.asarray(loop_factors, np.int64)] > 0.5 if loop_factors else np.zeros(0, bool)
    outvoted = np.asarray(sorted(i for i, f in robust_steps.items() if weights[f] <= 0.5), np.int64)
    hops = _hops(keys, segments, loops, kept)
    poses[:, 2] = np.degrees((poses[:, 2] + np.pi) % (2 * np.pi) - np.pi)
    return Solution(poses=poses, kept=kept, outvoted_steps=outvoted, hops=hops, unit=unit)


def _metric_steps(dx, dy, dt, sxy, st, amb, metric: "Metric", chain_starts: np.ndarray, params: MapParams, m: int):
    """The step factors in metres: (dx, dy, dtheta, sigma_xy, sigma_theta, ambiguous, weak
    sigma, metres per node step). Odometry's relative pose where both nodes have it (never
    ambiguous); elsewhere the image step scaled by its metric length (``_gps_scale``, or the
    median odometry step)."""
    n = dx.size
    scale = np.ones(n)
    odo = np.zeros(n, bool)
    if metric.odometry is not None and n:
        o = np.asarray(metric.odometry, np.float64)
        rel = _relative(o[:-1], o[1:])
        rel[:, 2] = (rel[:, 2] + np.pi) % (2 * np.pi) - np.pi
        odo = np.isfinite(rel).all(axis=1)
        odo[chain_starts[chain_starts > 0] - 1] = False
        length = np.hypot(rel[:, 0], rel[:, 1])
        moving = odo & (length >= _ODOM_MIN_STEP_M)
        scale[:] = float(np.median(length[moving])) if moving.any() else _ODOM_MIN_STEP_M
    elif metric.gps is not None:
        scale = _gps_scale(dx, dy, dt, metric.gps, chain_starts, params, m)
    dx, dy, sxy, weak = dx * scale, dy * scale, sxy * scale, scale.copy()
    st, amb = st.copy(), amb.copy()
    if odo.any():
        base = np.maximum(length[odo], _ODOM_MIN_STEP_M)
        dx[odo], dy[odo], dt = rel[odo, 0], rel[odo, 1], np.where(odo, rel[:, 2], dt)
        sxy[odo] = params.odom_sigma_rate * base
        st[odo] = np.radians(params.odom_turn_sigma_deg) * base
        amb[odo] = False
    length = np.hypot(dx, dy)
    moving = length > 0
    unit = float(np.median(length[moving])) if moving.any() else 1.0
    return dx, dy, dt, sxy, st, amb, weak, unit


def _gps_scale(dx, dy, dt, gps: np.ndarray, chain_starts: np.ndarray, params: MapParams, m: int) -> np.ndarray:
    """Metres per node step of every image step. Each chain is cut into stretches of equal node
    steps, as many as make a median GPS distance of ``gps_scale_span_m`` over a stretch (cut
    by node count, not where the fixes happen to lie far enough apart: that picks the noise
    which made them far); each stretch's image path (dead-reckoned in node steps) is fitted to
    its fixes by a similarity (least squares), and its scale is that fit's. A stretch with
    fixes too close together to say, or whose scale is over 3 times off the chain's median,
    takes the median. A chain with fewer than two fixes keeps 1."""
    scale = np.ones(dx.size)
    dr = _dead_reckoning(dx, dy, dt, m, chain_starts)
    have = np.isfinite(gps).all(axis=1)
    bounds = list(chain_starts) + [m]
    for s, e in zip(bounds[:-1], bounds[1:]):
        g = s + np.flatnonzero(have[s:e])
        if g.size < 2:
            continue
        size = _piece_size(g, gps, e - s, params.gps_scale_span_m)
        piece = (np.arange(s, e) - s) // size
        found = np.full(int(piece[-1]) + 1, np.nan)
        for k in range(found.size):
            nodes = np.arange(s + k * size, min(s + (k + 1) * size + 1, e))   # and the next stretch's first
            inside = nodes[have[nodes]]
            value = _similarity_scale(dr[inside, :2], gps[inside])
            found[k] = np.nan if value is None else value
        if not np.isfinite(found).any():
            continue
        mid = float(np.median(found[np.isfinite(found)]))
        found = np.where(np.isfinite(found) & (found <= 3 * mid) & (found >= mid / 3), found, mid)
        scale[s:e - 1] = found[piece[:-1]]
    return scale


def _piece_size(g: np.ndarray, gps: np.ndarray, n: int, span_m: float) -> int:
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


def _rigid(p: np.ndarray, q: np.ndarray):
    """(turn, rotation, shift) of the rigid motion that maps points ``p`` onto ``q`` best."""
    pc, qc = p - p.mean(axis=0), q - q.mean(axis=0)
    turn = float(np.arctan2(np.sum(pc[:, 0] * qc[:, 1] - pc[:, 1] * qc[:, 0]),
                            np.sum(pc[:, 0] * qc[:, 0] + pc[:, 1] * qc[:, 1]))) if p.shape[0] > 1 else 0.0
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    return turn, rot, q.mean(axis=0) - rot @ p.mean(axis=0)


def _similarity_scale(p: np.ndarray, q: np.ndarray) -> Optional[float]:
    """The scale of the similarity that maps points ``p`` onto ``q`` best (least squares in
    ``q``), or None when ``p`` spans less than a node step."""
    if p.shape[0] < 2:
        return None
    pc = (p[:, 0] - p[:, 0].mean()) + 1j * (p[:, 1] - p[:, 1].mean())
    qc = (q[:, 0] - q[:, 0].mean()) + 1j * (q[:, 1] - q[:, 1].mean())
    spread = float(np.sum(np.abs(pc) ** 2))
    if spread < 1.0 or np.ptp(p[:, 0]) ** 2 + np.ptp(p[:, 1]) ** 2 < 1.0:
        return None
    return float(np.abs(np.sum(np.conj(pc) * qc)) / spread)


def _gps_nodes(metric: "Metric", dx, dy, chain_starts: np.ndarray, params: MapParams, m: int,
               budget: int = _MIN_GPS_KEYS) -> np.ndarray:
    """Nodes that get a GPS factor besides the key nodes that have a fix: along each chain the
    first node with a fix in every ``gps_spacing_m`` of metric path, the spacing widened so
    that there are at most about ``budget`` of them."""
    if metric.gps is None:
        return np.zeros(0, np.int64)
    have = np.isfinite(metric.gps).all(axis=1)
    out = []
    bounds = list(chain_starts) + [m]
    length = np.hypot(dx, dy)
    crossing = chain_starts[chain_starts > 0] - 1
    spacing = max(params.gps_spacing_m, (float(length.sum()) - float(length[crossing].sum())) / max(budget, 1))
    for s, e in zip(bounds[:-1], bounds[1:]):
        along = np.concatenate([[0.0], np.cumsum(length[s:e - 1])])
        g = np.flatnonzero(have[s:e])
        if g.size == 0:
            continue
        bins = np.floor(along[g] / spacing)
        first = np.concatenate([[True], bins[1:] != bins[:-1]])
        out.append(s + g[first])
    return np.concatenate(out).astype(np.int64) if out else np.zeros(0, np.int64)


def _anchored(dr: np.ndarray, metric: "Metric", chain_starts: np.ndarray, m: int):
    """(initial poses, chain has GPS): each chain's dead reckoning moved onto its GPS fixes
    (the rotation and translation that fit best) or, without them, onto its odometry's first
    pose; the solution starts there (a pose graph far from the answer in heading may not find it)."""
    dr = dr.copy()
    has_gps = np.zeros(chain_starts.size, bool)
    bounds = list(chain_starts) + [m]
    have = np.isfinite(metric.gps).all(axis=1) if metric.gps is not None else np.zeros(m, bool)
    for c, (s, e) in enumerate(zip(bounds[:-1], bounds[1:])):
        g = s + np.flatnonzero(have[s:e])
        if g.size:
            has_gps[c] = True
            turn, rot, shift = _rigid(dr[g, :2], np.asarray(metric.gps[g], np.float64))
            dr[s:e, :2] = dr[s:e, :2] @ rot.T + shift
            dr[s:e, 2] += turn
        elif metric.odometry is not None and np.isfinite(metric.odometry[s]).all():
            dr[s:e] = _apply(np.asarray(metric.odometry[s], np.float64), dr[s:e])
    return dr, has_gps


def _initial(dr: np.ndarray, metric: "Metric", chain_starts: np.ndarray, params: MapParams, m: int) -> np.ndarray:
    """Where the solver starts: ``dr`` (``_anchored``), each stretch of a chain with GPS
    (``_piece_size``) moved onto its own fixes. Over a long recording the dead reckoning drifts
    far from the fixes (its heading wanders), and a start that far off costs many iterations
    or ends in a wrong minimum; a jump between stretches costs nothing (the steps close it)."""
    if metric.gps is None:
        return dr
    out = dr.copy()
    have = np.isfinite(metric.gps).all(axis=1)
    bounds = list(chain_starts) + [m]
    for s, e in zip(bounds[:-1], bounds[1:]):
        g = s + np.flatnonzero(have[s:e])
        if g.size < 2:
            continue
        size = _piece_size(g, metric.gps, e - s, params.gps_scale_span_m)
        for a in range(s, e, size):
            b = min(a + size, e)
            inside = g[(g >= a) & (g < b)]
            if inside.size < 2 or np.ptp(metric.gps[inside], axis=0).max() < 1.0:
                continue
            turn, rot, shift = _rigid(dr[inside, :2], np.asarray(metric.gps[inside], np.float64))
            out[a:b, :2] = dr[a:b, :2] @ rot.T + shift
            out[a:b, 2] = dr[a:b, 2] + turn
    return out


def _spread(dr: np.ndarray, keys: np.ndarray, solved: np.ndarray, segments, m: int) -> np.ndarray:
    """Every node's pose: from the solved key before it along the dead-reckoned path, the
    mismatch at the key after it spread in proportion to the steps."""
    poses = dr.copy()
    at = {int(k): i for i, k in enumerate(keys.tolist())}
    for k in keys.tolist():
        poses[k] = solved[at[k]]
    for i, j in segments:
        if j - i < 2:
            continue
        mid = np.arange(i + 1, j)
        start = solved[at[i]]
        path = _apply(start, _relative(dr[i], dr[mid]))
        end_dr = _apply(start, _relative(dr[i], dr[j]))
        miss = solved[at[j]] - end_dr
        miss[2] = (miss[2] + np.pi) % (2 * np.pi) - np.pi
        poses[mid] = path + ((mid - i) / (j - i))[:, None] * miss[None, :]
    return poses


def _hops(keys: np.ndarray, segments, loops: Loops, kept: np.ndarray):
    """Node steps between two key nodes along the path and the kept loops (a loop counts one
    step): how far apart the graph lets two nodes drift."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    at = {int(k): i for i, k in enumerate(keys.tolist())}
    rows = [at[i] for i, _ in segments] + [at[int(a)] for a in loops.a[kept]]
    cols = [at[j] for _, j in segments] + [at[int(b)] for b in loops.b[kept]]
    weight = [float(j - i) for i, j in segments] + [1.0] * int(kept.sum())
    n = keys.size
    adjacency = coo_matrix((weight, (rows, cols)), shape=(n, n)).tocsr()

    def hops(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        if a.size == 0:
            return np.zeros(0)
        src = np.unique([at[int(x)] for x in a])
        dist = dijkstra(adjacency, directed=False, indices=src)
        row = {s: r for r, s in enumerate(src.tolist())}
        return np.array([dist[row[at[int(x)]], at[int(y)]] for x, y in zip(a, b)])

    return hops


def step_measurements(steps: Steps, chain_starts: Sequence[int], params: MapParams,
                      metric: Optional["Metric"] = None):
    """The step factors ``solve`` uses, for exports (g2o): (dx, dy, dtheta, sigma_xy,
    sigma_theta), one entry per consecutive node pair (i, i + 1): the relative pose in node
    i's frame (x, y in node steps, or metres with ``metric``; theta in radians) and its
    standard deviations. A pair across ``chain_starts`` (two recordings) is no factor; its
    entry means nothing."""
    starts = np.unique(np.concatenate([[0], np.asarray(chain_starts, np.int64)]))
    motion = _step_motion(steps, starts, params)
    if metric is None or metric.empty:
        return motion
    m = motion[0].size + 1
    return _metric_steps(*motion, np.asarray(steps.ambiguous, bool), metric, starts, params, m)[:5]
