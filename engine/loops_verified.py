"""The ``verified`` loop method: calibrated scores, sequence support, yaw-aligned verification.

Beyond the paper (see README "beyond the paper"), in six steps and a final check, all on plain arrays:

1. Calibration (``engine.calibrate``): cosine similarities become z-scores against each
   node's own background of distant nodes, so thresholds mean the same for any
   descriptor and scene.
2. Sequence support: a revisit along a stretch (reverse drive, second lap, lateral
   offset) makes a run of high z-scores along a diagonal of the matrix, forwards or
   backwards. ``seq`` is the mean z over 2 * SEQ_HALF + 1 pairs on the better of the
   two diagonals through (i, j), scaled down where fewer pairs exist (the recording's
   ends). Unlike the paper's 5-node window it needs no node to pass an absolute
   threshold, and it follows the matched segment's own direction.
3. Yaw-aligned verification (``engine.verify``): every candidate pair is aligned by a
   circular shift search over column signatures; the alignment score, again as a
   z-score against distant pairs, must agree. The best shift is the loop's ``yaw``.
   A crossing at 90 degrees has no sequence support (the two passes share one point),
   so a single pair is accepted there only when both its own z-score and its
   verification are high, and its z-score is above the recording's best unrelated
   matches: verification stands in for the window count. People
   walking through a crossing can spoil the alignment, so a lone pair is also accepted
   without it when its z-score is far above the recording's own best unrelated
   matches (``lone_tail_ratio`` times the 99.9th percentile of its z-scores).
4. One loop per place: of neighbouring accepted pairs (within NMS_RADIUS nodes on both
   sides) only the strongest is kept, so the arc joins the two closest views rather
   than a fan of near-misses that are more than a metre apart; likewise of pairs on one
   diagonal line whose sequence windows overlap (the same evidence counted twice).
   In open spaces a loop with sequence support between parallel passes is then moved to
   whichever of the three parallel diagonals is the stretch itself, as in step 5
   (``_place_on_stretch``): the strongest pair can be one node off. Last, pairs on the
   diagonal line of a stronger crossing loop (yaw near 90) within half a run are dropped
   (``_off_crossing_lines``): along that line both passes are k nodes from the crossing, in
   different corridors.
5. Long runs (``run_loops``): a stretch driven twice with a lateral offset matches
   only weakly node by node (near walls are magnified, benchmarks/results/
   offset_analysis.md), but it does so for many nodes in a row. The descriptor's
   z-scores and those of a colour histogram of the horizon band (``engine.colour``,
   parallax-tolerant) are averaged over RUN_LENGTH consecutive pairs along a diagonal,
   and measured in standard deviations of the recording's own run scores. Each
   connected area above ``run_z`` (backward) or ``run_forward_z`` (forward) gives one
   loop: at its strongest pair, moved to whichever of the three parallel diagonals is
   the stretch itself (one node off is more than a metre away): in open spaces, where
   one node step moves the view only a little, the one whose views local alignment
   finds least displaced against each other (``engine.verify.local_shifts``), else the
   one with the higher mean over twice the run. It is kept only if the walls' colours
   match along it (mirror-alike corridors share the layout, not the walls) and the
   relative yaw along the run says the two passes were parallel: its axis near 0/180
   degrees (corridors look alike both ways, so the alignment may flip), and often
   enough in the diagonal's direction (in open spaces, where the alignment is
   reliable, on a third of the run). A run through a 90-degree crossing is not a
   stretch driven twice, nor are two different streets. One loop per stretch: none
   where steps 2-4 or another run already closed the place or the same diagonal line.

6. Places passed three times or more (``_visits_again``): where two loops share a place
   (laps 1-2 and 2-3), their other two visits are the same place as well, so a loop
   between them needs only moderate evidence (``again_seq_z``, ``again_verify_z``).

Last, every loop with a yaw must be possible: to pass a place again the same way the robot
must have turned a full circle in between (or made two U-turns), to pass it the other way a
U-turn. The turning between the two nodes is summed from the yaws of consecutive nodes
(``engine.verify.cumulative_turning``; errors only add to it), and loops joined by a
(nearly) straight drive are dropped: a street that looks alike along its length.

Descriptors without column signatures (files written before they existed) fall back to
steps 1, 2 and 4 with a stricter single-pair rule; loops then carry no ``yaw``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from scipy import ndimage

from .calibrate import zscores
from .robust import robust_stats
from .params import MapParams
from .verify import align_nodes, cumulative_turning, displacement, local_shifts, pair_yaw

SEQ_HALF = 2            # sequence support over 2 * SEQ_HALF + 1 pairs
NMS_RADIUS = 3          # nodes
AGAIN_RADIUS = 3        # nodes: how near two loops' ends must be to share a place (step 6)
# Forward sequence support only between nodes more than this many exclusion widths apart.
FORWARD_LAG_FACTOR = 4
# Loose gates for which pairs are verified at all (z units); the real thresholds follow.
_CANDIDATE_Z = 2.5
_MAX_CANDIDATES = 20000
_VERIFY_SAMPLE = 400    # distant pairs aligned to calibrate verification scores
TAIL_PERCENTILE = 99.9  # of a recording's z-scores: the level of its best unrelated matches
RUN_LENGTH = 15         # nodes of a long run (step 5); every pair of it must be valid
COLOUR_WEIGHT = 2.0     # weight of the colour-histogram z-score against the descriptor's
RUN_YAW_TOLERANCE = 45.0  # degrees: median deviation from parallel allowed along a run
RUN_MIN_DIRECTION = 0.125  # share of a run's pairs whose yaw must agree with its direction ...
RUN_MIN_DIRECTION_OPEN = 0.35  # ... where views change slowly (LOCAL_STEP_MAX), so the alignment is sure
SAME_LINE = 2           # runs within this many diagonals of a loop are the same stretch
# Local alignment measures how far apart two views are only where one node step moves
# the view by less than this (columns of the signatures, 2.8 degrees each): near walls
# (corridors) move further and distort, and there the descriptor's mean decides.
LOCAL_STEP_MAX = 2.8
_MAX_STEPS = 500        # node steps sampled to measure it
_PARALLEL_AXIS = 30.0   # degrees: a sequence loop this near 0 / 180 is a stretch driven twice (step 4b)
_CROSSING_AXIS = 45.0   # degrees: a loop further than this from 0 / 180 is a crossing
# To come back to a place the robot must have turned in between: a full circle (or two
# U-turns) to pass it the same way again, a U-turn to pass it the other way. Loops whose
# nodes were joined by a (nearly) straight drive are a street that looks alike along its
# length. Turning measured from consecutive alignments can fall short: three quarters of a
# circle (true same-way loops on seeds 20-254 measured 302 degrees or more, a false one after a
# single U-turn 219) and half a U-turn.
MIN_TURN_SAME_WAY = 270.0   # degrees between the nodes of a loop with yaw near 0
MIN_TURN_OTHER_WAY = 90.0   # ... and near 180
_WAY_TOLERANCE = 60.0       # degrees: how near 0 / 180 a loop's yaw must be to be checked


@dataclass(frozen=True)
class VerifiedThresholds:
    seq_z: float = 3.5        # sequence support (mean z along the diagonal)
    seq_verify_z: float = 1.5  # verification needed with sequence support ...
    seq_sum_z: float = 5.5    # ... and sequence + verification together
    single_z: float = 6.0     # a lone pair (crossing) needs this z-score ...
    single_verify_z: float = 3.0  # ... and this verification, and a z above the recording's z_tail
    near_extra_z: float = 2.0  # pairs a few nodes apart need seq + verify this much higher
    lone_z: float = 5.5       # a lone pair without verification (people hide the view) needs this z ...
    lone_tail_ratio: float = 1.45  # ... and this many times the recording's z_tail
    run_z: float = 3.8        # long runs driven the other way (std. dev. of the recording's run scores)
    run_forward_z: float = 4.6  # ... and the same way (streets driven alike resemble each other)
    run_colour_z: float = 1.1  # mean colour z along a run: the walls' colours must match, not only the layout
    again_seq_z: float = 2.5   # a place two loops already join to a third visit: sequence support ...
    again_verify_z: float = 1.0  # ... and verification for the loop between the other two


DEFAULT_THRESHOLDS = VerifiedThresholds()


@dataclass
class PairScores:
    """Scores of every candidate pair (a < b), for selection and for tuning."""
    a: np.ndarray
    b: np.ndarray
    z: np.ndarray          # calibrated single-pair similarity
    seq: np.ndarray        # sequence support
    verify: Optional[np.ndarray]  # calibrated verification score, None without columns
    shift: Optional[np.ndarray]   # best column shift of the aligned signatures
    cosine: np.ndarray
    m: int
    forward_min_lag: int = 0
    z_tail: float = np.inf  # the recording's 99.9th percentile of z: its best unrelated matches
    z_matrix: Optional[np.ndarray] = None  # (m, m) z of all pairs, temporal neighbours NaN (step 5)


def _mask_near(z: np.ndarray, exclude: int) -> None:
    """Set z to NaN for temporal neighbours |i - j| <= exclude (in place, per diagonal)."""
    m = z.shape[0]
    rows = np.arange(m)
    for lag in range(0, min(exclude, m - 1) + 1):
        z[rows[:m - lag], rows[lag:]] = np.nan
        z[rows[lag:], rows[:m - lag]] = np.nan


def _sequence_scores(z: np.ndarray, a: np.ndarray, b: np.ndarray, half: int,
                     forward_min_lag: int = 0) -> np.ndarray:
    """Mean z over (a + k, b + k) or (a + k, b - k), |k| <= half, the better direction.

    NaNs (temporal neighbours, outside the matrix) are skipped; fewer than half + 1
    valid terms give -inf. The forward direction counts only for pairs more than
    ``forward_min_lag`` apart: a forward run of pairs a few nodes apart is one stretch
    that looks alike along its length (a long uniform street), not a second visit.
    """
    m = z.shape[0]
    k = np.arange(-half, half + 1)
    best = np.full(a.size, -np.inf, np.float32)
    for sign in (1, -1):
        ii = a[:, None] + k[None, :]
        jj = b[:, None] + sign * k[None, :]
        inside = (ii >= 0) & (ii < m) & (jj >= 0) & (jj < m)
        vals = np.where(inside, z[np.clip(ii, 0, m - 1), np.clip(jj, 0, m - 1)], np.nan)
        ok = ~np.isnan(vals)
        cnt = ok.sum(axis=1)
        # Fewer terms (the recording's ends, temporal neighbours) are weaker evidence: the
        # mean is scaled by sqrt(terms / full run), as a mean of fewer z-scores spreads more.
        mean = np.where(cnt >= half + 1, np.where(ok, vals, 0.0).sum(axis=1) / np.maximum(cnt, 1)
                        * np.sqrt(cnt / k.size), -np.inf)
        if sign == 1:
            mean = np.where(b - a > forward_min_lag, mean, -np.inf)
        best = np.maximum(best, mean.astype(np.float32))
    return best


def score_pairs(node_vectors: np.ndarray, node_columns: Optional[np.ndarray], exclude: int,
                candidate_z: float = _CANDIDATE_Z,
                only_for: Optional[VerifiedThresholds] = None) -> PairScores:
    """Calibrated, sequence and verification scores of all plausible pairs.

    Cheap for thousands of nodes: the sequence score needs at least one pair of its
    diagonal run to stand out, so only the neighbourhoods (along both diagonals) of
    pairs with z >= candidate_z are scored, never the whole matrix. With ``only_for``
    given, pairs that no rule of ``select`` with those thresholds could accept are
    dropped before the (costly) alignment: ``select`` then returns the same loops.
    """
    v = np.asarray(node_vectors, dtype=np.float32)
    m = v.shape[0]
    sims = v @ v.T
    z = zscores(sims, exclude)
    _mask_near(z, exclude)
    gap = max(exclude, 1)
    sa, sb = np.nonzero(np.triu(z >= candidate_z, gap + 1))
    k = np.arange(-SEQ_HALF, SEQ_HALF + 1)
    ca = np.concatenate([(sa[:, None] + k).ravel(), (sa[:, None] + k).ravel()])
    cb = np.concatenate([(sb[:, None] + k).ravel(), (sb[:, None] - k).ravel()])
    ok = (ca >= 0) & (cb < m) & (cb > ca + gap)
    key = np.unique(ca[ok].astype(np.int64) * m + cb[ok])
    a, b = key // m, key % m
    zz = np.nan_to_num(z[a, b], nan=-np.inf)
    seq = _sequence_scores(z, a, b, SEQ_HALF, forward_min_lag=FORWARD_LAG_FACTOR * exclude)
    keep = np.maximum(zz, seq) >= candidate_z
    a, b, zz, seq = a[keep], b[keep], zz[keep], seq[keep]
    if a.size > _MAX_CANDIDATES:
        top = np.sort(np.argsort(-np.maximum(zz, seq), kind="stable")[:_MAX_CANDIDATES])
        a, b, zz, seq = a[top], b[top], zz[top], seq[top]
    if only_for is not None:   # every rule of select needs one of these
        can = (seq >= min(only_for.seq_z, only_for.again_seq_z)) | (zz >= min(only_for.single_z, only_for.lone_z))
        a, b, zz, seq = a[can], b[can], zz[can], seq[can]
    verify = shift = None
    if node_columns is not None:
        cols = np.asarray(node_columns)
        verify = np.zeros(a.size, np.float32)
        shift = np.zeros(a.size, np.int64)
        if a.size:
            ba, bb = _background_pairs(m, exclude)
            # One alignment call for candidates and background: each node's spectrum once.
            score, shift = align_nodes(cols, np.concatenate([a, ba]), np.concatenate([b, bb]))
            score, shift, back = score[:a.size], shift[:a.size], score[a.size:]
            mu, sd = robust_stats(back.astype(np.float64)) if back.size >= 10 else (0.0, 1.0)
            verify = ((score - mu) / sd).astype(np.float32)
    upper = z[np.triu_indices(m, gap + 1)]
    upper = upper[np.isfinite(upper)]
    z_tail = float(np.percentile(upper, TAIL_PERCENTILE)) if upper.size >= 100 else np.inf
    return PairScores(a.astype(np.int64), b.astype(np.int64), zz.astype(np.float32), seq, verify, shift,
                      sims[a, b], m, FORWARD_LAG_FACTOR * exclude, z_tail, z)


def _background_pairs(m: int, exclude: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``_VERIFY_SAMPLE`` random temporally distant pairs: what "different places"
    score when aligned, the reference of the verification z-scores."""
    rng = np.random.default_rng(seed)
    a = rng.integers(0, m, _VERIFY_SAMPLE * 2)
    b = rng.integers(0, m, _VERIFY_SAMPLE * 2)
    ok = np.abs(a - b) > exclude
    return a[ok][:_VERIFY_SAMPLE].astype(np.int64), b[ok][:_VERIFY_SAMPLE].astype(np.int64)


