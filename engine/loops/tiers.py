"""Stages 5 and 6 of ``verified``: tiers by a small table of rules, then the nearest pair.

Stage 5 (``tiers``): a pair is automatic when one row of ``AUTO_RULES`` holds, a candidate
for review when it reaches ``candidate_z`` and ``candidate_confidence``, else dropped. The
physical reference comes from the recording itself: two visits are one place when they are
as close as one node step, counted (they share as many inliers as an end shares with its
next node) or measured (``distance_steps``). Where each number came from: docs/method.md.

Stage 6 (``nearest``): a pair not automatic moves to the pair of its place whose views
measure closest, when that pair passes stage 5 by its measured distance. Stage 3 keeps the
pair with the best descriptor evidence; where two paths only touch (a crossing, an offset
return) the closest views can be a node or two beside it.
"""

from __future__ import annotations

import numpy as np

from ..params import MapParams
from ..retrieval import temporal_neighbours
from .pairs import Pairs, Status
from .places import PlaceGrid
from .retrieve import background, scored, with_support


def evidence(pairs: Pairs, params: MapParams, count_steps: bool = True,
             recording: np.ndarray = None) -> dict[str, np.ndarray]:
    """The named facts the rules combine, one boolean array each (NaN compares False);
    ``recording``: each node's recording (None: one)."""
    same = np.ones(len(pairs), bool) if recording is None else recording[pairs.a] == recording[pairs.b]
    step = np.maximum(pairs.step_inliers, 0)
    apart = pairs.distance_steps
    measured = (apart <= params.auto_distance_steps) & (pairs.inliers >= params.auto_measured_share * step)
    counted = (pairs.inliers >= params.auto_step_share * step) & ~(apart > params.auto_distance_steps)
    one_place = measured | counted if count_steps else measured      # a measurement outranks a count
    return {
        "geometry": (pairs.inliers >= params.auto_inliers) & one_place & ~(pairs.plane_share > params.auto_plane_share),
        "measured": measured,
        "both": measured & counted,
        "one_stretch": measured & same & (pairs.b - pairs.a <= 2 * params.neighbor_node_num + 1),
        "no_geometry": (pairs.inliers < 0) & (np.nan_to_num(pairs.support, nan=-np.inf) >= params.auto_support),
    }


# Automatic loops: (name, facts that must all hold, the calibrated score it needs). The score
# guards against a fooled geometry: the more geometry says one place, the less score it needs.
# "one_stretch": every node between the ends is a temporal neighbour of one of them, so there
# is no "elsewhere" for a look-alike place (a tight turn scores 2-3).
AUTO_RULES: tuple[tuple[str, tuple[str, ...], str], ...] = (
    ("geometry confirms", ("geometry",), "auto_geometry_z"),
    ("measured one place", ("geometry", "measured"), "candidate_z"),
    ("counted and measured", ("geometry", "both"), "candidate_floor"),
    ("one stretch of path", ("geometry", "one_stretch"), "candidate_floor"),
    ("descriptor alone", ("no_geometry",), "auto_z"),
)


def _score_needed(name: str, params: MapParams) -> float:
    if name == "candidate_floor":   # stage 3's floor: the score at which geometry is looked at
        return params.candidate_z - params.geometry_margin_z
    return float(getattr(params, name))


def tiers(pairs: Pairs, params: MapParams, count_steps: bool = True,
          recording: np.ndarray = None) -> tuple[np.ndarray, np.ndarray]:
    """Stage 5: (status, rule) per pair: ``Status`` values and the name of the first
    ``AUTO_RULES`` row that made it automatic ("" otherwise). ``count_steps=False`` judges
    by the measured distance alone (stage 6). ``recording``: each node's recording."""
    facts = evidence(pairs, params, count_steps, recording)
    rule = np.full(len(pairs), "", dtype=object)
    for name, needs, score in AUTO_RULES:
        holds = np.logical_and.reduce([facts[f] for f in needs]) & (pairs.score >= _score_needed(score, params))
        rule[(rule == "") & holds] = name
    auto = rule != ""
    cand = ~auto & (pairs.score >= params.candidate_z) & (pairs.confidence >= params.candidate_confidence)
    status = np.where(auto, Status.AUTO.value, np.where(cand, Status.CANDIDATE.value, Status.DROPPED.value))
    return status.astype(object), rule


