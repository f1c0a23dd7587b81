"""Yaw-aligned verification of loop candidates by circular alignment of column signatures.

At describe time every (panorama-shifted) frame is reduced to a small per-column
signature (``column_features``: colour and structure of a few horizontal bands per
column, ``COLUMN_WIDTH`` columns). Two panoramas of the same place differ by a yaw
rotation, i.e. a circular shift of columns, so for a candidate pair we search all
circular shifts at once (FFT cross-correlation, as Scan Context does for lidar rings)
and keep the best: its correlation is the verification score (1 = identical up to a
roll, ~0 unrelated) and its shift is the relative heading.

Yaw convention (same as ``engine.shift.relative_yaw``): the yaw of pair (a, b) is how
far, in degrees, the content of frame a appears displaced in frame b (positive towards
increasing column) in the ORIGINAL, unshifted frames. On the synthetic routes this is
the robot's heading change from node a to node b in degrees, counter-clockwise positive
(tests/test_verified_method.py checks it against ground truth).
"""

from __future__ import annotations

import numpy as np

from .errors import InputError
from .shift import column_signature

# Columns of a signature (2.8 degrees per column): enough for yaw, small enough to keep.
COLUMN_WIDTH = 128
# Bump when column_features changes, so cached descriptors are recomputed.
COLUMNS_VERSION = 1
# Pairs aligned per FFT batch (bounds memory to a few MB).
_BATCH = 512


def column_features(rgb: np.ndarray, width: int = COLUMN_WIDTH) -> np.ndarray:
    """Per-column signature of one panorama: float16 (width', F), F signals per column.

    Every signal is zero-mean and unit-norm over the columns (``shift.column_signature``),
    so the dot product of two aligned signatures summed over signals is a correlation.
    """
    return column_signature(rgb, width=width).T.astype(np.float16)