def select(ps: PairScores, th: VerifiedThresholds = DEFAULT_THRESHOLDS) -> np.ndarray:
    """Indices into ``ps`` of the accepted pairs (sequence or verified single), after NMS."""
    if ps.a.size == 0:
        return np.zeros(0, np.int64)
    if ps.verify is not None:
        with_seq = ((ps.seq >= th.seq_z) & (ps.verify >= th.seq_verify_z)
                    & (ps.seq + ps.verify >= th.seq_sum_z))
        # Pairs a few nodes apart: a corner seen from both sides mirrors like a U-turn,
        # so there the pair must stand out alone or be clearly stronger together.
        with_seq &= ((ps.b - ps.a > ps.forward_min_lag) | (ps.z >= th.single_z)
                     | (ps.seq + ps.verify >= th.seq_sum_z + th.near_extra_z))
        # ... and only above the recording's own best unrelated matches (a dead end
        # looks like every other dead end of the building).
        single = (ps.z >= th.single_z) & (ps.verify >= th.single_verify_z) & (ps.z >= ps.z_tail)
    else:  # no signatures: no verification, so ask more of both rules
        with_seq = (ps.seq >= th.seq_z + 1.0) & ((ps.b - ps.a > ps.forward_min_lag) | (ps.z >= th.single_z))
        single = ps.z >= th.single_z + 2.0
    # A lone pair far above the recording's own best unrelated matches needs no verification
    # (people walking through a crossing spoil the column alignment, not the descriptor).
    lone = ((ps.z >= th.lone_z) & (ps.z >= th.lone_tail_ratio * ps.z_tail)
            & (ps.b - ps.a > ps.forward_min_lag))
    ok = np.flatnonzero(with_seq | single | lone)
    if ok.size == 0:
        return ok
    strength = np.maximum(ps.z[ok], ps.seq[ok])
    if ps.verify is not None:
        strength = strength + ps.verify[ok]
    keep = _local_maxima(ps.a[ok], ps.b[ok], strength, NMS_RADIUS)
    ok, strength = ok[keep], strength[keep]
    # Pairs on one diagonal line whose sequence windows overlap share their evidence: only
    # the strongest stays (a 90-degree crossing's own diagonal of look-alike approaches
    # otherwise adds a second loop a few metres off).
    return ok[_line_maxima(ps.a[ok], ps.b[ok], strength, 2 * SEQ_HALF)]