def _beside(pairs: Pairs, owners: np.ndarray, half: int):
    """(a, b, owner) of every pair up to ``half`` nodes beside each pair in ``owners``."""
    reach = np.arange(-half, half + 1)
    da, db = (d.ravel() for d in np.meshgrid(reach, reach))
    moved = (da != 0) | (db != 0)
    da, db = da[moved], db[moved]
    return (pairs.a[owners, None] + da).ravel(), (pairs.b[owners, None] + db).ravel(), np.repeat(owners, da.size)


def nearest(pairs: Pairs, status: np.ndarray, rule: np.ndarray, set_aside: tuple, vectors: np.ndarray,
            recording: np.ndarray, geometry, params: MapParams, cache: dict):
    """Stage 6: each pair not automatic moves to the pair of its place whose views measure
    closest, among those that pass stage 5 by the measured distance alone; it then is that
    pair (status auto, rule "nearest pair of the place"). The pairs of its place: those stage
    3 set aside for it and, for a pair with ``auto_inliers``, every pair up to
    ``place_radius // 2`` nodes beside it. A pair does not move into a place that already has
    an automatic loop. ``set_aside``: stage 3's pairs set aside and the index of the kept pair
    of each one's place. Returns (pairs, status, rule), new arrays."""
    m = geometry.node_rows.size
    todo = np.flatnonzero(status != Status.AUTO.value)
    if not geometry.known or todo.size == 0:
        return pairs, status, rule
    na, nb, owner = _beside(pairs, todo[pairs.inliers[todo] >= params.auto_inliers], params.place_radius // 2)
    aside_pairs, aside_owner = set_aside
    mine = np.isin(aside_owner, todo)
    sa, sb, so = aside_pairs.a[mine], aside_pairs.b[mine], aside_owner[mine]
    stacked = np.stack([np.concatenate([owner, so]), np.concatenate([na, sa]), np.concatenate([nb, sb])], axis=1)
    aside = np.concatenate([np.zeros(owner.size, bool), np.ones(so.size, bool)])
    _, first = np.unique(stacked, axis=0, return_index=True)
    owner, na, nb, aside = stacked[first, 0], stacked[first, 1], stacked[first, 2], aside[first]
    ok = (na >= 0) & (nb < m) & (nb > na)
    ok[ok] &= ~temporal_neighbours(na[ok], nb[ok], params.neighbor_node_num, recording)
    owner, na, nb, aside = owner[ok], na[ok], nb[ok], aside[ok]
    if owner.size == 0:
        return pairs, status, rule
    stats = background(vectors, recording, params, cache)
    near = with_support(vectors, recording, scored(vectors, stats, na, nb), params, cache)
    near = geometry.measure(near, params)
    close = tiers(near, params, count_steps=False, recording=recording)[0] == Status.AUTO.value
    pairs, status, rule = pairs.take(np.arange(len(pairs))), status.copy(), rule.copy()
    closed = PlaceGrid(params.place_radius)
    for x, y in zip(pairs.a[status == Status.AUTO.value].tolist(), pairs.b[status == Status.AUTO.value].tolist()):
        closed.add(x, y)
    for i in todo[np.lexsort((pairs.b[todo], pairs.a[todo], -pairs.confidence[todo]))]:
        mine = np.flatnonzero(close & (owner == i))
        mine = mine[np.argsort(near.distance_steps[mine], kind="stable")]
        free = [j for j in mine.tolist() if not aside[j] or not closed.near(int(na[j]), int(nb[j]))]
        if free:
            closed.add(int(na[free[0]]), int(nb[free[0]]))
            pairs.set_row(i, near, free[0])
            status[i], rule[i] = Status.AUTO.value, "nearest pair of the place"
    return pairs, status, rule
