"""The ``verified`` method: loop closure by retrieval, evidence and one robust pose graph.

The stages, in the order ``detect_loops`` runs them; each takes one plain value and gives
the next, and every number it reads is a ``MapParams`` entry (``engine.params.PARAMETERS``):

1. ``retrieve.candidates``   each node's best matches, calibrated            -> Pairs
2. ``retrieve.with_support`` the mean calibrated score along the stretch      -> Pairs
3. ``places.one_per_place``  one pair per place                               -> Pairs (+ set aside)
4. ``geometry.measure``      two-view geometry on the sphere, confidence     -> Pairs (measured)
5. ``tiers.tiers``           auto / candidate / dropped by a table of rules  -> statuses
6. ``tiers.nearest``         a pair not automatic moves to its place's closest views
7. ``pose_graph.solve``      consistency: a robust pose graph of steps, automatic loops and
                             the other pairs whose views measured their offset;
                             the loops it rejects go to the queue with the reason, pairs it
                             closes join them, candidates it puts far apart are dropped
                                                                             -> LoopResult

Expensive results (retrieval, background statistics, two-view fits) live in ``cache``, so a
re-map after a threshold change costs the arithmetic, not the retrieval or the geometry.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from ..params import MapParams
from . import pose_graph
from .geometry import PairGeometry
from .pairs import LoopCandidate, Pairs, Status, recording_of
from .places import one_per_place
from .retrieve import candidates, descriptor_rank, with_support
from .tiers import nearest, tiers


@dataclass
class LoopResult:
    """What ``detect_loops`` finds: the loops (sorted by (a, b)) and, where the pose graph was
    solved, every node's estimated pose (x, y in node steps, or metres with metric data;
    heading in degrees)."""

    loops: list
    poses: Optional[np.ndarray] = None


def detect_loops(vectors: np.ndarray, params: MapParams, *, node_rows: np.ndarray, features=None,
                 columns=None, shifts=None, frame_width: int = 0, cache: Optional[dict] = None,
                 chain_starts: Sequence[int] = (0,), metric=None) -> LoopResult:
    """Stages 1-7 on node descriptors ``vectors`` (m, d). ``node_rows`` are the nodes' rows in
    the recording (features are per row); without ``features`` there is no geometry and no
    pose graph, and automatic loops need score and support. ``chain_starts``: the first node
    of every recording (several recordings are chains joined only by loops). ``metric``: the
    nodes' odometry and GPS (``engine.metric.Metric``), the pose graph then in metres."""
    cache = {} if cache is None else cache
    v = np.asarray(vectors, np.float32)
    m = v.shape[0]
    shifts = np.zeros(m, np.int64) if shifts is None else np.asarray(shifts, np.int64)
    recording = recording_of(m, chain_starts)
    geometry = PairGeometry(features, node_rows, shifts, frame_width, columns, cache, recording)
    if m <= params.neighbor_node_num + 1:   # no pair beyond the temporal window: the path's poses alone
        e = np.zeros(0)
        nothing = Pairs(a=e.astype(np.int64), b=e.astype(np.int64), cosine=e, score=e, yaw=e)
        return LoopResult([], consistent(nothing, e.astype(object), geometry, params, m, chain_starts, metric)[3])
    pairs = with_support(v, recording, candidates(v, recording, params, cache), params, cache)    # 1, 2
    floor = params.candidate_z - params.geometry_margin_z
    pairs = pairs.take((pairs.score >= floor) | (np.nan_to_num(pairs.support, nan=-np.inf) >= floor))
    pairs.confidence = descriptor_rank(pairs)
    owner = one_per_place(pairs, params.place_radius)                                # 3
    kept = owner == np.arange(len(pairs))
    set_aside = (pairs.take(~kept), (np.cumsum(kept) - 1)[owner[~kept]])   # and the kept pair of its place
    pairs = pairs.take(kept)
    pairs = geometry.measure(pairs, params)                                         # 4
    status, rule = tiers(pairs, params, recording=recording)                        # 5
    pairs, status, rule = nearest(pairs, status, rule, set_aside, v, recording, geometry, params, cache)   # 6
    status, reason, closure, poses, rule = consistent(pairs, status, geometry, params, m, chain_starts, metric,
                                                      rule)                                        # 7
    out = [LoopCandidate(a=int(pairs.a[i]), b=int(pairs.b[i]), similarity=float(pairs.cosine[i]), window_count=0,
                         yaw=float(pairs.yaw[i]) if np.isfinite(pairs.yaw[i]) else None,
                         score=float(pairs.score[i]), status=str(status[i]),
                         evidence=_evidence(pairs, i, rule[i], reason[i], closure[i]))
           for i in np.flatnonzero(status != Status.DROPPED.value)]
    out.sort(key=lambda lc: (lc.a, lc.b))
    return LoopResult(out, poses)