def _local_maxima(a: np.ndarray, b: np.ndarray, strength: np.ndarray, radius: int) -> np.ndarray:
    """Mask of pairs that are the strongest within ``radius`` nodes on both sides (ties keep all)."""
    keep = np.ones(a.size, bool)
    order = np.argsort(a, kind="stable")
    a_s = a[order]
    for pos, idx in enumerate(order):   # accepted pairs are few; each looks at a narrow band
        lo = np.searchsorted(a_s, a[idx] - radius, "left")
        hi = np.searchsorted(a_s, a[idx] + radius, "right")
        band = order[lo:hi]
        near = band[np.abs(b[band] - b[idx]) <= radius]
        keep[idx] = strength[idx] >= strength[near].max()
    return keep


def _line_maxima(a: np.ndarray, b: np.ndarray, strength: np.ndarray, reach: int) -> np.ndarray:
    """Mask of pairs that no stronger pair beats on their diagonal line (forward b - a or
    backward a + b, within one diagonal) within ``reach`` nodes of a."""
    keep = np.ones(a.size, bool)
    for s0 in range(0, a.size, 1024):   # bounded memory on maps with many loops
        s1 = min(a.size, s0 + 1024)
        near = np.abs(a[s0:s1, None] - a[None, :]) <= reach
        line = _on_one_line(a[s0:s1], b[s0:s1], a, b)
        keep[s0:s1] = ~np.any(near & line & (strength[None, :] > strength[s0:s1, None]), axis=1)
    return keep


