"""Loop closure by retrieval, evidence and consistency: the ``verified`` method.

The stages read top to bottom (``detect_loops`` below calls them in this order); each is a
plain function of plain arrays, and every number it uses is a ``MapParams`` entry declared
once in ``engine.params.PARAMETERS`` (with where it came from):

1. ``retrieve``     each node's best ``retrieval_k`` descriptor matches, temporal neighbours
                    excluded, in blocks (``engine.retrieval``: never an n x n array).
2. ``calibrate``    each match's cosine as standard deviations above the two nodes' own
                    background (their similarities to unrelated nodes), so that one threshold
                    means the same for any descriptor, scene and recording.
3. ``support``      the mean calibrated score along the matched stretch, forwards (the same
                    way again) and backwards (a reverse drive): the paper's window count,
                    generalised to both directions.
4. ``one_per_place`` a match must be the most confident (score + support) within
                    ``place_radius`` nodes on both ends (non-maximum suppression in the
                    (a, b) plane), so that geometry is checked once per place.
5. ``geometry``     local features of the two frames matched and fitted with a two-view model
                    on the sphere (essential matrix, or a pure rotation at the same spot):
                    inliers are physical evidence of the same scene; the rotation gives the
                    loop's ``yaw``. The same is measured between each end and its next
                    node along its own path (``step_inliers``: what one node step away
                    shares) and its path neighbour just outside the temporal window
                    (``path_inliers``), and, where the two views could make an automatic
                    loop, how far apart they are in node steps (``distance_steps``: the
                    scale of the loop's geometry against that of each end's steps).
                    Cached per frame pair.
6. ``confidence``   one ranking number from the three voices.
7. ``tiers``        auto (the two visits are as close as one node step: they share as many
                    inliers, or measure closer while sharing a good part of a step's inliers)
                    or candidate (for a person), by the thresholds.
   ``nearest``      a match not yet automatic moves to the pair of its place whose views
                    measure closest (the pairs stage 4 set aside for it and, where geometry
                    confirms the scene, those up to half of ``place_radius`` nodes beside it),
                    when those are at most ``auto_distance_steps`` apart (an automatic loop).
8a. ``half_turns``  a path step that read a straight step as a half turn (a scene that looks
                    the same turned round) is turned back where the automatic loops on both
                    sides of it agree only without it: the path's headings, repaired.
8b. ``straight_for_a_loop`` a step read as a half turn (or two consecutive ones together)
                    is read straight where an automatic loop across it comes back, in
                    place and in heading, only that way and no loop across it needs the
                    turn (a crossing passed once more has one loop, too few for stage 8a).
9. ``closure``      the path itself must come back: dead reckoning of the path between a
                    loop's ends (headings and directions of motion from the two-view
                    geometry of consecutive nodes, one unit per node step) must meet again,
                    or the loop joins two look-alike places far apart: an automatic loop
                    goes back to the candidate tier, a candidate is dropped.
9a. ``lone_turns``  a loop whose path comes back only through a step read as a half turn,
                    a turn no other loop needs, goes back to the candidate tier: a straight
                    step in a corridor alike both ways can read as one and fold the path.
8. ``consistency``  then, of the loops left, relative headings composed around a cycle of
                    path and two loops must close (the PCM idea of Kimera-RPGO): an automatic
                    loop that disagrees with the loops around it goes back to the candidate
                    tier (after stage 9, so that loops the path rejects do not vote).
   ``lengths``      and of two loops, the stretches between their ends join the same two
                    places, so they are equally long: two automatic loops that cannot
                    both hold both go back to the candidate tier.
10. ``closed_places`` a candidate within ``place_radius`` nodes of an automatic loop (on
                    both ends) leaves the queue: its place has its loop (stage 4's one loop
                    per place, again after stage 7b moved the loops).

Expensive results (retrieval, background statistics, geometry) live in ``Descriptors.cache``,
so re-mapping after a threshold change costs the arithmetic of the stages, not the retrieval
or the geometry of pairs verified before.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .loops import LoopCandidate
from .params import MapParams


# ----------------------------------------------------------------------------- plain data

@dataclass
class Matches:
    """Candidate node pairs (a < b) with their evidence, one entry per pair."""

    a: np.ndarray                 # int64 node index
    b: np.ndarray                 # int64 node index, b - a > neighbour window
    cosine: np.ndarray            # float32 descriptor cosine
    score: np.ndarray             # float64 calibrated score (stage 2)
    support: np.ndarray = None    # float64 best mean calibrated score along the stretch (stage 3)
    direction: np.ndarray = None  # int64 +1 forward, -1 reverse (stage 3)
    matches: np.ndarray = None    # int64 local feature matches (stage 4; -1 unknown)
    inliers: np.ndarray = None    # int64 two-view inliers (stage 4; -1 unknown)
    inlier_ratio: np.ndarray = None
    yaw: np.ndarray = None        # float64 relative heading of b to a, degrees (NaN unknown)
    path_inliers: np.ndarray = None  # int64 inliers of each end with its own path neighbour (-1 unknown)
    step_inliers: np.ndarray = None  # int64 inliers of each end with its next node (smaller end; -1 unknown)
    confidence: np.ndarray = None
    closure: np.ndarray = None    # float64 node steps dead reckoning misses meeting by (stage 9; NaN unknown)
    plane_share: np.ndarray = None  # float64 share of inliers on one plane (stage 5; NaN unknown)
    distance_steps: np.ndarray = None  # float64 the two visits apart, in node steps (stage 5; NaN unknown)

    def __len__(self) -> int:
        return int(self.a.size)

    def take(self, keep: np.ndarray) -> "Matches":
        out = {}
        for k, v in self.__dict__.items():
            out[k] = None if v is None else v[keep]
        return Matches(**out)


# ----------------------------------------------------------------------------- stages

def retrieve(vectors: np.ndarray, params: MapParams, cache: dict) -> "tuple[np.ndarray, np.ndarray]":
    """Stage 1: each node's best ``retrieval_k`` matches beyond the temporal neighbours, as
    unique pairs (a < b) with their cosine. Cached per node set (``cache``)."""
    from . import retrieval

    key = ("nearest", vectors.shape, hash(vectors[:, :4].tobytes()), params.retrieval_k, params.neighbor_node_num)
    if key not in cache:
        neigh = retrieval.nearest(vectors, params.retrieval_k, params.neighbor_node_num)
        cache[key] = neigh
    neigh = cache[key]
    m, k = neigh.index.shape
    rows = np.repeat(np.arange(m, dtype=np.int64), k)
    cols = neigh.index.reshape(-1).astype(np.int64)
    ok = cols >= 0
    a, b = np.minimum(rows[ok], cols[ok]), np.maximum(rows[ok], cols[ok])
    pair = np.unique(a * m + b)
    a, b = pair // m, pair % m
    return a, b


def background(vectors: np.ndarray, params: MapParams, cache: dict):
    """Each node's background similarity statistics (for stage 2), cached per node set."""
    from . import retrieval

    key = ("background", vectors.shape, hash(vectors[:, :4].tobytes()), params.neighbor_node_num)
    if key not in cache:
        cache[key] = retrieval.background(vectors, params.neighbor_node_num)
    return cache[key]


