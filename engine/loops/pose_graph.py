"""Stage 7 of ``verified``: consistency as one robust pose graph (GTSAM, graduated non-convexity).

Every node has a planar pose (x, y in node steps, heading). Consecutive nodes are joined by
step factors from their two-view fit (``geometry.Steps``: the turn, the direction of motion,
one node step long, each with its uncertainty); loops by loop factors (b where the two views
measured it: the measured distance along the two-view direction, or on a where the views did
not measure a distance; within ``loop_sigma_steps``; the two-view yaw). A loop factor of no
translation between views a metre apart would pull a route and its return beside it onto one
line, and the solved map would then put their other nodes together too. The loops are robust:
GTSAM's ``GncLMOptimizer`` with a truncated least-squares cost rejects the loops the path and
the other loops cannot hold (as Kimera-RPGO does). A step that turns more than a quarter turn
is ``ambiguous`` (a corridor alike both ways reads a straight step as a half turn): its
measured factor is robust too, so the loops across it can outvote it, and a weak factor
(one step, any turn) keeps the chain joined.

Only the nodes the loops touch matter to the solution: the steps between two of them are
composed into one factor with its propagated covariance, so 100,000 nodes cost what their
loops cost. The other nodes' poses are then read off the path, the mismatch at each key node
spread along the stretch. Several recordings are several chains joined only by loops. Where
the recording has odometry or GPS (``engine.metric_factors``) the graph is solved in metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional, Sequence

import numpy as np

from .. import metric_factors
from ..metric_factors import StepFactors
from ..params import MapParams
from ..planar import apply, compose, dead_reckoning, relative
from .pairs import Steps, recording_of

if TYPE_CHECKING:
    from ..metric import Metric

# A turn or position this uncertain says nothing (a weak factor): the chain stays joined.
_FREE_TURN = 1e3
_FREE_STEP = 1e3
# A direction of motion this far from the way the camera moved reads backwards: halfway
# between the two signs two views leave open (0 and 180 degrees), not a tuned number.
_BACKWARDS_DEG = 90.0
# A recording has a usual direction of motion in its camera's frame when its steps' mean
# direction vector is at least this long: 1 - 2p with a share p of steps read backwards and
# the rest one way, so at most a quarter of them misread. A camera that keeps its heading
# while the vehicle turns (a gimbal, a 360 camera's direction lock) moves every way in its
# own frame over a route: near 0, and no step is judged by it.
_USUAL_LENGTH = 0.5
# Solver effort per graduated step: each starts from the last solution, which is close, so a
# looser tolerance and fewer iterations than GTSAM's defaults (1e-5, 100) suffice; with the
# defaults Levenberg-Marquardt took 45 iterations per solve (20,000 nodes, 800 loops: 23 s).
_BASE_ITERATIONS = 15
_RELATIVE_TOL = 1e-3


@dataclass
class Loops:
    """Loop factors: node pairs with the relative heading of b to a (degrees, NaN unknown) and
    where b lies in a's frame (node steps; None or NaN: on a)."""

    a: np.ndarray
    b: np.ndarray
    yaw: np.ndarray
    offset: Optional[np.ndarray] = None   # (n, 2) b's position in a's frame, node steps (None: 0)


@dataclass
class Solution:
    """The robust solution: every node's pose and what it kept."""

    poses: np.ndarray           # (m, 3) x, y (node steps), heading (degrees)
    kept: np.ndarray            # bool per loop: the solution holds it
    outvoted_steps: np.ndarray  # indices i of ambiguous steps (i, i + 1) the loops outvoted
    hops: object = None         # callable (a, b) -> node steps along the solved graph
    unit: float = 1.0           # length of poses' x, y per node step: 1, or metres (metric factors)