def _off_parallel(yaw: np.ndarray) -> np.ndarray:
    """Degrees from the nearest of 0 / 180: 0 for parallel passes, 90 for a crossing."""
    return np.abs((np.asarray(yaw) + 90.0) % 180.0 - 90.0)


def _pair_yaws(ps: PairScores, index: np.ndarray, node_shifts: np.ndarray, width: int,
               frame_width: int) -> np.ndarray:
    """``pair_yaw`` of the candidate pairs ``ps[index]``."""
    return pair_yaw(ps.shift[index], width, node_shifts[ps.a[index]], node_shifts[ps.b[index]], frame_width)


def _on_one_line(a1: np.ndarray, b1: np.ndarray, a2: np.ndarray, b2: np.ndarray) -> np.ndarray:
    """(len(a1), len(a2)) mask: pairs on one diagonal line (forward b - a or backward a + b,
    within one diagonal)."""
    return ((np.abs((b1 - a1)[:, None] - (b2 - a2)[None, :]) <= 1)
            | (np.abs((b1 + a1)[:, None] - (b2 + a2)[None, :]) <= 1))


def run_means(z: np.ndarray, length: int, sign: int) -> np.ndarray:
    """Mean of ``z`` over the run (i + k, j + sign * k), |k| <= length // 2, for every (i, j).

    -inf where any pair of the run is outside the matrix or NaN (a temporal neighbour):
    only whole runs count, so a run is never judged on a few terms at the border.
    """
    m = z.shape[0]
    h = length // 2
    padded = np.full((m + 2 * h, m + 2 * h), np.nan, np.float32)
    padded[h:h + m, h:h + m] = z
    total = np.zeros((m, m), np.float32)
    for k in range(-h, h + 1):   # the term (i + k, j + sign * k) of every run at once
        total += padded[h + k:h + k + m, h + sign * k:h + sign * k + m]
    return np.nan_to_num(total / (2 * h + 1), nan=-np.inf)