def _spectra(columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """rfft over columns of (k, W, F) signatures -> (k, F, W//2+1) and the active-signal mask."""
    c = np.asarray(columns, dtype=np.float32).transpose(0, 2, 1)   # (k, F, W)
    active = np.any(c != 0, axis=2)                                 # (k, F)
    return np.fft.rfft(c, axis=2), active


def align(columns_a: np.ndarray, columns_b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best circular alignment of K signature pairs (K, W, F) each.

    Returns ``score`` (K,) mean correlation at the best shift, ``shift`` (K,) int columns
    (content of a at column j appears at j + shift in b), and ``margin`` (K,): best score
    minus the best score more than W/8 columns away (how unique the alignment is).
    """
    a = np.asarray(columns_a)
    b = np.asarray(columns_b)
    if a.shape != b.shape or a.ndim != 3:
        raise InputError(f"column signatures must have equal (K, W, F) shapes, got {a.shape} and {b.shape}")
    k, w, _ = a.shape
    score = np.zeros(k, np.float32)
    shift = np.zeros(k, np.int64)
    margin = np.zeros(k, np.float32)
    far = max(1, w // 8)
    for s0 in range(0, k, _BATCH):
        s1 = min(k, s0 + _BATCH)
        fa, act_a = _spectra(a[s0:s1])
        fb, act_b = _spectra(b[s0:s1])
        n_active = np.maximum((act_a & act_b).sum(axis=1), 1)
        corr = np.fft.irfft((np.conj(fa) * fb).sum(axis=1), n=w, axis=1) / n_active[:, None]
        best = np.argmax(corr, axis=1)
        top = corr[np.arange(s1 - s0), best]
        dist = np.abs(np.arange(w)[None, :] - best[:, None])
        dist = np.minimum(dist, w - dist)
        second = np.where(dist > far, corr, -np.inf).max(axis=1)
        score[s0:s1] = top
        shift[s0:s1] = best
        margin[s0:s1] = top - second
    return score, shift, margin


def align_nodes(columns: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``align`` for pairs (a[k], b[k]) of rows of ``columns`` (n, W, F): (score, shift).

    Each node's spectrum is computed once, however many pairs it is in, so thousands
    of candidate pairs cost one small product and inverse FFT each.
    """
    a = np.asarray(a, np.int64)
    b = np.asarray(b, np.int64)
    if a.size == 0:
        return np.zeros(0, np.float32), np.zeros(0, np.int64)
    nodes, inv = np.unique(np.concatenate([a, b]), return_inverse=True)
    spec, active = _spectra(np.asarray(columns)[nodes])
    spec = spec.astype(np.complex64)
    ia, ib = inv[:a.size], inv[a.size:]
    w = np.asarray(columns).shape[1]
    score = np.empty(a.size, np.float32)
    shift = np.empty(a.size, np.int64)
    for s0 in range(0, a.size, 4 * _BATCH):
        s1 = min(a.size, s0 + 4 * _BATCH)
        pa, pb = ia[s0:s1], ib[s0:s1]
        n_active = np.maximum((active[pa] & active[pb]).sum(axis=1), 1)
        cross = np.einsum("kfw,kfw->kw", np.conj(spec[pa]), spec[pb])
        corr = np.fft.irfft(cross, n=w, axis=1) / n_active[:, None]
        best = np.argmax(corr, axis=1)
        score[s0:s1] = corr[np.arange(s1 - s0), best]
        shift[s0:s1] = best
    return score, shift


def pair_yaw(shift_cols: np.ndarray, column_width: int, frame_shift_a: np.ndarray,
             frame_shift_b: np.ndarray, frame_width: int) -> np.ndarray:
    """Relative yaw (degrees, (-180, 180]) of the original frames of each pair.

    ``shift_cols`` is the alignment of the shifted frames at ``column_width`` columns;
    the panorama shifts ``frame_shift_*`` (full-resolution columns) are added back.
    """
    deg = (np.asarray(shift_cols, np.float64) * 360.0 / column_width
           + (np.asarray(frame_shift_b, np.float64) - np.asarray(frame_shift_a, np.float64))
           * 360.0 / float(frame_width))
    deg = (deg + 180.0) % 360.0 - 180.0
    return np.where(deg == -180.0, 180.0, deg)


# Local alignment (after the global one): windows of LOCAL_HALF * 2 + 1 columns every
# LOCAL_STEP columns, each searched over +-LOCAL_SEARCH columns.
LOCAL_HALF = 8
LOCAL_STEP = 8
LOCAL_SEARCH = 10


def local_shifts(columns: np.ndarray, a: np.ndarray, b: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """How far each part of panorama a appears displaced in b beyond the global ``shift``.

    Returns (K, W // LOCAL_STEP) sub-column offsets, one per window of a. A pure rotation
    gives zeros; a translation displaces nearby content by up to (translation / distance)
    radians, towards the back on both sides for a step forwards.
    """
    cols = np.asarray(columns, np.float32)
    a, b, shift = (np.asarray(x, np.int64) for x in (a, b, shift))
    w = cols.shape[1]
    offsets = np.arange(-LOCAL_SEARCH, LOCAL_SEARCH + 1)
    # prod[k, c, d]: column c of a against column c + shift + d of b, summed over signals.
    prod = np.empty((a.size, w, offsets.size), np.float32)
    for s0 in range(0, a.size, _BATCH):
        s1 = min(a.size, s0 + _BATCH)
        ca = cols[a[s0:s1]]
        index = (np.arange(w)[None, :] + shift[s0:s1, None]) % w
        cb = cols[b[s0:s1][:, None], index]                         # b rolled by the global shift
        for n, d in enumerate(offsets):
            prod[s0:s1, :, n] = np.einsum("kwf,kwf->kw", ca, np.roll(cb, -d, axis=1))
    centres = np.arange(0, w, LOCAL_STEP)
    corr = sum(prod[:, (centres + j) % w, :] for j in range(-LOCAL_HALF, LOCAL_HALF + 1))   # (K, n, D)
    best = np.argmax(corr, axis=2)
    # Sub-column offset from a parabola through the peak and its neighbours (interior peaks only).
    inner = np.clip(best, 1, offsets.size - 2)
    left, mid, right = (np.take_along_axis(corr, (inner + o)[..., None], axis=2)[..., 0] for o in (-1, 0, 1))
    curv = left - 2.0 * mid + right
    peaked = (best == inner) & (curv < 0)
    frac = np.where(peaked, 0.5 * (left - right) / np.where(peaked, curv, -1.0), 0.0)
    return (offsets[best] + frac).astype(np.float32)


def displacement(local: np.ndarray) -> np.ndarray:
    """Amplitude of the first circular harmonic of ``local_shifts`` rows (columns).

    A translation shifts content by roughly t sin(angle to it) / distance, one period
    around the panorama: the amplitude grows with the distance between the two views
    whatever their headings.
    """
    n = local.shape[-1]
    phase = np.exp(-2j * np.pi * np.arange(n) / n)
    return (2.0 * np.abs((local * phase).mean(axis=-1))).astype(np.float32)


def cumulative_turning(columns: np.ndarray, frame_shifts: np.ndarray, frame_width: int) -> np.ndarray:
    """Degrees the robot has turned, summed without sign, from node 0 to each node.

    Each step is the relative yaw of consecutive nodes (``pair_yaw`` of their alignment).
    A misaligned step (a corridor looks alike both ways) only adds turning, so a small
    value between two nodes reliably means "drove (nearly) straight from one to the other".
    """
    n = np.asarray(columns).shape[0]
    if n < 2:
        return np.zeros(n)
    steps = np.arange(n - 1)
    _, shift = align_nodes(columns, steps, steps + 1)
    shifts = np.asarray(frame_shifts)
    yaw = pair_yaw(shift, np.asarray(columns).shape[1], shifts[steps], shifts[steps + 1], frame_width)
    return np.concatenate([[0.0], np.cumsum(np.abs(yaw))])