def step_factors(steps: Steps, chain_starts: Sequence[int], params: MapParams,
                 metric: Optional["Metric"] = None) -> StepFactors:
    """The step factors (also the g2o export's): each step's turn and direction of motion, one
    node step long (none where the camera stood still). A step without a direction of motion
    keeps the direction of the step before it (a robot keeps moving the way it moved) with a
    step's worth of uncertainty. With ``metric``: in metres (``metric_factors.in_metres``).
    A step read moving backwards (``backwards``) has no direction of motion either."""
    starts = np.unique(np.concatenate([[0], np.asarray(chain_starts, np.int64)]))
    n = steps.yaw.size
    motion = np.where(backwards(steps, starts), np.nan, steps.motion)
    known = np.isfinite(motion)
    idx = np.arange(n)
    into_new = np.zeros(n, bool)
    into_new[starts[(starts > 0) & (starts <= n)] - 1] = True   # a step into a new chain
    last = np.maximum.accumulate(np.where(known | into_new, idx, -1))
    carried = np.where(last >= 0, motion[np.maximum(last, 0)], np.nan)
    rad = np.radians(np.where(np.isfinite(carried), carried, 0.0))
    length = np.where(steps.still, 0.0, 1.0)
    f = StepFactors(dx=length * np.cos(rad), dy=length * np.sin(rad),
                    dt=np.radians(np.nan_to_num(steps.yaw, nan=0.0)),
                    sigma_xy=np.where(known, params.step_sigma_steps, 1.0),
                    sigma_t=np.where(np.isfinite(steps.yaw), np.radians(params.step_turn_sigma_deg), _FREE_TURN),
                    ambiguous=np.asarray(steps.ambiguous, bool).copy(), weak=np.ones(n))
    if metric is not None and not metric.empty:
        f = metric_factors.in_metres(f, metric, starts, params)
    f.ambiguous[starts[starts > 0] - 1] = False                  # no factor between chains
    return f


def backwards(steps: Steps, chain_starts: Sequence[int]) -> np.ndarray:
    """(n,) bool: the steps whose direction of motion, in the camera's own frame, points more
    than a quarter turn from the way its recording mostly moves (the mean direction of its
    moving steps).

    Two views give the direction of motion up to its sign, and cheirality (points in front of
    both cameras) picks the sign: in a dim scene or a corridor of far points either sign
    fits. A camera fixed to a vehicle moves the same way in its own frame all along (half the
    turn off it in a turn), so a step read the other way is the sign misread, and a step
    factor sure of it folds the path. The over-exposed third day of the first family's loop
    route read three steps in a row backwards; the path folded and the map closed two places
    3.9 m apart (docs/history.md, round 34). Such a step keeps the direction before it with a
    step's worth of uncertainty, like a step with no reading. A vehicle that really backs up
    is then mapped as uncertain there, not folded with confidence. Still and ambiguous steps
    are left as they are, and so is a recording with no usual direction (``_USUAL_LENGTH``)."""
    n = steps.yaw.size
    out = np.zeros(n, bool)
    moving = np.isfinite(steps.motion) & ~np.asarray(steps.still, bool) & ~np.asarray(steps.ambiguous, bool)
    bounds = np.unique(np.concatenate([[0], np.asarray(chain_starts, np.int64), [n + 1]]))
    for first, end in zip(bounds[:-1], bounds[1:]):
        rows = np.flatnonzero(moving[first:min(end - 1, n)]) + first   # the step into the next chain is unused
        if rows.size == 0:
            continue
        mean = np.exp(1j * np.radians(steps.motion[rows])).mean()
        if np.abs(mean) < _USUAL_LENGTH:   # no usual direction: a camera that keeps its heading
            continue
        off = np.abs(np.angle(np.exp(1j * np.radians(steps.motion[rows])) / mean))
        out[rows] = off > np.radians(_BACKWARDS_DEG)
    return out