def _diagonal_means(z: np.ndarray, a: int, b: int, sign: int, half: int) -> list[float]:
    """Mean of ``z`` along the diagonal through (a, b + db), db = -1, 0, 1, over |k| <= half."""
    m = z.shape[0]
    k = np.arange(-half, half + 1)
    means = []
    for db in (-1, 0, 1):
        ii, jj = a + k, b + db + sign * k
        inside = (ii >= 0) & (ii < m) & (jj >= 0) & (jj < m)
        vals = z[ii[inside], jj[inside]]
        vals = vals[np.isfinite(vals)]
        means.append(float(vals.mean()) if vals.size else -np.inf)
    return means


def _local_alignment_works(cols: np.ndarray) -> bool:
    """Whether one node step moves the recording's views less than LOCAL_STEP_MAX columns (median)."""
    steps = np.unique(np.linspace(0, cols.shape[0] - 2, min(cols.shape[0] - 1, _MAX_STEPS)).astype(np.int64))
    _, shift = align_nodes(cols, steps, steps + 1)
    return bool(np.median(displacement(local_shifts(cols, steps, steps + 1, shift))) < LOCAL_STEP_MAX)


def _closest_diagonal(combined: np.ndarray, cols: np.ndarray, a: int, b: int, sign: int, local: bool,
                      exclude: int) -> int:
    """Which of the diagonals through (a, b - 1), (a, b), (a, b + 1) is the stretch itself: -1, 0 or 1.

    One node off is more than a metre away after a sideways offset. With ``local`` (local
    alignment can measure displacement in this recording, see ``_local_alignment_works``)
    the diagonal whose views are least displaced against each other along the run wins;
    otherwise the one with the higher mean score over twice the run. Pairs of temporal
    neighbours (a U-turn's apex: the same node on both sides) do not count, and a diagonal
    with fewer than half a run of other pairs is not chosen.
    """
    m = combined.shape[0]
    means = _diagonal_means(combined, a, b, sign, RUN_LENGTH)
    if not local:
        return int(np.argmax(means)) - 1
    h = RUN_LENGTH // 2
    apart = []
    for db in (-1, 0, 1):
        ia, ib = a + np.arange(-h, h + 1), b + db + sign * np.arange(-h, h + 1)
        ok = (ia >= 0) & (ia < m) & (ib >= 0) & (ib < m) & (np.abs(ib - ia) > exclude)
        if not np.isfinite(means[db + 1]) or np.count_nonzero(ok) <= h:
            apart.append(np.inf)
            continue
        _, shift = align_nodes(cols, ia[ok], ib[ok])
        apart.append(float(np.median(displacement(local_shifts(cols, ia[ok], ib[ok], shift)))))
    if not np.isfinite(min(apart)):
        return 0
    return int(np.argmin(apart)) - 1


