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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..params import MapParams
from .pairs import Steps

# A turn or position this uncertain says nothing (a weak factor): the chain stays joined.
_FREE_TURN = 1e3
_FREE_STEP = 1e3
# Solver effort per graduated step: each starts from the last solution, which is close, so a
# looser tolerance and fewer iterations than GTSAM's defaults (1e-5, 100) suffice; with the
# defaults Levenberg-Marquardt took 45 iterations per solve (20,000 nodes, 800 loops: 23 s).
_BASE_ITERATIONS = 15
_RELATIVE_TOL = 1e-3


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
          chain_starts: Sequence[int] = (0,), extra_keys: Sequence[int] = ()) -> Solution:
    """Stage 7: the robust pose graph of ``m`` nodes (chains starting at ``chain_starts``;
    ``steps`` has one entry per consecutive node pair, those across chains unused), with
    ``loops`` robust. ``extra_keys``: nodes whose distances along the solved graph will be
    asked (``Solution.hops``)."""
    import gtsam

    chain_starts = np.unique(np.concatenate([[0], np.asarray(chain_starts, np.int64)]))
    dx, dy, dt, sxy, st = _step_motion(steps, chain_starts, params)
    amb = np.asarray(steps.ambiguous, bool).copy()
    cross = chain_starts[chain_starts > 0] - 1                          # steps between chains
    amb[cross] = False
    chain_of = np.searchsorted(chain_starts, np.arange(m), side="right") - 1
    keys = np.unique(np.concatenate([chain_starts, chain_starts[1:] - 1, [m - 1], loops.a, loops.b,
                                     np.flatnonzero(amb), np.flatnonzero(amb) + 1,
                                     np.asarray(extra_keys, np.int64)])).astype(np.int64)
    dr = _dead_reckoning(dx, dy, dt, m, chain_starts)

    graph, initial = gtsam.NonlinearFactorGraph(), gtsam.Values()
    inliers: list[int] = []
    robust_steps: dict[int, int] = {}

    def add(factor, known: bool) -> int:
        graph.add(factor)
        if known:
            inliers.append(graph.size() - 1)
        return graph.size() - 1

    for c, start in enumerate(chain_starts):   # each chain a prior; the first fixes the map
        sigma = 1e-3 if c == 0 else _FREE_STEP
        add(gtsam.PriorFactorPose2(int(start), gtsam.Pose2(0.0, 0.0, 0.0),
                                   gtsam.noiseModel.Isotropic.Sigma(3, sigma)), True)
    for k in keys:
        p = dr[k]
        initial.insert(int(k), gtsam.Pose2(float(p[0]), float(p[1]), float(p[2])))
    segments = []   # (i, j) consecutive keys on one chain, joined by composed steps
    for i, j in zip(keys[:-1], keys[1:]):
        if chain_of[i] != chain_of[j]:
            continue
        segments.append((int(i), int(j)))
        if j - i == 1 and amb[i]:
            noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sxy[i], sxy[i], st[i]]))
            robust_steps[i] = add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(dx[i], dy[i], dt[i]), noise), False)
            weak = gtsam.noiseModel.Isotropic.Sigmas(np.array([1.0, 1.0, _FREE_TURN]))
            add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(0.0, 0.0, 0.0), weak), True)
            continue
        rel, cov = _compose(dx[i:j], dy[i:j], dt[i:j], sxy[i:j], st[i:j])
        add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(*rel),
                                     gtsam.noiseModel.Gaussian.Covariance(cov + 1e-9 * np.eye(3))), True)
    loop_factors = []
    for a, b, yaw in zip(loops.a.tolist(), loops.b.tolist(), loops.yaw.tolist()):
        turn = np.radians(yaw) if np.isfinite(yaw) else 0.0
        st_loop = np.radians(params.loop_turn_sigma_deg) if np.isfinite(yaw) else _FREE_TURN
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([params.loop_sigma_steps, params.loop_sigma_steps, st_loop]))
        loop_factors.append(add(gtsam.BetweenFactorPose2(int(a), int(b), gtsam.Pose2(0.0, 0.0, turn), noise), False))

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
    return Solution(poses=poses, kept=kept, outvoted_steps=outvoted, hops=hops)


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


def step_measurements(steps: Steps, chain_starts: Sequence[int], params: MapParams):
    """The step factors ``solve`` uses, for exports (g2o): (dx, dy, dtheta, sigma_xy,
    sigma_theta), one entry per consecutive node pair (i, i + 1): the relative pose in node
    i's frame (x, y in node steps, theta in radians) and its standard deviations. A pair
    across ``chain_starts`` (two recordings) is no factor; its entry means nothing."""
    starts = np.unique(np.concatenate([[0], np.asarray(chain_starts, np.int64)]))
    return _step_motion(steps, starts, params)