def solve(m: int, steps: Steps, loops: Loops, params: MapParams,
          chain_starts: Sequence[int] = (0,), extra_keys: Sequence[int] = (),
          metric: Optional["Metric"] = None) -> Solution:
    """Stage 7: the robust pose graph of ``m`` nodes (chains starting at ``chain_starts``;
    ``steps`` has one entry per consecutive node pair, those across chains unused), with
    ``loops`` robust. ``extra_keys``: nodes whose distances along the solved graph will be
    asked (``Solution.hops``). ``metric``: the nodes' odometry and GPS, or None: image-only,
    in node steps."""
    import gtsam

    chain_starts = np.unique(np.concatenate([[0], np.asarray(chain_starts, np.int64)]))
    metric = None if metric is None or metric.empty else metric
    f = step_factors(steps, chain_starts, params, metric)
    dx, dy, dt, sxy, st, amb = f.dx, f.dy, f.dt, f.sigma_xy, f.sigma_t, f.ambiguous
    chain_of = recording_of(m, chain_starts)
    keys = np.unique(np.concatenate([chain_starts, chain_starts[1:] - 1, [m - 1], loops.a, loops.b,
                                     np.flatnonzero(amb), np.flatnonzero(amb) + 1,
                                     np.asarray(extra_keys, np.int64)])).astype(np.int64)
    dr = dead_reckoning(dx, dy, dt, m, chain_starts)
    start, has_gps = dr, np.zeros(chain_starts.size, bool)
    if metric is not None:   # GPS key nodes; the path moved onto the fixes
        keys, dr, start, has_gps = metric_factors.keys_and_start(metric, keys, dr, f, chain_starts, params)

    graph, initial = gtsam.NonlinearFactorGraph(), gtsam.Values()
    inliers: list[int] = []
    robust_steps: dict[int, int] = {}

    def add(factor, known: bool) -> int:
        graph.add(factor)
        if known:
            inliers.append(graph.size() - 1)
        return graph.size() - 1

    def pose(p) -> "gtsam.Pose2":
        return gtsam.Pose2(float(p[0]), float(p[1]), float(p[2]))

    start = _aligned(start, chain_starts, m, loops, has_gps, np.radians(3 * params.loop_turn_sigma_deg))
    for c, first in enumerate(chain_starts):   # each chain a prior; the first fixes the map (unless GPS does)
        sigma = 1e-3 if c == 0 and not has_gps[c] else _FREE_STEP
        add(gtsam.PriorFactorPose2(int(first), pose(start[first]), gtsam.noiseModel.Isotropic.Sigma(3, sigma)), True)
    for k in keys:
        initial.insert(int(k), pose(start[k]))
    segments = []   # (i, j) consecutive keys on one chain, joined by composed steps
    for i, j in zip(keys[:-1], keys[1:]):
        if chain_of[i] != chain_of[j]:
            continue
        segments.append((int(i), int(j)))
        if j - i == 1 and amb[i]:
            noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sxy[i], sxy[i], st[i]]))
            robust_steps[i] = add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(dx[i], dy[i], dt[i]), noise), False)
            loose = gtsam.noiseModel.Isotropic.Sigmas(np.array([f.weak[i], f.weak[i], _FREE_TURN]))
            add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(0.0, 0.0, 0.0), loose), True)
            continue
        rel, cov = compose(dx[i:j], dy[i:j], dt[i:j], sxy[i:j], st[i:j])
        add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(*rel),
                                     gtsam.noiseModel.Gaussian.Covariance(cov + 1e-9 * np.eye(3))), True)
    loop_factors = []
    loop_sigma = params.loop_sigma_steps * f.unit
    offset = np.zeros((loops.a.size, 2)) if loops.offset is None else np.nan_to_num(loops.offset) * f.unit
    for (a, b, yaw), (ox, oy) in zip(zip(loops.a.tolist(), loops.b.tolist(), loops.yaw.tolist()), offset.tolist()):
        turn = np.radians(yaw) if np.isfinite(yaw) else 0.0
        st_loop = np.radians(params.loop_turn_sigma_deg) if np.isfinite(yaw) else _FREE_TURN
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([loop_sigma, loop_sigma, st_loop]))
        loop_factors.append(add(gtsam.BetweenFactorPose2(int(a), int(b), gtsam.Pose2(ox, oy, turn), noise), False))
    for k, xy, sigma in (metric_factors.positions(metric, keys, params) if metric is not None else ()):
        add(gtsam.PoseTranslationPrior2D(k, xy, gtsam.noiseModel.Isotropic.Sigma(2, sigma)), True)   # heading free

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
    solved = np.array([[p.x(), p.y(), p.theta()] for p in map(result.atPose2, keys.tolist())]).reshape(-1, 3)
    poses = _spread(dr, keys, solved, segments)
    kept = weights[np.asarray(loop_factors, np.int64)] > 0.5 if loop_factors else np.zeros(0, bool)
    outvoted = np.asarray(sorted(i for i, k in robust_steps.items() if weights[k] <= 0.5), np.int64)
    hops = _hops(keys, segments, loops, kept)
    poses[:, 2] = np.degrees((poses[:, 2] + np.pi) % (2 * np.pi) - np.pi)
    return Solution(poses=poses, kept=kept, outvoted_steps=outvoted, hops=hops, unit=f.unit)