def run_loops(z: np.ndarray, node_colours: np.ndarray, node_columns: np.ndarray,
              node_shifts: np.ndarray, frame_width: int, exclude: int,
              th: VerifiedThresholds = DEFAULT_THRESHOLDS,
              local: Optional[bool] = None) -> list[tuple[int, int, float, float, int]]:
    """Step 5: one (a, b, run score, yaw, direction) per long run of matching nodes, a < b.

    ``z`` is the descriptor's calibrated z-matrix (``PairScores.z_matrix``); direction is
    -1 for a backward run (driven the other way), +1 for a forward one. ``local``:
    ``_local_alignment_works`` of the columns, measured here unless given.
    """
    m = z.shape[0]
    if m < RUN_LENGTH + exclude + 2:
        return []
    col = np.asarray(node_colours, np.float32)
    zc = zscores(col @ col.T, exclude)
    combined = ((z + COLOUR_WEIGHT * zc) / np.sqrt(1.0 + COLOUR_WEIGHT ** 2)).astype(np.float32)
    _mask_near(combined, exclude)
    backward = run_means(combined, RUN_LENGTH, -1)
    forward = run_means(combined, RUN_LENGTH, 1)
    lag = np.arange(m)[None, :] - np.arange(m)[:, None]
    forward[lag <= FORWARD_LAG_FACTOR * exclude] = -np.inf   # see _sequence_scores
    score = np.maximum(backward, forward)
    valid = np.isfinite(score) & (lag > exclude)
    if np.count_nonzero(valid) < 10:
        return []
    # Run scores of a recording spread more where its views are alike all along (long
    # streets): thresholds are in standard deviations of the recording's own run scores.
    mu, sd = robust_stats(score[valid].astype(np.float64))
    is_back = backward >= forward
    above = valid & np.where(is_back, backward >= mu + th.run_z * sd, forward >= mu + th.run_forward_z * sd)
    labels, count = ndimage.label(above, structure=np.ones((3, 3), bool))
    if count == 0:
        return []
    # The strongest pair of every connected area (ties: the first in row order).
    flat = np.flatnonzero(labels)
    order = flat[np.lexsort((-score.ravel()[flat], labels.ravel()[flat]))]
    firsts = order[np.r_[True, np.diff(labels.ravel()[order]) != 0]]
    h = RUN_LENGTH // 2
    k = np.arange(-h, h + 1)
    cols = np.asarray(node_columns, np.float32)
    if local is None:
        local = _local_alignment_works(cols)
    out = []
    for pos in firsts:
        a, b = divmod(int(pos), m)
        sign = -1 if is_back[a, b] else 1
        b += _closest_diagonal(combined, cols, a, b, sign, local, exclude)
        if b <= a + exclude or b >= m:
            continue
        ra, rb = a + k, b + sign * k
        inside = (ra >= 0) & (ra < m) & (rb >= 0) & (rb < m)
        ra, rb = ra[inside], rb[inside]
        # A building whose corridors mirror each other matches in layout (the descriptor)
        # along a whole run; its walls' colours do not.
        if not np.nanmean(zc[ra, rb]) >= th.run_colour_z:
            continue
        _, shift = align_nodes(cols, ra, rb)
        yaw = pair_yaw(shift, cols.shape[1], node_shifts[ra], node_shifts[rb], frame_width)
        # Parallel passes: the yaw's axis along the run is near 0 / 180 degrees. Only the axis
        # counts, since a corridor looks alike both ways (column alignment may flip it); the
        # diagonal tells the direction. A 90-degree crossing fails here.
        off = _off_parallel(yaw)
        # ... but a run whose yaw all but never agrees with the diagonal's direction (the
        # alignment is sure the passes went the same way) is two different streets.
        heading = 180.0 if sign == -1 else 0.0
        agree = np.abs((yaw - heading + 180.0) % 360.0 - 180.0) <= RUN_YAW_TOLERANCE
        # Where views change slowly (open spaces) the alignment is seldom fooled, and must
        # agree more often: mirror-alike corners and streets there face the wrong way.
        min_direction = RUN_MIN_DIRECTION_OPEN if local else RUN_MIN_DIRECTION
        if np.median(off) <= RUN_YAW_TOLERANCE and agree.mean() >= min_direction:
            doubled = np.radians(2.0 * yaw[off <= RUN_YAW_TOLERANCE])   # axial mean of the agreeing pairs
            axis = 0.5 * np.degrees(np.arctan2(np.sin(doubled).mean(), np.cos(doubled).mean()))
            run_yaw = float((axis + heading + 180.0) % 360.0 - 180.0)
            out.append((a, b, float(score[a, b]), run_yaw, sign))
    return out


