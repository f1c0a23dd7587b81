"""The ``verified`` loop method: calibrated scores, sequence support, yaw-aligned verification.

Beyond the paper (see README "beyond the paper"), in four steps, all on plain arrays:

1. Calibration (``engine.calibrate``): cosine similarities become z-scores against each
   node's own background of distant nodes, so thresholds mean the same for any
   descriptor and scene.
2. Sequence support: a revisit along a stretch (reverse drive, second lap, lateral
   offset) makes a run of high z-scores along a diagonal of the matrix, forwards or
   backwards. ``seq`` is the mean z over 2 * SEQ_HALF + 1 pairs on the better of the
   two diagonals through (i, j). Unlike the paper's 5-node window it needs no node to
   pass an absolute threshold, and it follows the matched segment's own direction.
3. Yaw-aligned verification (``engine.verify``): every candidate pair is aligned by a
   circular shift search over column signatures; the alignment score, again as a
   z-score against distant pairs, must agree. The best shift is the loop's ``yaw``.
   A crossing at 90 degrees has no sequence support (the two passes share one point),
   so a single pair is accepted there only when both its own z-score and its
   verification are high: verification stands in for the window count.
4. One loop per place: of neighbouring accepted pairs (within NMS_RADIUS nodes on both
   sides) only the strongest is kept, so the arc joins the two closest views rather
   than a fan of near-misses that are more than a metre apart.

Descriptors without column signatures (files written before they existed) fall back to
steps 1, 2 and 4 with a stricter single-pair rule; loops then carry no ``yaw``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.ndimage import maximum_filter

from .calibrate import robust_stats, zscores
from .params import MapParams
from .verify import align, pair_yaw

SEQ_HALF = 2            # sequence support over 2 * SEQ_HALF + 1 pairs
NMS_RADIUS = 2          # nodes
# Loose gates for which pairs are verified at all (z units); the real thresholds follow.
_CANDIDATE_Z = 2.0
_MAX_CANDIDATES = 20000
_VERIFY_SAMPLE = 400    # distant pairs aligned to calibrate verification scores


@dataclass(frozen=True)
class VerifiedThresholds:
    seq_z: float = 3.0        # sequence support (mean z along the diagonal)
    seq_verify_z: float = 1.5  # verification needed with sequence support ...
    seq_sum_z: float = 5.5    # ... and sequence + verification together
    single_z: float = 6.0     # a lone pair (crossing) needs this z-score ...
    single_verify_z: float = 3.0  # ... and this verification


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


def _diagonal_mean(z: np.ndarray, half: int, reverse: bool) -> np.ndarray:
    """Mean of z over (i + k, j + k) (or (i + k, j - k)) for |k| <= half, NaNs skipped."""
    m = z.shape[0]
    pad = np.full((m + 2 * half, m + 2 * half), np.nan, np.float32)
    pad[half:half + m, half:half + m] = z
    acc = np.zeros((m, m), np.float32)
    cnt = np.zeros((m, m), np.int16)
    for k in range(-half, half + 1):
        kj = -k if reverse else k
        part = pad[half + k:half + k + m, half + kj:half + kj + m]
        ok = ~np.isnan(part)
        acc += np.where(ok, part, 0.0)
        cnt += ok
    out = np.full((m, m), -np.inf, np.float32)
    enough = cnt >= half + 1
    out[enough] = acc[enough] / cnt[enough]
    return out


def score_pairs(node_vectors: np.ndarray, node_columns: Optional[np.ndarray], exclude: int,
                candidate_z: float = _CANDIDATE_Z) -> PairScores:
    """Calibrated, sequence and verification scores of all plausible pairs."""
    v = np.asarray(node_vectors, dtype=np.float32)
    m = v.shape[0]
    sims = v @ v.T
    z = zscores(sims, exclude)
    idx = np.arange(m)
    near = np.abs(idx[:, None] - idx[None, :]) <= exclude
    z[near] = np.nan
    seq = np.maximum(_diagonal_mean(z, SEQ_HALF, False), _diagonal_mean(z, SEQ_HALF, True))
    zz = np.where(np.isnan(z), -np.inf, z)
    strength = np.maximum(zz, seq)
    upper = idx[None, :] > idx[:, None] + max(exclude, 1)
    a, b = np.nonzero(upper & (strength >= candidate_z))
    if a.size > _MAX_CANDIDATES:
        keep = np.argsort(-strength[a, b], kind="stable")[:_MAX_CANDIDATES]
        keep.sort()
        a, b = a[keep], b[keep]
    verify = shift = None
    if node_columns is not None and a.size:
        cols = np.asarray(node_columns)
        score, shift, _ = align(cols[a], cols[b])
        mu, sd = _verify_background(cols, exclude)
        verify = (score - mu) / sd
    elif node_columns is not None:
        verify = np.zeros(0, np.float32)
        shift = np.zeros(0, np.int64)
    return PairScores(a.astype(np.int64), b.astype(np.int64), zz[a, b], seq[a, b], verify, shift,
                      sims[a, b], m)


def _verify_background(cols: np.ndarray, exclude: int, seed: int = 0) -> tuple[float, float]:
    """Median and spread of alignment scores of random temporally distant pairs."""
    m = cols.shape[0]
    rng = np.random.default_rng(seed)
    a = rng.integers(0, m, _VERIFY_SAMPLE * 2)
    b = rng.integers(0, m, _VERIFY_SAMPLE * 2)
    ok = np.abs(a - b) > exclude
    a, b = a[ok][:_VERIFY_SAMPLE], b[ok][:_VERIFY_SAMPLE]
    if a.size < 10:
        return 0.0, 1.0
    score, _, _ = align(cols[a], cols[b])
    mu, sd = robust_stats(score.astype(np.float64))
    return float(mu), float(sd)


def select(ps: PairScores, th: VerifiedThresholds = DEFAULT_THRESHOLDS) -> np.ndarray:
    """Indices into ``ps`` of the accepted pairs (sequence or verified single), after NMS."""
    if ps.a.size == 0:
        return np.zeros(0, np.int64)
    if ps.verify is not None:
        with_seq = ((ps.seq >= th.seq_z) & (ps.verify >= th.seq_verify_z)
                    & (ps.seq + ps.verify >= th.seq_sum_z))
        single = (ps.z >= th.single_z) & (ps.verify >= th.single_verify_z)
    else:  # no signatures: no verification, so ask more of both rules
        with_seq = ps.seq >= th.seq_z + 1.0
        single = ps.z >= th.single_z + 2.0
    ok = np.flatnonzero(with_seq | single)
    if ok.size == 0:
        return ok
    strength = np.maximum(ps.z[ok], ps.seq[ok])
    if ps.verify is not None:
        strength = strength + ps.verify[ok]
    grid = np.full((ps.m, ps.m), -np.inf, np.float32)
    grid[ps.a[ok], ps.b[ok]] = strength
    peak = maximum_filter(grid, size=2 * NMS_RADIUS + 1, mode="constant", cval=-np.inf)
    keep = grid[ps.a[ok], ps.b[ok]] >= peak[ps.a[ok], ps.b[ok]]
    return ok[keep]


def verified_loops(node_vectors: np.ndarray, params: MapParams, node_columns: Optional[np.ndarray] = None,
                   node_shifts: Optional[np.ndarray] = None, frame_width: int = 0,
                   thresholds: VerifiedThresholds = DEFAULT_THRESHOLDS):
    """Loop candidates of the ``verified`` method, sorted by (a, b), with yaw where known."""
    from .loops import LoopCandidate

    ps = score_pairs(node_vectors, node_columns, int(params.neighbor_node_num))
    chosen = select(ps, thresholds)
    yaw = None
    if ps.shift is not None and chosen.size and node_shifts is not None and frame_width > 0:
        width = np.asarray(node_columns).shape[1]
        yaw = pair_yaw(ps.shift[chosen], width, np.asarray(node_shifts)[ps.a[chosen]],
                       np.asarray(node_shifts)[ps.b[chosen]], frame_width)
    out = []
    for k, c in enumerate(chosen):
        score = float(ps.verify[c]) if ps.verify is not None else None
        out.append(LoopCandidate(int(ps.a[c]), int(ps.b[c]), float(ps.cosine[c]), 0,
                                 yaw=None if yaw is None else float(yaw[k]), score=score))
    out.sort(key=lambda lc: (lc.a, lc.b))
    return out