def calibrate(vectors: np.ndarray, stats, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stage 2: (cosine, calibrated score) of pairs (a, b)."""
    from . import retrieval

    cos = retrieval.pair_similarities(vectors, a, b)
    return cos, retrieval.zscores(cos, stats, a, b)


def support(vectors: np.ndarray, stats, a: np.ndarray, b: np.ndarray, params: MapParams
            ) -> tuple[np.ndarray, np.ndarray]:
    """Stage 3: the better of the forward and the reverse mean calibrated score along the
    stretch through (a, b), and which direction it was (+1 forward, -1 reverse).

    A place passed once more along a path is a run of matches along a diagonal of the
    similarity matrix; a crossing shares a single point and has no such run (stage 4 must
    carry it)."""
    from . import retrieval

    fwd, _ = retrieval.diagonal_support(vectors, stats, a, b, params.support_half, +1)
    rev, _ = retrieval.diagonal_support(vectors, stats, a, b, params.support_half, -1)
    fwd = np.nan_to_num(fwd, nan=-np.inf)
    rev = np.nan_to_num(rev, nan=-np.inf)
    best = np.maximum(fwd, rev)
    direction = np.where(rev > fwd, -1, 1).astype(np.int64)
    return np.where(np.isfinite(best), best, np.nan), direction


# Geometry is checked only on matches that could become a loop: this far below candidate_z
# (a crossing's single pair can have a modest descriptor score and strong geometry).
GEOMETRY_MARGIN_Z = 1.0
# Inliers worth one standard deviation of calibrated score in the confidence ranking.
INLIERS_PER_Z = 20.0


class _PlaceGrid:
    """Node pairs (a, b) bucketed on a grid of ``radius + 1`` nodes, so that the pairs within
    ``radius`` nodes of a pair on both ends are found in nine buckets, not among all pairs."""

    def __init__(self, radius: int):
        self.radius = max(int(radius), 0)
        self.cell = self.radius + 1
        self.buckets: dict[tuple[int, int], list[tuple[int, int, int]]] = {}

    def add(self, a: int, b: int, item: int = -1) -> None:
        self.buckets.setdefault((a // self.cell, b // self.cell), []).append((a, b, item))

    def near(self, a: int, b: int) -> list[int]:
        """The items of the pairs within ``radius`` nodes of (a, b) on both ends."""
        ka, kb, r = a // self.cell, b // self.cell, self.radius
        return [item for da in (-1, 0, 1) for db in (-1, 0, 1)
                for u, w, item in self.buckets.get((ka + da, kb + db), ())
                if abs(u - a) <= r and abs(w - b) <= r]


def _descriptor_rank(c: Matches) -> np.ndarray:
    """Stage 4's ranking of a match: calibrated score + positive support (no geometry yet)."""
    return c.score + np.maximum(np.nan_to_num(c.support, nan=0.0), 0.0)


def _automatic_places(c: Matches, status: np.ndarray, radius: int) -> _PlaceGrid:
    """The places closed by automatic loops: their pairs on a ``_PlaceGrid`` of ``radius``."""
    closed = _PlaceGrid(radius)
    for x, y in zip(c.a[status == "auto"].tolist(), c.b[status == "auto"].tolist()):
        closed.add(x, y)
    return closed


def one_per_place(c: Matches, radius: int) -> np.ndarray:
    """Stage 4: keep a match only if no more confident match lies within ``radius`` nodes on
    both ends (ties go to the earlier pair). A stretch passed twice gives one loop every
    ``radius`` nodes or so, not one per node pair."""
    keep = np.ones(len(c), bool)
    order = np.lexsort((c.b, c.a, -c.confidence))
    kept = _PlaceGrid(radius)
    for i in order:
        ai, bi = int(c.a[i]), int(c.b[i])
        if kept.near(ai, bi):
            keep[i] = False
        else:
            kept.add(ai, bi)
    return keep


def _verified(features, node_rows: np.ndarray, a: np.ndarray, b: np.ndarray, cache: dict):
    """(matches, inliers, inlier_ratio, yaw, motion azimuth, plane share, parallax; of the
    shifted frames, see ``engine.sphere``) of node pairs, from the per-frame-pair cache, verifying
    only the pairs not seen before."""
    from . import sphere

    store = cache.setdefault("geometry", {})
    ra, rb = node_rows[a], node_rows[b]
    keys = list(zip(ra.tolist(), rb.tolist()))
    todo = sorted({k for k in keys if k not in store})
    if todo:
        arr = np.asarray(todo, np.int64)
        res = sphere.verify_pairs(features, arr[:, 0], arr[:, 1])
        for j, k in enumerate(todo):
            store[k] = (int(res["matches"][j]), int(res["inliers"][j]), float(res["inlier_ratio"][j]),
                        float(res["yaw_deg"][j]), float(res["motion_deg"][j]), float(res["plane_share"][j]),
                        float(res["parallax_deg"][j]))
    if not keys:
        return np.zeros((0, 7))
    return np.asarray([store[k] for k in keys], np.float64)


def geometry(features, node_rows: np.ndarray, a: np.ndarray, b: np.ndarray, gap: int, cache: dict,
             distance_from: int = 0) -> dict:
    """Stage 5: two-view geometry on the sphere of node pairs (a, b), and of each end with its
    path neighbour ``gap`` nodes away (the nearest node that could be a loop).

    Returns arrays ``matches``, ``inliers`` (-1 where there are no features), ``inlier_ratio``,
    ``yaw`` (degrees, shifted frames; NaN where no model), ``path_inliers`` (the larger
    count of the two ends with their path neighbours, before or after, other than the
    loop's other end), ``step_inliers``
    (each end's count with its nearer-sharing next node, before or after; the smaller end's)
    ``plane_share`` (share of the pair's inliers on one plane, ``engine.sphere.plane_share``;
    NaN without an essential model) and ``distance_steps`` (``_distance_steps``, for pairs with
    at least ``distance_from`` inliers, NaN for the others: it costs up to four more two-view
    fits per pair, and only pairs that could become automatic loops need it)."""
    n = a.size
    out = {"matches": np.full(n, -1, np.int64), "inliers": np.full(n, -1, np.int64),
           "inlier_ratio": np.full(n, np.nan), "yaw": np.full(n, np.nan),
           "path_inliers": np.full(n, -1, np.int64), "step_inliers": np.full(n, -1, np.int64),
           "plane_share": np.full(n, np.nan), "distance_steps": np.full(n, np.nan)}
    if features is None or n == 0:
        return out
    pair = _verified(features, node_rows, a, b, cache)
    out["matches"], out["inliers"] = pair[:, 0].astype(np.int64), pair[:, 1].astype(np.int64)
    out["inlier_ratio"], out["yaw"], out["plane_share"] = pair[:, 2], pair[:, 3], pair[:, 5]
    out["path_inliers"] = np.maximum(_neighbour_inliers(features, node_rows, a, gap, cache, partners=b),
                                     _neighbour_inliers(features, node_rows, b, gap, cache, partners=a))
    out["step_inliers"] = np.minimum(_neighbour_inliers(features, node_rows, a, 1, cache),
                                     _neighbour_inliers(features, node_rows, b, 1, cache))
    near = np.flatnonzero(out["inliers"] >= max(int(distance_from), 1))
    out["distance_steps"][near] = _distance_steps(features, node_rows, a[near], b[near], cache)
    return out


def measure(c: Matches, features, node_rows: np.ndarray, shifts: np.ndarray, frame_width: int,
            params: MapParams, cache: dict) -> None:
    """Stage 5 on the matches ``c``, in place: ``geometry`` of each pair (the distance where it
    has ``auto_inliers``) and its yaw between the original frames."""
    geo = geometry(features, node_rows, c.a, c.b, params.neighbor_node_num + 1, cache,
                   distance_from=params.auto_inliers)
    c.matches, c.inliers, c.inlier_ratio = geo["matches"], geo["inliers"], geo["inlier_ratio"]
    c.path_inliers, c.step_inliers, c.plane_share = geo["path_inliers"], geo["step_inliers"], geo["plane_share"]
    c.distance_steps = geo["distance_steps"]
    c.yaw = original_yaw(geo["yaw"], shifts[c.a], shifts[c.b], frame_width)


def _two_view(features, row_a: int, row_b: int, cache: dict):
    """``engine.sphere.two_view`` of two frames (the fit ``verify_pairs`` makes), cached per pair."""
    from . import sphere

    store = cache.setdefault("two_view", {})
    key = (int(row_a), int(row_b))
    if key not in store:
        store[key] = sphere.two_view(features.of(key[0]), features.of(key[1]))
    return store[key]


def _distance_steps(features, node_rows: np.ndarray, a: np.ndarray, b: np.ndarray, cache: dict) -> np.ndarray:
    """How far apart the two views of each pair (a, b) are, in node steps: for each end, the
    median of ``engine.sphere.baseline_ratio`` of the pair against the end's step to its
    previous and to its next node; the mean of the two ends (NaN unless both are known).

    Two views' geometry knows the direction between them, not the distance; a point seen
    from an end is also triangulated by that end's step along its own path, whose length is
    one node step, and that gives the loop's length in steps. On the first synthetic family
    (seeds 0-4, 2,900 estimates against the true positions) estimates from at least
    ``sphere.COMMON_POINTS_MIN`` common points were all within a factor 1.42 of the truth,
    95 % within 12 %. Both ends must be known, so one end alone cannot make a loop. Until the
    twenty-second round the larger end was taken: the larger of two estimates that each err
    either way is biased long, and a pair at the method's one place (``auto_distance_steps``)
    then measures beyond it. On the first family (seeds 0-4, 2,819 pairs with both ends
    measured, against the true positions) the mean calls 590 of the 590 pairs truly within 1.1 steps
    close (the larger end: 587) and, like the larger end, no pair beyond 1.25 steps (1 m).
    Cached per frame pair and the neighbours used."""
    from . import sphere

    store = cache.setdefault("distance_steps", {})
    m = node_rows.size
    out = np.full(a.size, np.nan)
    for k, (i, j) in enumerate(zip(a.tolist(), b.tolist())):
        near = tuple(int(node_rows[n]) if 0 <= n < m else -1 for n in (i - 1, i, i + 1, j - 1, j, j + 1))
        if near not in store:
            loop = _two_view(features, node_rows[i], node_rows[j], cache)
            ends = []
            for end, side in ((i, 0), (j, 1)):
                ratios = []
                for other in (end - 1, end + 1):
                    if 0 <= other < m and other not in (i, j):
                        lo, hi = min(end, other), max(end, other)
                        step = _two_view(features, node_rows[lo], node_rows[hi], cache)
                        ratios.append(sphere.baseline_ratio(loop, side, step, 0 if lo == end else 1))
                ratios = [r for r in ratios if np.isfinite(r)]
                ends.append(float(np.median(ratios)) if ratios else np.nan)
            store[near] = float(np.mean(ends)) if all(np.isfinite(ends)) else np.nan
        out[k] = store[near]
    return out


def _step_geometry(features, node_rows: np.ndarray, shifts: np.ndarray, frame_width: int,
                   cache: dict) -> np.ndarray:
    """``_verified`` of every consecutive node pair (i, i + 1), gathered once per node set,
    with the turns ``_turns_read`` finds read again: the path's headings (stage 8) and its
    dead reckoning (stage 9) both read it."""
    key = ("steps", hash(node_rows.tobytes()), hash(np.asarray(shifts).tobytes()), node_rows.size)
    if key not in cache:
        steps = np.arange(node_rows.size - 1)
        geo = _verified(features, node_rows, steps, steps + 1, cache).copy()   # the pair cache stays
        cache[key] = _turns_read(geo, features, node_rows, shifts, frame_width, cache)
    return cache[key]


def _turns_read(geo: np.ndarray, features, node_rows: np.ndarray, shifts: np.ndarray, frame_width: int,
                cache: dict) -> np.ndarray:
    """Steps whose essential model turns the camera by more than a quarter turn are read again
    as planar motion (``engine.sphere.planar_yaw``); where that reading differs by more than
    a quarter turn, the step takes its yaw, and its direction of motion is left unknown
    (``path_track`` keeps the step before's). ``geo``: rows of ``_verified``, in place.

    Two views of a scene that looks the same turned round (facing walls with one picture, a
    symmetric corridor) fit a model turned by 180 degrees, and one such step turns every
    heading after it. Where few matches are right, RANSAC's eight-match samples find that
    model about as often as the right one; the planar reading tries every turn and every
    direction, so it finds the model most matches agree with. First synthetic family (seeds
    0-4): the planar reading lies within 3 degrees of every true turn of 120-180 degrees
    (ten), and reads the one straight step read as a turn (105 degrees) straight (1 degree).
    Only steps read as turns are read again (a few per recording; the search costs about a
    tenth of a second for 300 matches)."""
    from . import sphere

    turned = np.abs(original_yaw(geo[:, 3], shifts[:-1], shifts[1:], frame_width)) > 90.0   # NaN: False
    store = cache.setdefault("planar", {})                             # per frame pair, as the fits
    for k in np.flatnonzero(turned & np.isfinite(geo[:, 4])):          # essential models only
        key = (int(node_rows[k]), int(node_rows[k + 1]))
        if key not in store:
            store[key] = sphere.planar_yaw(_two_view(features, key[0], key[1], cache))[0]
        yaw = store[key]
        if abs(_wrap(yaw - geo[k, 3])) > 90.0:
            geo[k, 3], geo[k, 4] = yaw, np.nan
    return geo


def _neighbour_inliers(features, node_rows: np.ndarray, ends: np.ndarray, gap: int, cache: dict,
                       partners: Optional[np.ndarray] = None) -> np.ndarray:
    """Inliers of each node in ``ends`` with the node ``gap`` before or after it on the path,
    whichever shares more (0 where neither exists); never with its loop's other end
    (``partners``): a loop exactly ``gap`` nodes long would be its own reference."""
    m = node_rows.size
    best = np.zeros(ends.size, np.int64)
    for step in (-gap, gap):
        other = ends + step
        ok = (other >= 0) & (other < m)
        if partners is not None:
            ok &= other != partners
        if ok.any():
            lo, hi = np.minimum(ends[ok], other[ok]), np.maximum(ends[ok], other[ok])
            ref = _verified(features, node_rows, lo, hi, cache)[:, 1].astype(np.int64)
            best[ok] = np.maximum(best[ok], ref)
    return best


def confidence(c: Matches) -> np.ndarray:
    """Stage 6: calibrated score + positive support + inliers beyond the path's own /
    ``INLIERS_PER_Z``.

    Each voice is in (about) standard deviations of evidence: the score and the support are
    calibrated z; ``INLIERS_PER_Z`` = 20 because unrelated views keep about 20 inliers at
    most (99th percentile 22 in the probe of issue 13), so 20 more is one more spread."""
    lift = np.where(c.inliers > 0, np.maximum(c.inliers - np.maximum(c.path_inliers, 0), 0), 0)
    sup = np.where(np.isfinite(c.support), np.maximum(c.support, 0.0), 0.0)
    return c.score + sup + lift / INLIERS_PER_Z


def tiers(c: Matches, params: MapParams, share_steps: bool = True) -> np.ndarray:
    """Stage 7: "auto", "candidate" or "" (dropped) for every match.

    Automatic: a match at least at ``auto_geometry_z`` whose two views share ``auto_inliers``
    two-view inliers and at least ``auto_step_share`` times what each end shares with its
    next node along its own path (``step_inliers``). A topological node is a stretch of path
    whose views are alike; two visits are the same place when they are as alike as one
    node step: the physical reference comes from the recording itself (texture, camera,
    node spacing), not from a number tuned on one world. On the first synthetic family
    the true revisits share 0.8-2.6 times a step's inliers, views 1-3 m apart 0.5-0.9 times
    (5th-95th percentiles of the matches kept by stage 4). Or, measured rather than
    counted, the two views are at most ``auto_distance_steps`` node steps apart
    (``distance_steps``): inliers fall with distance, but also with what changed between
    two visits (light, people, the camera's tilt), so a revisit half a step away can share
    fewer inliers than a step made a second apart; the distance does not care. Where the
    distance is measured it decides: views measured more than ``auto_distance_steps`` apart
    are not one place however many inliers they share (the count is a stand-in for the
    distance; on the first family this changed nothing, on the second family's seeds 5-24 it
    removed two false loops, offset returns 1.15-1.41 m apart sharing 1.07-1.08 steps' inliers,
    and sent three right loops to the queue). Nor may more than
    ``auto_plane_share`` of the inliers lie on one plane: a flat picture copied elsewhere (a
    poster, a printed facade, a repeated wall texture) fits two views as well as the place
    does; a revisit sees things at several depths.
    A measured distance counts only with at least ``auto_measured_share`` of a step's inliers:
    a texture repeated along a corridor or a block can fit two views metres apart as a virtual
    pair a fraction of a step apart (0.2-0.33 steps for views 6-19 m apart on the second
    family), but then only the repeated part matches and the pair shares a third to a half of
    what a step shares; every true loop the first family accepts by its distance shares 0.7 or
    more. With that check a loop whose views measure within a step needs only ``candidate_z``
    of score, not ``auto_geometry_z``: the score's job at this tier is to guard against a
    fooled geometry, and two checks of the geometry now do it (the fifth and seventh rounds
    tried the lower score without the share check and each met such a pair: dropped).
    Where both readings say one place, measured within a step and sharing a full step's
    inliers (``auto_step_share``), the score needs only stage 5's floor (``candidate_z`` -
    ``GEOMETRY_MARGIN_Z``, the score at which stage 4 keeps a match to look at its geometry):
    a view a quarter of a step from a junction's other arm can score low (other parts of the
    panorama in view, other light) and share 1.5-2 times a step's inliers. No new number.
    First family: unchanged (one true pair, its place already found). Second family,
    looked-at seeds 5-42 and 55-78: 20 more places (888 -> 908 of 1,066), no false loop; three
    false pairs passed stage 7 this way (look-alike places 83-85 m apart, a corridor 6.4 m) and
    the path checks (stages 9, 8, 9b) sent all three back. Held-out seeds 79-84, mapped once:
    83 -> 87 of 105, no false loop. The same floor with the measured distance alone (share 0.6) met a false
    loop in the ninth round (42 inliers where a step shares 57).
    So too where the two ends are one stretch of path: every node between them is a
    temporal neighbour (``neighbor_node_num``) of one end or the other, so the loop spans
    at most ``2 * neighbor_node_num + 1`` steps (a tight turn: the robot turns round and
    passes within a step of where it was a few nodes before). The score guards against a
    place that looks like another place elsewhere (the three false loops the lower floor
    met in the fifth, seventh and ninth rounds joined views 6-20 m apart along corridors
    and reverse drives), and between two ends of one stretch there is no elsewhere: the
    path between them is one temporal neighbourhood of each end. At a tight turn the two
    views face opposite ways, blurred by the turn, and score 2-3 (second family, seeds
    204-205: nodes 6-7 apart, 0.74-0.85 m, measured 0.78-0.99 steps, sharing 0.75-0.9 of a
    step) where a pass along the same stretch scores 4 or more. No new number; the paper's
    temporal window. First family (0-4, 300-301): the same places and queue (it has few
    tight turns).
    Where geometry is not known (descriptors from another program) a high score
    (``auto_z``) with strong support along the stretch (``auto_support``) instead.
    A candidate for review is any other match at ``candidate_z`` whose confidence (score,
    support and geometry together) reaches ``candidate_confidence``: a node's best match in a
    large recording is a few standard deviations up by chance alone (the best of 25,000
    unrelated scores is about 4), but then nothing along the stretch or in the geometry
    agrees with it. ``share_steps=False`` leaves out the inlier count against a step (the
    measured distance alone says "one place"; stage 7b)."""
    step = np.maximum(c.step_inliers if c.step_inliers is not None else np.zeros(len(c), np.int64), 0)
    plane = c.plane_share if c.plane_share is not None else np.full(len(c), np.nan)
    apart = c.distance_steps if c.distance_steps is not None else np.full(len(c), np.nan)
    measured_close = ((apart <= params.auto_distance_steps)                            # NaN: no
                      & (c.inliers >= params.auto_measured_share * step))
    shares_a_step = c.inliers >= params.auto_step_share * step
    one_place = measured_close
    if share_steps:   # the count only where the distance is not measured: a measurement outranks it
        one_place = one_place | (shares_a_step & ~(apart > params.auto_distance_steps))
    geo_strong = ((c.inliers >= params.auto_inliers) & one_place
                  & ~(plane > params.auto_plane_share))                          # NaN: not flat

    no_geo = c.inliers < 0
    sup = np.nan_to_num(c.support, nan=-np.inf)
    both_close = measured_close & shares_a_step                     # count and measure agree
    one_stretch = c.b - c.a <= 2 * params.neighbor_node_num + 1     # no "elsewhere" between the ends
    floor = np.where(both_close | (measured_close & one_stretch), params.candidate_z - GEOMETRY_MARGIN_Z,
                     params.candidate_z)
    auto = ((geo_strong & ((c.score >= params.auto_geometry_z)
                           | (measured_close & (c.score >= floor))))
            | (no_geo & (c.score >= params.auto_z) & (sup >= params.auto_support)))
    cand = ~auto & (c.score >= params.candidate_z) & (c.confidence >= params.candidate_confidence)
    return np.where(auto, "auto", np.where(cand, "candidate", ""))


def nearest(c: Matches, status: np.ndarray, set_aside: Matches, v: np.ndarray, stats, features,
            node_rows: np.ndarray, shifts: np.ndarray, frame_width: int, params: MapParams,
            cache: dict) -> tuple[Matches, np.ndarray]:
    """Stage 7b: a match that stage 7 did not make automatic moves to the pair of its place
    whose two views measure closest (``distance_steps``), when that pair passes stage 7 by
    its measured distance (score, inliers, measured share, plane share and at most
    ``auto_distance_steps`` apart); it then is that pair. The pairs of its place: those
    stage 4 set aside for it (``_set_aside_for``) and, for a match with ``auto_inliers``,
    every pair up to ``place_radius`` // 2 nodes beside it (on either end or both).

    Stage 4 keeps of each place the pair with the best descriptor evidence, but where two
    paths only touch (a crossing, a return offset to one side, a figure eight's lobe end)
    the two views closest in space can be a node or two beside it, and only they are one
    place. The reach is half of stage 4's radius, no new number: stage 4 keeps one match
    per ``place_radius`` nodes, so the pairs within half of it belong to this match rather
    than to the next one kept. The move is judged by the measured distance alone: moving to
    the neighbour with the most inliers instead (tried in the third round) made 3 false
    loops on the first family, pairs one step along a shared stretch sharing more than a
    step does. One node beside it (rounds 4-10): on the first family one more place, no
    false loop. Two (eleventh round): first family the same places (42/50, held out 18/20)
    and a shorter queue (132 -> 86 entries, 119 -> 75 of them false: candidates a step or
    two off a place now close it), looked-at second family seeds 5-42 555 -> 558/647 and
    55-96 604 -> 611/723, no new false loop. The seventh round's walk from neighbour to
    neighbour up to ``place_radius`` met three false loops on a texture repeated along a
    block (measured 0.22-0.33 steps); stage 7's measured share, added after it, is part of
    this test. Costs up to 24 more two-view fits per such match (cached with the others).

    Nineteenth round: the pairs stage 4 set aside. Stage 4 keeps of a place the pair with the
    best descriptor evidence and sets aside the others of the place; the pair whose views
    are closest can be among them, further along than two nodes (the start of a block lap
    seen again four nodes before the lap's end, a crossing whose best descriptor pair is
    three nodes past it), or beside a match with too few inliers to be given the 24
    neighbours. The pairs set aside were retrieved and passed stage 4's score, so they are
    the descriptor's own candidates for this place, no new number, and each costs one
    two-view fit. A pair set aside can lie within ``place_radius`` of another match's place
    too; it does not give a place that has an automatic loop a second one. First family
    (seeds 0-4): the same places (42/50), no false loop, queue 75 -> 74 entries. Looked-at
    second family: 157-171 the same places (224/253), 190-201 169 -> 171/199, 202-219
    273 -> 276/335, no false loop."""
    m = node_rows.size
    todo = np.flatnonzero(status != "auto")
    if features is None or todo.size == 0:
        return c, status
    na, nb, owner = _beside(c, todo[c.inliers[todo] >= params.auto_inliers], params.place_radius // 2)
    sa, sb, so = _set_aside_for(c, todo, set_aside, params.place_radius)
    # each (owner, pair) once; a pair both beside its owner and set aside for it counts as beside
    pairs = np.stack([np.concatenate([owner, so]), np.concatenate([na, sa]), np.concatenate([nb, sb])], axis=1)
    aside = np.concatenate([np.zeros(owner.size, bool), np.ones(so.size, bool)])
    _, first = np.unique(pairs, axis=0, return_index=True)
    owner, na, nb, aside = pairs[first, 0], pairs[first, 1], pairs[first, 2], aside[first]
    ok = (na >= 0) & (nb < m) & (nb - na > params.neighbor_node_num)
    na, nb, owner, aside = na[ok], nb[ok], owner[ok], aside[ok]
    if owner.size == 0:
        return c, status
    cos, score = calibrate(v, stats, na, nb)
    n = Matches(a=na, b=nb, cosine=cos, score=score)
    n.support, n.direction = support(v, stats, na, nb, params)
    measure(n, features, node_rows, shifts, frame_width, params, cache)
    n.confidence = confidence(n)
    close = tiers(n, params, share_steps=False) == "auto"      # by the measured distance alone
    c, status = c.take(np.arange(len(c))), status.copy()
    # A pair set aside may lie nearer another match's place than its owner's: a match does
    # not move to one within place_radius of an automatic loop (the most confident moves
    # first), so that a place closed already does not get a second loop through them.
    closed = _automatic_places(c, status, params.place_radius)
    for i in todo[np.lexsort((c.b[todo], c.a[todo], -c.confidence[todo]))]:
        mine = np.flatnonzero(close & (owner == i))
        mine = mine[np.argsort(n.distance_steps[mine], kind="stable")]
        free = [j for j in mine.tolist() if not aside[j] or not closed.near(int(na[j]), int(nb[j]))]
        if free:
            j = free[0]
            closed.add(int(na[j]), int(nb[j]))
            for key, value in n.__dict__.items():
                if value is not None and getattr(c, key) is not None:
                    getattr(c, key)[i] = value[j]
            status[i] = "auto"
    return c, status


def _beside(c: Matches, owners: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, owner) of every pair up to ``half`` nodes beside each match ``owners`` (on
    either end or both; the match itself left out), not yet checked against the recording."""
    reach = np.arange(-half, half + 1)
    da, db = (d.ravel() for d in np.meshgrid(reach, reach))
    beside = (da != 0) | (db != 0)
    da, db = da[beside], db[beside]
    return ((c.a[owners, None] + da).ravel(), (c.b[owners, None] + db).ravel(),
            np.repeat(owners, da.size))


def _set_aside_for(c: Matches, todo: np.ndarray, set_aside: Matches, radius: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, owner) of the matches stage 4 set aside for a match in ``todo``: of the kept
    matches within ``radius`` nodes of it on both ends, the one stage 4 ranks first (score
    and positive support; ties to the earlier pair), where that one is in ``todo`` (a pair
    set aside for an automatic loop belongs to a place already closed)."""
    empty = np.zeros(0, np.int64)
    if set_aside is None or len(set_aside) == 0 or todo.size == 0:
        return empty, empty, empty
    rank = _descriptor_rank(c)
    kept = _PlaceGrid(radius)
    for i in range(len(c)):
        kept.add(int(c.a[i]), int(c.b[i]), i)
    in_todo = np.zeros(len(c), bool)
    in_todo[todo] = True
    out = []
    for sa, sb in zip(set_aside.a.tolist(), set_aside.b.tolist()):
        near = kept.near(sa, sb)
        if near:
            first = min(near, key=lambda i: (-rank[i], int(c.a[i]), int(c.b[i])))
            if in_todo[first]:
                out.append((sa, sb, first))
    if not out:
        return empty, empty, empty
    a, b, owner = (np.asarray(x, np.int64) for x in zip(*out))
    return a, b, owner


# Heading drift per node step along the path, degrees (consecutive alignments err by a few
# degrees; the tolerance of a cycle grows with the square root of the path it runs along).
DRIFT_PER_STEP_DEG = 2.0


def path_headings(features, columns, node_rows: np.ndarray, shifts: np.ndarray, frame_width: int,
                  cache: dict) -> Optional[np.ndarray]:
    """Heading of every node relative to node 0, degrees, summed from consecutive relative
    yaws: two-view geometry where features exist (a robot turning on the spot between two
    nodes turns the view by 100 degrees or more, which column alignment of rotation-alike
    corridors gets wrong: 122-degree turns read as 0-20 on the second family; a step whose
    model turns more than a quarter turn is read again as planar motion, ``_turns_read``),
    column alignment for steps without a model or without features; None without either."""
    m = node_rows.size
    if m < 2:
        return np.zeros(m)
    steps = np.arange(m - 1)
    yaw = np.full(m - 1, np.nan)
    if features is not None:
        yaw = _step_geometry(features, node_rows, shifts, frame_width, cache)[:, 3]
        yaw = original_yaw(yaw, shifts[steps], shifts[steps + 1], frame_width)
    if columns is not None and not np.isfinite(yaw).all():
        yaw = np.where(np.isfinite(yaw), yaw, column_yaw(columns, steps, steps + 1, shifts, frame_width))
    if features is None and columns is None:
        return None
    return np.concatenate([[0.0], np.cumsum(np.nan_to_num(yaw))])


def column_yaw(columns, a: np.ndarray, b: np.ndarray, shifts: np.ndarray, frame_width: int) -> np.ndarray:
    """Relative heading of the original frames of node pairs (a, b) from their column
    signatures (``engine.verify``): where geometry gives none."""
    from .verify import align_nodes, pair_yaw

    _, sh = align_nodes(columns, a, b)
    return pair_yaw(sh, columns.shape[1], shifts[a], shifts[b], frame_width)


def original_yaw(yaw_shifted: np.ndarray, shift_a: np.ndarray, shift_b: np.ndarray, frame_width: int) -> np.ndarray:
    """Relative heading of the original frames from that of the panorama-shifted ones."""
    if frame_width <= 0:
        return np.asarray(yaw_shifted, np.float64)
    deg = np.asarray(yaw_shifted, np.float64) + (np.asarray(shift_b) - np.asarray(shift_a)) * 360.0 / frame_width
    return _wrap(deg)


def _wrap(deg):
    return (np.asarray(deg, np.float64) + 180.0) % 360.0 - 180.0


def _heading_tolerance(steps, params: MapParams) -> tuple[np.ndarray, np.ndarray]:
    """Degrees a cycle of loops and ``steps`` node steps of path may miss closing
    (``heading_tol`` plus the drift along the path, growing with the square root of its
    steps), and whether the cycle can be judged at all (a tolerance over 90 degrees says
    nothing)."""
    tol = params.heading_tol + DRIFT_PER_STEP_DEG * np.sqrt(steps)
    return tol, tol <= 90.0


def _cycle_tolerance(a: np.ndarray, b: np.ndarray, params: MapParams) -> tuple[np.ndarray, np.ndarray]:
    """Stage 8's test for every pair of loops (a[i], b[i]), (a[j], b[j]): ``_heading_tolerance``
    of the path between them. Stage 8a asks the same question of the loops across a step."""
    return _heading_tolerance(np.abs(a[:, None] - a[None, :]) + np.abs(b[:, None] - b[None, :]), params)


def consistency(c: Matches, status: np.ndarray, headings: Optional[np.ndarray], params: MapParams) -> np.ndarray:
    """Stage 8: demote automatic loops whose heading disagrees with the loops around them.

    For loops (a1, b1) and (a2, b2) the cycle a1 -> a2 (path) -> b2 (loop) -> b1 (path) -> a1
    (loop) must close: ``yaw1 - (H[b1] - H[a1])`` equals ``yaw2 - (H[b2] - H[a2])`` up to
    ``heading_tol`` plus the drift along the path between them (``DRIFT_PER_STEP_DEG`` per
    node, growing with the square root of the steps). Pairs too far apart for the test to mean
    anything (tolerance over 90 degrees) are not compared. As in PCM, the largest mutually
    consistent set wins, not the single most confident loop: loops are taken in order of the
    confidence of all loops that agree with them, and one that disagrees with a loop already
    taken and agrees with none goes back to "candidate" (a person decides)."""
    out = status.copy()
    if headings is None:
        return out
    auto = np.flatnonzero((status == "auto") & np.isfinite(c.yaw))
    if auto.size < 2:
        return out
    a, b = c.a[auto], c.b[auto]
    offset = _wrap(c.yaw[auto] - (headings[b] - headings[a]))
    tol, comparable = _cycle_tolerance(a, b, params)
    err = np.abs(_wrap(offset[:, None] - offset[None, :]))
    agree = comparable & (err <= tol)
    disagree = comparable & ~agree
    weight = np.where(agree, c.confidence[auto][None, :], 0.0).sum(axis=1)
    taken = np.zeros(auto.size, bool)
    for k in np.argsort(-weight, kind="stable"):
        if disagree[k, taken].any() and not agree[k, taken].any():
            out[auto[k]] = "candidate"
        else:
            taken[k] = True
    return out


def half_turn_steps(headings: np.ndarray, params: MapParams) -> np.ndarray:
    """Path steps (k: node k to k + 1) read as a half turn, within ``heading_tol`` of 180
    degrees: the reading stages 8a and 9a both doubt."""
    return np.flatnonzero(np.abs(_wrap(np.diff(headings))) >= 180.0 - params.heading_tol)


def half_turns(c: Matches, status: np.ndarray, headings: Optional[np.ndarray],
               params: MapParams) -> tuple[Optional[np.ndarray], np.ndarray]:
    """Stage 8a: path steps whose half turn the loops overrule; the headings without it, and
    those steps.

    Two views of a scene that looks the same turned half way round (two facing walls with
    the same picture, a symmetric corridor) fit a model turned by 180 degrees as well as the
    right one, and a straight step can read as a half turn. Every heading after it is then
    half a turn off, and stage 8 sees two groups of loops, each consistent within itself,
    that disagree by 180 degrees: those whose path runs over the step and those whose path
    does not (the second family, seeds 32, 36, 39, 41, 44, 47: one such step each, 19-72
    inliers, where a node's loops on both sides were then sent to the queue). A step that
    measured a half turn (within ``heading_tol`` of 180 degrees) is taken as straight when
    that makes more pairs of automatic loops across it agree (stage 8's test) than agreed
    before, and at least two loops on each side agree with one on the other: one loop against
    one is no majority, and a lone wrong loop cannot turn the path to fit itself. Steps are
    taken one at a time, the largest gain first. No new number: stage 8's tolerance, and two
    as the least that is a majority of more than one voice. A robot that really turned on
    the spot keeps its half turn: the loops across such a step agree with it.
    Tried in the fifth round and dropped: any step, turned where that made two more pairs
    agree; it let a false loop through on the second family's seeds 17-18. Here the step must
    read as a half turn itself; with that, no false loop that was not there without it on the
    first family, seeds 5-42 or the held-out seeds 67-72 (README, "What this shows")."""
    none = np.zeros(0, np.int64)
    if headings is None or headings.size < 2:
        return headings, none
    auto = np.flatnonzero((status == "auto") & np.isfinite(c.yaw))
    half = half_turn_steps(headings, params)
    if auto.size < 4 or half.size == 0:
        return headings, none
    a, b = c.a[auto], c.b[auto]
    tol, comparable = _cycle_tolerance(a, b, params)
    out, overruled = headings.astype(np.float64).copy(), []
    while True:
        offset = _wrap(c.yaw[auto] - (out[b] - out[a]))
        diff = offset[:, None] - offset[None, :]
        agree_now = comparable & (np.abs(_wrap(diff)) <= tol)
        agree_turned = comparable & (np.abs(_wrap(diff + 180.0)) <= tol)
        best, best_gain = -1, 0
        for k in half:
            if k in overruled:
                continue
            over = (a <= k) & (k < b)
            across = over[:, None] != over[None, :]
            after = agree_turned & across
            gain = int(after.sum() - (agree_now & across).sum()) // 2
            joined = after.any(axis=1)
            if gain > best_gain and (joined & over).sum() >= 2 and (joined & ~over).sum() >= 2:
                best, best_gain = int(k), gain
        if best < 0:
            return out, np.asarray(overruled, np.int64)
        out[best + 1:] += 180.0
        overruled.append(best)


# A node step whose two views show less parallax than this (``engine.sphere.parallax``, the
# 90th percentile of how far the matched points moved beyond the turn, degrees) is read as
# the camera turning where it stood: no distance in dead reckoning. A robot that turns on
# the spot cuts a node or two while it turns (the view changes), and each of them counted
# as a whole step in a direction the essential model cannot know (no baseline), which bent
# short loops round a tight turn by up to two steps. First synthetic family (seeds 0-4):
# every one of the 5,198 steps at least half a node step long shows at least 2.97 degrees
# (outdoors, where near points are fewest); its one step that did not move, 1.47 degrees
# (and two fitted as pure rotations, which show less than the inlier threshold): 2.5, the
# round number between. The second family (seeds 157-162, checked afterwards): steps of at
# least half a node step 3.67 or more, and 101 of its 104 unmoved steps fitted with an
# essential model under 2.5 (21 more fitted as pure rotations).
STILL_PARALLAX_DEG = 2.5


def path_track(features, node_rows: np.ndarray, shifts: np.ndarray, frame_width: int,
               headings: Optional[np.ndarray], cache: dict, overruled: np.ndarray = ()) -> Optional[np.ndarray]:
    """Dead-reckoned node positions (m, 2), in node steps, or None without features.

    Each step from node i to i + 1 is one unit long (nodes are cut where the view has
    changed by about the same amount, and samples come at a steady rate), or none where its
    views show no parallax (``STILL_PARALLAX_DEG``: the camera turned where it stood), in
    the direction the essential model of the pair puts i + 1 seen from i
    (``engine.sphere.motion_azimuth``, turned by i's heading); where the pair has no
    essential model the direction of the step before is kept (a robot keeps moving the way
    it moved); so too at the ``overruled`` steps (stage 8a: their model was the wrong one).
    On the first synthetic family (seeds 0-4) the path between the two visits of a place
    misses meeting by at most 2 steps on short returns and 0.175 of its length beyond that
    (a curve indoors read 31 degrees short; 0.08 elsewhere, since the seventeenth round's
    sign of the motion, ``engine.sphere._decompose``; 0.185 before still steps counted no
    distance): the numbers of ``closure_slack`` and ``closure_rate``."""
    if features is None or headings is None or node_rows.size < 2:
        return None
    steps = np.arange(node_rows.size - 1)
    geo = _step_geometry(features, node_rows, shifts, frame_width, cache)
    motion = geo[:, 4].copy()                                          # the cache stays as it is
    if frame_width > 0:   # azimuths of the shifted frames to the original ones
        motion = motion - shifts[steps] * 360.0 / frame_width
    motion[np.asarray(overruled, np.int64)] = np.nan
    known = np.isfinite(motion)
    if not known.any():
        return None
    last = np.maximum.accumulate(np.where(known, steps, -1))
    motion = np.where(last >= 0, motion[np.maximum(last, 0)], motion[known][0])
    angle = np.radians(headings[steps] + motion)
    length = np.where(geo[:, 6] < STILL_PARALLAX_DEG, 0.0, 1.0)       # NaN (no model): a step
    xy = np.cumsum(length[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1), axis=0)
    return np.concatenate([np.zeros((1, 2)), xy])


def reckoning_tolerance(steps, params: MapParams):
    """Node steps dead reckoning may be off after a path of ``steps`` node steps:
    ``closure_slack + closure_rate * steps`` (stage 9 for a loop's path, stage 9b for the two
    stretches between two loops)."""
    return params.closure_slack + params.closure_rate * steps


def _comes_back(c: Matches, track: np.ndarray, params: MapParams) -> np.ndarray:
    """Stage 9's test of every loop on ``track``: dead reckoning puts its two ends within
    ``reckoning_tolerance`` of the steps between them (stages 8b and 9a weigh other readings
    of the path with it)."""
    return np.linalg.norm(track[c.b] - track[c.a], axis=1) <= reckoning_tolerance(c.b - c.a, params)


def closure(c: Matches, status: np.ndarray, params: MapParams) -> np.ndarray:
    """Stage 9: the path must come back: demote automatic loops whose path does not, and
    drop candidates whose path does not.

    A loop (a, b) says the path from a to b ends where it started; dead reckoning
    (``path_track``) says how far apart its ends are, ``c.closure`` node steps (NaN where
    unknown: nothing changes). More than ``closure_slack + closure_rate * (b - a)`` steps
    and the loop joins two places that only look alike (a copied facade 80 m down the same
    street): appearance and geometry cannot tell an exact copy from a revisit, the path can.
    An automatic loop there goes back to "candidate" (strong evidence against the path: a
    person decides); a candidate there is dropped (weak evidence and the path against it:
    nothing to review). On the first synthetic family (seeds 0-4) no automatic loop within
    1 m of its place misses by more than 0.175 of its path beyond ``closure_slack``, where
    the tolerance allows 0.2 (``closure_rate``); on the second family (seeds 157-171,
    checked afterwards) 5 of 1,763 do (turns misread), and the false automatic loop that
    a rate of 0.6 let through (a figure eight's look-alike side street 35 m away) misses by
    0.25 (``benchmarks/results/closure_rate_seventeenth.md``)."""
    out = status.copy()
    far = c.closure > reckoning_tolerance(c.b - c.a, params)   # NaN: False
    out[(status == "candidate") & far] = ""
    out[(status == "auto") & far] = "candidate"
    return out


def straightened_tracks(features, node_rows: np.ndarray, shifts: np.ndarray, frame_width: int,
                        headings: np.ndarray, cache: dict, overruled: np.ndarray,
                        params: MapParams) -> dict[int, np.ndarray]:
    """For each step the path reads as a half turn (``half_turn_steps``; not one stage 8a
    overruled), the dead-reckoned track (``path_track``) with that step read
    straight instead: what stage 9a compares each loop's closure with."""
    out = {}
    for k in half_turn_steps(headings, params):
        if k in overruled:
            continue
        track = path_track(features, node_rows, shifts, frame_width, read_straight(headings, k), cache,
                           np.append(overruled, k))
        if track is not None:
            out[int(k)] = track
    return out


def read_straight(headings: np.ndarray, *steps: int) -> np.ndarray:
    """The path's headings with each of ``steps`` (k: node k to k + 1) turned back by half a turn."""
    out = np.asarray(headings, np.float64).copy()
    for k in steps:
        out[k + 1:] -= 180.0
    return out


def _heading_agrees(c: Matches, headings: np.ndarray, params: MapParams) -> tuple[np.ndarray, np.ndarray]:
    """Stage 8's test for the cycle of one loop and the path between its ends: the loop's
    ``yaw`` equals the path's turn from a to b up to ``heading_tol`` plus the drift along the
    path (``_heading_tolerance``; ``(agrees, comparable)``, NaN yaw not comparable)."""
    tol, comparable = _heading_tolerance(c.b - c.a, params)
    comparable = comparable & np.isfinite(c.yaw)
    return comparable & (np.abs(_wrap(c.yaw - (headings[c.b] - headings[c.a]))) <= tol), comparable


def straight_for_a_loop(c: Matches, status: np.ndarray, headings: Optional[np.ndarray],
                        track: Optional[np.ndarray], options: dict[tuple[int, ...], np.ndarray],
                        params: MapParams) -> Optional[tuple[int, ...]]:
    """Stage 8b: the steps read as half turns that the path is to read straight, or None.

    Stage 8a turns such a step back where two or more loops on each side agree only
    without it, and a crossing passed once more has one loop: the second family's crossing
    returns of seeds 196, 197, 199, 203, 208 and 210 each cross one straight step read as a
    half turn (seed 196: 63 inliers, a 179-degree turn, the planar reading agreeing), which
    folds the path: dead reckoning puts the crossing's two visits 46-61 steps apart on paths
    of 116-138, and stage 9 sends the loop to the queue. A loop has two voices about the
    path between its ends, each its own stage's test: where it comes back (stage 9:
    ``closure_slack + closure_rate`` per step) and how it is turned (stage 8, for the cycle
    of the loop and its path). A step is read straight when an automatic loop across it
    passes both only with the step straight (``options``: the tracks of
    ``straight_options``), and no automatic loop across it passes either only with the
    turn: a real turn on the spot (a reverse drive's U-turn) is needed by every loop across
    it. One reading per call, the one most loops ask for (a single step where as many ask
    for it); the caller reads it straight and asks again. No new number: stages 8 and 9's
    tolerances. Two consecutive half-turn steps are also tried together (twenty-first
    round): two straight steps misread on the way undo each other's heading,
    so a loop across both agrees in heading only with both turns or with neither, but the
    positions between them are folded and the path does not come back (the second family's
    seed 232: a crossing's return 0.22 m apart, steps 82 and 116, closure 73 steps). The
    same two tests, for the two steps read straight together; a loop across only one of
    them is turned round by it and then needs the turns, which keeps them.
    A false loop could turn a path to fit itself only by falling, once straightened, within
    stage 9's reach of its place and stage 8's of its heading, where no loop keeps the turn.
    First family (seeds 0-4, held out 300-301): never applies (no automatic loop asks for a
    step straight), the same places and queue. Looked-at second family: 157-189
    502 -> 508/560 places, 190-219 447 -> 454/534, no false loop; held-out 226-231, mapped
    once: 89/97 (88 with the code before), no false loop
    (``benchmarks/results/families_twentieth.md``)."""
    if track is None or headings is None or not options:
        return None
    auto = status == "auto"
    comes_back = _comes_back(c, track, params)
    turned, comparable = _heading_agrees(c, headings, params)
    best, most = None, 0
    for steps, straight in sorted(options.items(), key=lambda kv: len(kv[0])):   # one step before two
        across = np.zeros(len(c), bool)
        for k in steps:
            across |= auto & (c.a <= k) & (k < c.b)
        comes_back_straight = _comes_back(c, straight, params)
        agrees_straight, _ = _heading_agrees(c, read_straight(headings, *steps), params)
        asks = across & comes_back_straight & ~comes_back & agrees_straight
        needs = across & ((comes_back & ~comes_back_straight) | (comparable & turned & ~agrees_straight))
        if int(asks.sum()) > most and not needs.any():
            best, most = tuple(int(k) for k in steps), int(asks.sum())
    return best


def straight_options(c: Matches, status: np.ndarray, features, node_rows: np.ndarray, shifts: np.ndarray,
                     frame_width: int, headings: Optional[np.ndarray], track: Optional[np.ndarray],
                     straightened: dict[int, np.ndarray], cache: dict, overruled: np.ndarray,
                     params: MapParams) -> dict[tuple[int, ...], np.ndarray]:
    """Stage 8b's readings to weigh: each half-turn step read straight alone
    (``straightened``) and each two consecutive ones read straight together where an
    automatic loop across both does not come back now (only such a loop can ask for them;
    consecutive, so that the tracks to compute grow with the half turns, not their square)."""
    options = {(k,): t for k, t in straightened.items()}
    if track is None or len(straightened) < 2:
        return options
    far = (status == "auto") & ~_comes_back(c, track, params)
    steps = sorted(straightened)
    for k1, k2 in zip(steps[:-1], steps[1:]):
        if (far & (c.a <= k1) & (k2 < c.b)).any():
            both = path_track(features, node_rows, shifts, frame_width, read_straight(headings, k1, k2), cache,
                              np.append(overruled, [k1, k2]))
            if both is not None:
                options[(k1, k2)] = both
    return options


def lone_turns(c: Matches, status: np.ndarray, straightened: Optional[dict[int, np.ndarray]],
               params: MapParams) -> np.ndarray:
    """Stage 9a: an automatic loop whose path comes back only through a half turn that no
    other loop needs goes back to "candidate".

    A step read as a half turn (within ``heading_tol`` of 180 degrees, as stage 8a) is the
    one reading of the path that two views of a symmetric scene cannot settle: a straight
    step in a corridor that looks the same both ways fits a model turned round as well as
    the right one (stage 8a), and the planar reading agrees with it. Every position after
    such a step is then folded back, and a pair of look-alike views far apart along a
    straight corridor seems to close (the second family's held-out seeds 139-144: a
    crossing's nodes 24 m apart, dead reckoning putting them 2.2 steps apart through one
    misread step). ``straightened`` holds, for each half-turn step, the dead-reckoned
    track with that step read straight (``straightened_tracks``). A loop that closes (stage
    9) with the turn and not without it needs the turn; a real turn on the spot (a reverse
    drive's U-turn) is needed by every loop across it, so the turn stands when at least two
    loops need it, and a lone loop cannot keep a doubtful turn to fit itself (stage 8a's
    rule turned round: two, the least that is a majority of more than one voice). No new
    number."""
    out = status.copy()
    if not straightened:     # no geometry, or no step read as a half turn
        return out
    auto = (status == "auto") & np.isfinite(c.closure)
    tol = reckoning_tolerance(c.b - c.a, params)
    for k, track in straightened.items():
        needs = auto & (c.a <= k) & (k < c.b) & (c.closure <= tol) & ~_comes_back(c, track, params)
        if needs.sum() < 2:
            out[needs] = "candidate"
    return out


def lengths(c: Matches, status: np.ndarray, track: Optional[np.ndarray], params: MapParams) -> np.ndarray:
    """Stage 9b: two automatic loops that cannot hold together both go back to "candidate".

    Two loops (a1, b1) and (a2, b2) say that a1 and b1 are one place and a2 and b2 are one
    place, so the path from a1 to a2 and the path from b1 to b2 join the same two places:
    their ends lie equally far apart. Dead reckoning (``path_track``, in node steps) may miss
    by what stage 9 allows a path of that length, ``closure_slack + closure_rate`` times the
    steps of the two stretches; a pair of loops whose stretches differ by more cannot both be
    right. Typical: one node joined to two nodes of another pass seven steps apart (a reverse
    drive on the second family, seed 58: the true pair and one 5.9 m off with fewer inliers).
    This is the translation half of the PCM idea, stage 8 being its rotation half; lengths, not
    vectors, are compared, so the heading between the two passes does not enter.
    Which of the two is wrong the path cannot say, and neither can the evidence: until the
    twelfth round the more confident loop stayed, which was right on seeds 58 and 104 and
    wrong on seed 105 (two look-alike rooms 12 m apart, each joined to the other's place with
    more confidence than the true loop beside them: two false loops in the map). A false loop
    breaks the map, a true loop in the queue costs a person one click: both go to the queue.
    No new number: stage 9's tolerance, chosen on the first synthetic family, where (seeds 0-4)
    none of the 366 automatic loops conflicts with another. Memory is one row of the automatic
    loops at a time (a large map can hold many loops)."""
    out = status.copy()
    auto = np.flatnonzero(status == "auto")
    if track is None or auto.size < 2:
        return out
    a, b = c.a[auto], c.b[auto]
    at_a, at_b = track[a], track[b]
    for k in auto:
        apart_a = np.linalg.norm(at_a - track[c.a[k]], axis=1)
        apart_b = np.linalg.norm(at_b - track[c.b[k]], axis=1)
        steps = np.abs(a - c.a[k]) + np.abs(b - c.b[k])   # 0 for k itself: never a conflict
        if (np.abs(apart_a - apart_b) > reckoning_tolerance(steps, params)).any():
            out[k] = "candidate"
    return out


def path_checks(c: Matches, status: np.ndarray, headings: Optional[np.ndarray], track: Optional[np.ndarray],
                params: MapParams, straightened: Optional[dict[int, np.ndarray]] = None) -> np.ndarray:
    """Stages 9, 9a, 8 and 9b in this order: each loop alone against its path (``straightened``:
    the path with each half turn read straight, for stage 9a), then the headings of the loops
    that passed against each other, then their lengths.

    A loop the path rejects does not vote on headings: look-alike views of a scene that looks
    the same turned round make false loops turned by 180 degrees, all alike, so that together
    they outvote a crossing's one true loop (the second family, seeds 36, 44 and 47). Tried in
    the eighth round and dropped then: with the path's headings still carrying half turns read
    at straight steps, dead reckoning let a false loop through and stage 8 had been what
    stopped it (seeds 31-42). Kept in the ninth round, with the steps read again as planar
    motion (``_turns_read``) and stage 8a: first family unchanged; seeds 5-30 381/446 with no
    false loop (380 and one with stage 8 first); seeds 31-42 unchanged (169/201)."""
    status = closure(c, status, params)                                # 9
    status = lone_turns(c, status, straightened, params)               # 9a
    status = consistency(c, status, headings, params)                  # 8
    return lengths(c, status, track, params)                           # 9b


def closed_places(c: Matches, status: np.ndarray, params: MapParams) -> np.ndarray:
    """Stage 10: a candidate within ``place_radius`` nodes of an automatic loop on both ends
    is dropped from the queue: its place has its loop.

    Stage 4 keeps one match per place (no two kept matches within ``place_radius`` on both
    ends), but stage 7b then moves a match up to half that radius, or to a pair stage 4 set
    aside, so an automatic loop can come to lie beside a candidate of its own place. Such a
    candidate asks a person about a place the map has closed already. No new number: stage
    4's radius. First family (seeds 0-4): 16 of the queue's 74 entries lie there, none of
    them a same-place pair, so no place reached only through the queue is lost (queue 74 ->
    58). The same on the second family's looked-at seeds 190-195 (15 of 301) and 238-240 (22
    of 199); over seeds 157-249 no place found with the queue was lost."""
    auto = np.flatnonzero(status == "auto")
    queue = np.flatnonzero(status == "candidate")
    if auto.size == 0 or queue.size == 0:
        return status
    closed = _automatic_places(c, status, params.place_radius)
    out = status.copy()
    for i in queue.tolist():
        if closed.near(int(c.a[i]), int(c.b[i])):
            out[i] = ""
    return out


# ----------------------------------------------------------------------------- the method

def detect_loops(vectors: np.ndarray, params: MapParams, *, node_rows: np.ndarray,
                 features=None, columns=None, shifts=None, frame_width: int = 0,
                 cache: Optional[dict] = None) -> list[LoopCandidate]:
    """The ``verified`` method on node descriptors ``vectors`` (m, d): stages 1-10.

    ``node_rows`` are the descriptor rows of the nodes (features are per row); ``features``
    (``engine.features.FeatureTable``), ``columns`` and ``shifts`` are optional: without
    features there is no geometry stage and automatic loops need score and support."""
    cache = {} if cache is None else cache
    v = np.asarray(vectors, np.float32)
    m = v.shape[0]
    node_rows = np.asarray(node_rows, np.int64)
    shifts = np.zeros(m, np.int64) if shifts is None else np.asarray(shifts, np.int64)
    if m <= params.neighbor_node_num + 1:
        return []
    a, b = retrieve(v, params, cache)                                  # 1
    stats = background(v, params, cache)
    cos, score = calibrate(v, stats, a, b)                             # 2
    c = Matches(a=a, b=b, cosine=cos, score=score)
    c.support, c.direction = support(v, stats, a, b, params)          # 3
    sup = np.nan_to_num(c.support, nan=-np.inf)
    c = c.take((c.score >= params.candidate_z - GEOMETRY_MARGIN_Z)
               | (sup >= params.candidate_z - GEOMETRY_MARGIN_Z))
    c.confidence = _descriptor_rank(c)
    kept = one_per_place(c, params.place_radius)                       # 4
    set_aside, c = c.take(~kept), c.take(kept)
    measure(c, features, node_rows, shifts, frame_width, params, cache)   # 5
    if columns is not None and len(c):
        c.yaw = np.where(np.isfinite(c.yaw), c.yaw, column_yaw(columns, c.a, c.b, shifts, frame_width))
    c.confidence = confidence(c)                                       # 6
    status = tiers(c, params)                                          # 7
    c, status = nearest(c, status, set_aside, v, stats, features, node_rows, shifts, frame_width,
                        params, cache)                                 # 7b
    headings = path_headings(features, columns, node_rows, shifts, frame_width, cache)
    headings, overruled = half_turns(c, status, headings, params)     # 8a
    track, straightened = _tracks(features, node_rows, shifts, frame_width, headings, cache, overruled, params)
    while True:                                                                        # 8b
        options = straight_options(c, status, features, node_rows, shifts, frame_width, headings, track,
                                   straightened, cache, overruled, params)
        steps = straight_for_a_loop(c, status, headings, track, options, params)
        if steps is None:
            break
        headings, overruled = read_straight(headings, *steps), np.append(overruled, steps).astype(np.int64)
        track, straightened = _tracks(features, node_rows, shifts, frame_width, headings, cache, overruled, params)
    c.closure = np.full(len(c), np.nan) if track is None else np.linalg.norm(track[c.b] - track[c.a], axis=1)
    status = path_checks(c, status, headings, track, params, straightened)   # 9, 9a, 8, 9b
    status = closed_places(c, status, params)                          # 10
    out = []
    for i in np.flatnonzero(status != ""):
        out.append(LoopCandidate(
            a=int(c.a[i]), b=int(c.b[i]), similarity=float(c.cosine[i]), window_count=0,
            yaw=None if not np.isfinite(c.yaw[i]) else float(c.yaw[i]), score=float(c.score[i]),
            status=str(status[i]), evidence=_evidence(c, i)))
    out.sort(key=lambda lc: (lc.a, lc.b))
    return out


def _tracks(features, node_rows: np.ndarray, shifts: np.ndarray, frame_width: int, headings,
            cache: dict, overruled: np.ndarray, params: MapParams):
    """``path_track`` and ``straightened_tracks`` of the path as read now (None and {} without
    geometry)."""
    track = path_track(features, node_rows, shifts, frame_width, headings, cache, overruled)
    if track is None:
        return None, {}
    return track, straightened_tracks(features, node_rows, shifts, frame_width, headings, cache, overruled, params)


def _evidence(c: Matches, i: int) -> dict:
    known = c.inliers[i] >= 0
    return {"score": float(c.score[i]), "support": float(c.support[i]), "direction": int(c.direction[i]),
            "matches": int(c.matches[i]) if known else None, "inliers": int(c.inliers[i]) if known else None,
            "inlier_ratio": float(c.inlier_ratio[i]) if known else None,
            "path_inliers": int(c.path_inliers[i]) if known else None,
            "step_inliers": int(c.step_inliers[i]) if known else None,
            "confidence": float(c.confidence[i]),
            "closure": float(c.closure[i]) if np.isfinite(c.closure[i]) else None,
            "plane_share": (float(c.plane_share[i]) if c.plane_share is not None and np.isfinite(c.plane_share[i])
                            else None),
            "distance_steps": (float(c.distance_steps[i])
                               if c.distance_steps is not None and np.isfinite(c.distance_steps[i]) else None)}