def _place_on_stretch(ps: PairScores, chosen: np.ndarray, cols: np.ndarray, node_shifts: np.ndarray,
                      frame_width: int, exclude: int, th: VerifiedThresholds) -> np.ndarray:
    """Step 4b (open spaces): move each sequence-supported loop to the parallel diagonal of
    its stretch whose views are least displaced (``_closest_diagonal`` over a run's length).

    The sequence score finds the stretch; which of three neighbouring diagonals is the
    same place is decided as for long runs, since one node off is more than a metre away.
    Only pairs whose yaw says the passes were parallel (not a crossing), and only to a
    pair that has sequence support itself (a candidate of ``ps``).
    """
    where = {(int(a), int(b)): n for n, (a, b) in enumerate(zip(ps.a, ps.b))}
    yaw = _pair_yaws(ps, chosen, node_shifts, cols.shape[1], frame_width)
    placed = []
    for c, pair_yaw_deg, off_axis in zip(chosen, yaw, _off_parallel(yaw)):
        a, b = int(ps.a[c]), int(ps.b[c])
        if ps.seq[c] < th.seq_z or off_axis > _PARALLEL_AXIS:
            placed.append(c)
            continue
        sign = -1 if abs(pair_yaw_deg) > 90.0 else 1
        db = _closest_diagonal(ps.z_matrix, cols, a, b, sign, True, exclude)
        placed.append(where.get((a, b + db), c))
    return np.unique(np.asarray(placed, np.int64))