def consistent(pairs: Pairs, status: np.ndarray, geometry: PairGeometry, params: MapParams, m: int,
               chain_starts, metric=None, rule: Optional[np.ndarray] = None) -> tuple:
    """Stage 7: (status, reason, closure, poses, rule). The automatic loops and the steps make
    one robust pose graph (``pose_graph.solve``), shaped also by the other pairs whose views
    measured their offset (``_measured_apart``); an automatic loop it rejects becomes a
    candidate with the reason. The solved map is a measurement too (docs/method.md, stage 7):
    a pair not automatic (a candidate, or one stage 5 dropped for its descriptor score) whose
    ends it joins and puts within ``auto_distance_steps``, whose views share
    ``map_closes_share`` of a step's inliers and did not measure them further apart, becomes
    automatic (rule "the map closes it") and the graph is solved again with it. A candidate
    the map puts further apart than ``closure_slack`` + ``closure_rate`` per step of the
    graph between its ends is dropped. ``closure``: the ends' distance in the solved map,
    node steps (NaN without geometry; in metres / the median step with ``metric``)."""
    n = len(pairs)
    reason = np.full(n, "", dtype=object)
    closure = np.full(n, np.nan)
    rule = np.full(n, "", dtype=object) if rule is None else rule.copy()
    steps = geometry.steps(params)
    if steps is None:
        return status, reason, closure, None, rule
    status = status.copy()

    def solve():
        auto = np.flatnonzero(status == Status.AUTO.value)
        seen = _measured_apart(pairs, status)
        rows = np.concatenate([auto, seen])
        loops = pose_graph.Loops(pairs.a[rows], pairs.b[rows], pairs.yaw[rows], _offsets(pairs, rows))
        solution = pose_graph.solve(m, steps, loops, params, chain_starts,
                                    extra_keys=np.concatenate([pairs.a, pairs.b]), metric=metric)
        solution.kept = solution.kept[:auto.size]     # the loops; the other measurements only shape the map
        xy = solution.poses[:, :2]
        return auto, solution, np.linalg.norm(xy[pairs.b] - xy[pairs.a], axis=1) / solution.unit

    auto, solution, closure = solve()
    cand = np.flatnonzero(status != Status.AUTO.value)   # candidates and the pairs stage 5 dropped
    if pairs.inliers is None or pairs.step_inliers is None:   # not measured: nothing to share
        cand = cand[:0]
    shared = (pairs.inliers[cand] > 0) & (pairs.inliers[cand] >= params.map_closes_share * pairs.step_inliers[cand]) \
        if cand.size else np.zeros(0, bool)
    not_far = ~(pairs.distance_steps[cand] > params.auto_distance_steps) if pairs.distance_steps is not None \
        else np.ones(cand.size, bool)
    closes = cand[shared & not_far & (closure[cand] <= params.auto_distance_steps)]
    if closes.size:
        closes = closes[np.isfinite(solution.hops(pairs.a[closes], pairs.b[closes]))]
    if closes.size:
        status[closes], rule[closes] = Status.AUTO.value, "the map closes it"
        auto, solution, closure = solve()
    rejected = auto[~solution.kept]
    status[rejected] = Status.CANDIDATE.value
    rule[np.intersect1d(rejected, closes)] = ""   # the map's own measurement does not stand
    reason[rejected] = "the pose graph rejects it: the path and the other loops disagree"
    cand = np.setdiff1d(np.flatnonzero(status == Status.CANDIDATE.value), rejected)
    if cand.size:
        tolerance = params.closure_slack + params.closure_rate * solution.hops(pairs.a[cand], pairs.b[cand])
        status[cand[closure[cand] > tolerance]] = Status.DROPPED.value
    return status, reason, closure, solution.poses, rule


def _measured_apart(pairs: Pairs, status: np.ndarray) -> np.ndarray:
    """Rows of the pairs that are not automatic loops but whose two views measured where one
    lies from the other (distance, direction and turn): a measurement of the map whether or
    not the two are one place. A route and its return driven two metres beside it share many
    points, and these pairs hold the two legs apart; without them nothing in the graph says
    how far apart the legs are, the loops at the ends pull them together, and the map then
    closes pairs two metres apart (docs/method.md, stage 7). Robust in the graph like a loop;
    a wrong one is outvoted, and the map's loops are unchanged by it."""
    if pairs.distance_steps is None or pairs.bearing is None or pairs.yaw is None:
        return np.zeros(0, np.int64)
    known = np.isfinite(pairs.distance_steps) & np.isfinite(pairs.bearing) & np.isfinite(pairs.yaw)
    return np.flatnonzero(known & (status != Status.AUTO.value))


def _offsets(pairs: Pairs, rows: np.ndarray) -> Optional[np.ndarray]:
    """Where each loop's b lies in a's frame (node steps): its measured distance along the
    two-view direction of b seen from a (``bearing``); 0 where either is unknown."""
    if pairs.distance_steps is None or pairs.bearing is None:
        return None
    d, az = pairs.distance_steps[rows], np.radians(pairs.bearing[rows])
    ok = np.isfinite(d) & np.isfinite(az)
    return np.where(ok[:, None], np.stack([d * np.cos(az), d * np.sin(az)], axis=1), 0.0)


def _evidence(pairs: Pairs, i: int, rule: str, reason: str, closure: float) -> dict:
    known = pairs.inliers[i] >= 0   # two-view geometry was measured

    def value(name, cast=float):    # None where not measured
        arr = getattr(pairs, name)
        return cast(arr[i]) if arr is not None and np.isfinite(arr[i]) else None

    def fit(name, cast=int):
        return value(name, cast) if known else None

    return {"score": float(pairs.score[i]), "support": value("support"), "direction": int(pairs.direction[i]),
            "matches": fit("matches"), "inliers": fit("inliers"), "inlier_ratio": fit("inlier_ratio", float),
            "path_inliers": fit("path_inliers"), "step_inliers": fit("step_inliers"),
            "confidence": float(pairs.confidence[i]), "closure": float(closure) if np.isfinite(closure) else None,
            "plane_share": value("plane_share"), "distance_steps": value("distance_steps"),
            "bearing": value("bearing") if np.isfinite(pairs.distance_steps[i]) else None,
            "rule": str(rule) or None, "reason": str(reason) or None}