def _aligned(start: np.ndarray, chain_starts: np.ndarray, m: int, loops: Loops, has_gps: np.ndarray,
             tolerance: float) -> np.ndarray:
    """Where the solver starts: each chain after the first (without GPS) moved rigidly onto the
    chains already placed, by the loops that join them.

    Every chain is dead-reckoned from the origin facing 0, so a second recording that starts
    elsewhere, facing elsewhere, begins wrong by its whole start pose; the robust solver's first
    solve then settles in a wrong turn and rejects every loop across (three days of one world:
    all 147 of them). Each loop with a heading says where the chain should be turned
    (``phi``); the turn most of them agree on within ``tolerance`` (three loop standard
    deviations of heading) wins, their circular mean is the turn, the median of their shifts
    the shift. A start only: the factors are unchanged, and a chain no loop joins stays put."""
    start = start.copy()
    chain_of = recording_of(m, chain_starts)
    placed = np.asarray(has_gps, bool).copy()
    placed[0] = True
    known = np.isfinite(loops.yaw)
    a, b, yaw = loops.a[known], loops.b[known], np.radians(loops.yaw[known])
    moved = True
    while moved and not placed.all():
        moved = False
        for c in np.flatnonzero(~placed).tolist():
            from_a, from_b = placed[chain_of[a]] & (chain_of[b] == c), placed[chain_of[b]] & (chain_of[a] == c)
            p, q = np.concatenate([a[from_a], b[from_b]]), np.concatenate([b[from_a], a[from_b]])
            if p.size == 0:
                continue
            # a loop (a, b, yaw) says heading(b) = heading(a) + yaw; q on chain c, p placed
            phi = start[p, 2] + np.concatenate([yaw[from_a], -yaw[from_b]]) - start[q, 2]
            near = np.abs(np.angle(np.exp(1j * (phi[:, None] - phi[None, :])))) <= tolerance
            agree = near[np.argmax(near.sum(axis=1))]
            turn = float(np.angle(np.exp(1j * phi[agree]).mean()))
            rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
            shift = np.median(start[p[agree], :2] - start[q[agree], :2] @ rot.T, axis=0)
            rows = chain_of == c
            start[rows, :2] = start[rows, :2] @ rot.T + shift
            start[rows, 2] += turn
            placed[c] = moved = True
    return start


def _spread(dr: np.ndarray, keys: np.ndarray, solved: np.ndarray, segments) -> np.ndarray:
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
        path = apply(start, relative(dr[i], dr[mid]))
        end_dr = apply(start, relative(dr[i], dr[j]))
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