def _off_crossing_lines(ps: PairScores, chosen: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Mask of the chosen pairs not on the diagonal line of a stronger crossing loop.

    Pairs along the diagonal line through a 90-degree crossing (yaw far from 0 / 180) are
    k nodes from the crossing along both corridors, never the same place: a 4-way crossing
    that looks alike from every side makes such a line (its mirror diagonal). ``select``
    keeps one pair per line within 2 * SEQ_HALF nodes; next to a crossing the line is
    dropped over half a run.
    """
    strength = np.maximum(ps.z[chosen], ps.seq[chosen]) + ps.verify[chosen]
    a, b = ps.a[chosen], ps.b[chosen]
    crossing = _off_parallel(yaw) > _CROSSING_AXIS
    same_line = _on_one_line(a, b, a, b)
    near = np.abs(a[:, None] - a[None, :]) <= RUN_LENGTH // 2
    stronger_crossing = crossing[None, :] & (strength[None, :] > strength[:, None])
    return ~np.any(same_line & near & stronger_crossing, axis=1)


def _same_stretch(a: int, b: int, sign: int, other, near: int) -> bool:
    """Whether loop ``other`` closes the same place or the same stretch as run (a, b)."""
    if abs(a - other.a) <= near and abs(b - other.b) <= near:
        return True
    # Same diagonal line: the same stretch driven twice, seen at another point along it.
    if sign == -1:
        return abs((a + b) - (other.a + other.b)) <= SAME_LINE
    return abs((b - a) - (other.b - other.a)) <= SAME_LINE


def verified_loops(node_vectors: np.ndarray, params: MapParams, node_columns: Optional[np.ndarray] = None,
                   node_shifts: Optional[np.ndarray] = None, frame_width: int = 0,
                   thresholds: VerifiedThresholds = DEFAULT_THRESHOLDS,
                   node_colours: Optional[np.ndarray] = None):
    """Loop candidates of the ``verified`` method, sorted by (a, b), with yaw where known.

    Step 5 (long runs) needs colour histograms, column signatures and the panorama
    shifts (for the yaw of the run); without them it is skipped.
    """
    from .loops import LoopCandidate
    from .validate import dense_nodes

    dense_nodes(int(np.asarray(node_vectors).shape[0]), "verified-rules")  # before any m x m matrix
    exclude = int(params.neighbor_node_num)
    ps = score_pairs(node_vectors, node_columns, exclude, only_for=thresholds)
    chosen = select(ps, thresholds)
    yaw = None
    local = None
    # Column signatures and panorama shifts give every pair a yaw (steps 3-6, the final check).
    has_yaw = ps.shift is not None and node_shifts is not None and frame_width > 0
    if has_yaw:
        cols = np.asarray(node_columns, np.float32)
        shifts = np.asarray(node_shifts)
        local = _local_alignment_works(cols)
        if local and chosen.size:
            chosen = _place_on_stretch(ps, chosen, cols, shifts, frame_width, exclude, thresholds)
    if has_yaw and chosen.size:
        yaw = _pair_yaws(ps, chosen, shifts, cols.shape[1], frame_width)
        keep = _off_crossing_lines(ps, chosen, yaw)
        chosen, yaw = chosen[keep], yaw[keep]
    out = []
    for k, c in enumerate(chosen):
        score = float(ps.verify[c]) if ps.verify is not None else None
        out.append(LoopCandidate(int(ps.a[c]), int(ps.b[c]), float(ps.cosine[c]), 0,
                                 yaw=None if yaw is None else float(yaw[k]), score=score))
    if params.long_runs and node_colours is not None and has_yaw:
        v = np.asarray(node_vectors, np.float32)
        near = RUN_LENGTH // 2   # one loop per stretch: skip runs whose place is already closed
        runs = run_loops(ps.z_matrix, node_colours, node_columns, shifts, frame_width, exclude, thresholds, local)
        for a, b, strength, run_yaw, sign in runs:
            if not any(_same_stretch(a, b, sign, lc, near) for lc in out):
                out.append(LoopCandidate(a, b, float(v[a] @ v[b]), 0, yaw=run_yaw, score=strength))
    if has_yaw:
        out += _visits_again(out, ps, shifts, frame_width, cols.shape[1], exclude, thresholds)
        if out:
            out = _turned_in_between(out, cumulative_turning(cols, shifts, frame_width))
    out.sort(key=lambda lc: (lc.a, lc.b))
    return out


def _visits_again(loops: list, ps: PairScores, node_shifts: np.ndarray, frame_width: int, width: int,
                  exclude: int, th: VerifiedThresholds) -> list:
    """Step 6: loops between the other visits of a place two loops already share.

    A place passed three times (a third lap) is joined by loops 1-2 and 2-3; the pair of
    visits 1 and 3 is the same place too, so near it a pair needs only moderate sequence
    support and verification (``again_seq_z``, ``again_verify_z``). Returns the new loops.
    """
    from .loops import LoopCandidate

    ok = np.flatnonzero((ps.seq >= th.again_seq_z) & (ps.verify >= th.again_verify_z))
    if len(loops) < 2 or ok.size == 0:
        return []
    strength = ps.seq[ok] + ps.verify[ok]
    ends = sorted((node, n, other) for n, lc in enumerate(loops)
                  for node, other in ((lc.a, lc.b), (lc.b, lc.a)))
    added: list = []
    for i, (node, n, other) in enumerate(ends):
        for node2, n2, other2 in ends[i + 1:]:
            if node2 - node > AGAIN_RADIUS:
                break
            p, q = sorted((other, other2))
            if n2 == n or q - p <= exclude:
                continue
            if any(abs(lc.a - p) <= AGAIN_RADIUS and abs(lc.b - q) <= AGAIN_RADIUS for lc in loops + added):
                continue
            near = np.flatnonzero((np.abs(ps.a[ok] - p) <= AGAIN_RADIUS) & (np.abs(ps.b[ok] - q) <= AGAIN_RADIUS))
            if near.size == 0:
                continue
            c = ok[near[np.argmax(strength[near])]]
            yaw = _pair_yaws(ps, np.array([c]), node_shifts, width, frame_width)
            added.append(LoopCandidate(int(ps.a[c]), int(ps.b[c]), float(ps.cosine[c]), 0, yaw=float(yaw[0]),
                                       score=float(ps.verify[c])))
    return added


def _turned_in_between(loops: list, turned: np.ndarray) -> list:
    """The loops whose nodes the robot turned enough between (see MIN_TURN_SAME_WAY)."""
    kept = []
    for lc in loops:
        if lc.yaw is not None:
            turn = turned[lc.b] - turned[lc.a]
            same_way = abs((lc.yaw + 180.0) % 360.0 - 180.0) < _WAY_TOLERANCE
            other_way = abs(lc.yaw % 360.0 - 180.0) < _WAY_TOLERANCE
            if (same_way and turn < MIN_TURN_SAME_WAY) or (other_way and turn < MIN_TURN_OTHER_WAY):
                continue
        kept.append(lc)
    return kept
