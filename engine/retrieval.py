"""Loop candidates by retrieval: each node's k most similar distant nodes, never an n x n array.

The paper's methods and the first "verified" stage look at every pair of nodes, which
needs an (n, n) similarity matrix: 20k nodes are 1.6 GB per float32 copy, 100k are 40 GB.
Here every question is answered with memory bounded whatever n:

* ``nearest``: for every row its k best rows more than ``exclude`` apart in time.
  Exact search multiplies one block of rows by all rows at a time (``block_rows_for``
  keeps rows * n under ``BLOCK_ELEMENTS``); beyond ``EXACT_MAX_COST`` (n * n * d) the
  approximate path (an inverted file searched with matrix products, numpy only) takes over.
* ``background``: each row's robust similarity to "a different place" (median and MAD
  of its similarities to a fixed random sample of columns outside its temporal window).
* ``calibrated`` / ``pair_z``: symmetric z-scores of candidate pairs against both rows'
  backgrounds (the same formula as ``engine.calibrate.zscores``, without the matrix).
* ``diagonal_support``: the mean z-score along a matched stretch, forward or reverse.

Several recordings (a site) are *segments* of the rows (``segment``: one label per row,
each recording's rows contiguous). Temporal neighbours exist only within a recording;
``nearest`` gives every row its k best matches in its own recording and ``k_across`` in the
others together, shared equally among them (``per_other_recording``), and ``background`` keeps
each row's statistics against each recording, so a pair across two recordings is judged
against what "a different place" looks like between those two (another day's light lowers
every similarity across the days alike; pooled with the rows of its own day, a true match
across the days scored a median 1.6 standard deviations, against 3.7 calibrated per
pair of recordings; docs/method.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .robust import robust_stats

# Elements of one similarity block (rows x n). A block costs 4 bytes (float32 sims) plus
# 8 bytes (the int64 index array of np.argpartition) per element: 16M elements is about
# 200 MB, a few hundred MB at most whatever n.
BLOCK_ELEMENTS = 16_000_000

# Exact search costs n * n * d multiply-adds plus an n * n selection; the approximate
# path grows about linearly with n. Measured with benchmarks/bench_retrieval.py
# (random-walk 1024-D descriptors, k 10, OMP_NUM_THREADS=2, CPU seconds on the shared
# 2-core development machine): exact 1.1 s at 5k (n*n*d 2.6e10) and 14.9 s at 20k
# (4.1e11); approximate 3.9 s at 5k and 8.7 s at 20k. The two cross near 12k-15k rows
# at 1024-D (n*n*d about 2e11), where exact costs about 7 s: "auto" stays exact (no
# recall loss) up to there. 100k x 1024-D (1e13) would cost exact about 6 minutes.
EXACT_MAX_COST = 2e11

# Columns sampled per row for the background: the median of 1024 values has a standard
# error of 1.25 / sqrt(1024), about 4% of the spread (the brief asked for >= 1024).
BACKGROUND_SAMPLE = 1024
# Several recordings: BACKGROUND_SAMPLE is shared among them, never fewer than this per
# recording (the median's standard error is then 1.25 / sqrt(256): 8% of the spread).
MIN_SAMPLE_PER_RECORDING = 256
# MAD -> standard deviation for a normal distribution; spread floor against division by 0.
_SD_FLOOR = 1e-3

METHODS = ("auto", "exact", "approximate")


@dataclass(frozen=True)
class Neighbours:
    """index[i]: rows j with |i - j| > exclude, most similar first; sim[i] their cosines.
    Missing entries (fewer than k distant rows) are index -1, sim NaN."""
    index: np.ndarray   # (n, k) int64
    sim: np.ndarray     # (n, k) float32


@dataclass(frozen=True)
class Background:
    """Per-row background of similarities to rows outside the temporal window, against
    each recording (column s: the rows of segment s)."""
    mean: np.ndarray    # (n, S) float32, robust centre (median)
    std: np.ndarray     # (n, S) float32, robust spread (1.4826 * MAD, floored at 1e-3)
    exclude: int        # the temporal window the statistics left out
    segment: np.ndarray = None  # (n,) int64 recording of each row (all 0: one recording)

    def __post_init__(self):
        if self.segment is None:
            object.__setattr__(self, "segment", np.zeros(self.mean.shape[0], np.int64))
        if self.mean.ndim == 1:
            object.__setattr__(self, "mean", self.mean[:, None])
            object.__setattr__(self, "std", self.std[:, None])


def segment_labels(n: int, segment: Optional[np.ndarray]) -> np.ndarray:
    """(n,) int64 recording labels 0..S-1 (all 0 when ``segment`` is None); refused unless
    each recording's rows are contiguous and in order."""
    if segment is None:
        return np.zeros(n, np.int64)
    seg = np.asarray(segment, np.int64)
    if seg.shape != (n,) or (seg.size and (seg[0] != 0 or np.any(np.diff(seg) < 0) or np.any(np.diff(seg) > 1))):
        raise ValueError("segment must label contiguous recordings 0, 1, ... in row order")
    return seg


def temporal_neighbours(a: np.ndarray, b: np.ndarray, exclude: int, segment: np.ndarray) -> np.ndarray:
    """True where rows a and b are within ``exclude`` rows of each other in one recording."""
    near = np.abs(a - b) <= exclude
    if segment.size == 0 or segment[-1] == 0:   # one recording (labels are contiguous from 0)
        return near
    return near & (segment[a] == segment[b])


def block_rows_for(n: int, budget: int = BLOCK_ELEMENTS) -> int:
    """Rows per similarity block so that rows * n <= budget (at least one row)."""
    return int(max(1, min(max(n, 1), budget // max(n, 1))))


def sorted_unique(ids: np.ndarray) -> np.ndarray:
    """``np.unique`` of integer ids by a sort: numpy 2.4's hash table took 0.9 s for the 632k
    distinct candidate pairs of 100k nodes, a sort 0.02 s (benchmarks/bench_scale.py)."""
    ids = np.sort(ids)
    first = np.ones(ids.size, bool)
    first[1:] = ids[1:] != ids[:-1]
    return ids[first]


def pair_similarities(vectors: np.ndarray, a: np.ndarray, b: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """cos(v[a_k], v[b_k]) for every pair, a chunk at a time: gathering all pairs of
    long descriptors at once would need (pairs x d) floats twice."""
    a = np.asarray(a, np.int64)
    b = np.asarray(b, np.int64)
    out = np.empty(a.size, dtype=np.float32)
    for k in range(0, a.size, chunk):
        out[k:k + chunk] = np.einsum("ij,ij->i", vectors[a[k:k + chunk]], vectors[b[k:k + chunk]])
    return out


def _mask_window(sims: np.ndarray, r0: int, exclude: int, value: float, segment: np.ndarray) -> None:
    """Set sims[i - r0, j] = value for temporal neighbours i, j (in place; rows r0..r0+len)."""
    rows = np.arange(sims.shape[0])
    n = sims.shape[1]
    for off in range(-exclude, exclude + 1):
        cols = rows + r0 + off
        ok = (cols >= 0) & (cols < n)
        ok[ok] &= segment[rows[ok] + r0] == segment[cols[ok]]
        sims[rows[ok], cols[ok]] = value


def _empty(n: int, k: int) -> Neighbours:
    return Neighbours(np.full((n, k), -1, np.int64), np.full((n, k), np.nan, np.float32))


def _top_k(sims: np.ndarray, kk: int) -> tuple[np.ndarray, np.ndarray]:
    """(index, sim) of each row's kk largest entries, best first; -1 / NaN where not finite."""
    w = sims.shape[1]
    top = np.argpartition(sims, w - kk, axis=1)[:, w - kk:] if kk < w else np.tile(np.arange(w), (sims.shape[0], 1))
    s = np.take_along_axis(sims, top, axis=1)
    order = np.argsort(-s, axis=1, kind="stable")
    top = np.take_along_axis(top, order, axis=1)
    s = np.take_along_axis(s, order, axis=1)
    bad = ~np.isfinite(s)
    top[bad] = -1
    s[bad] = np.nan
    return top, s


def per_other_recording(k_across: int, recordings: int) -> int:
    """Matches each row keeps in each recording other than its own: ``k_across`` shared
    equally among the other ``recordings - 1``, rounded up (at least one in each).

    Why a shared budget rather than k in every recording: candidate pairs, and with them
    the stage-2 support and everything after it, grew with nodes x recordings (a site of 10
    recordings: 100 matches per node, 8.7 million pairs at 120,000 nodes). With two
    recordings the budget is k in the other one, as before; with ten, 2 in each of nine.
    A place seen in several recordings is still matched in every one of them from every
    node of its stretch, and the places are joined through any of them."""
    if recordings <= 1:
        return 0
    return max(1, -(-int(k_across) // (recordings - 1)))


def _layout(segment: np.ndarray, k: int, w: int) -> tuple[np.ndarray, int]:
    """(base, width): row i's matches in recording s start at column base[i, s]; its own
    recording first (k columns), then each other recording in order (w columns each)."""
    n_seg = int(segment[-1]) + 1 if segment.size else 1
    s = np.arange(n_seg)[None, :]
    own = segment[:, None]
    base = np.where(s == own, 0, k + w * (s - (s > own)))
    return base.astype(np.int64), k + w * (n_seg - 1)


def _segment_bounds(segment: np.ndarray) -> list[tuple[int, int]]:
    starts = np.flatnonzero(np.diff(np.concatenate([[-1], segment])) != 0)
    ends = np.concatenate([starts[1:], [segment.size]])
    return list(zip(starts.tolist(), ends.tolist()))


def _exact(v: np.ndarray, k: int, exclude: int, block_rows: Optional[int], segment: np.ndarray,
           w: int) -> Neighbours:
    """k best in the row's own recording, then w in each other one (``_layout``)."""
    n = v.shape[0]
    bounds = _segment_bounds(segment)
    base, width = _layout(segment, k, w)
    out = _empty(n, width)
    if n == 0 or width == 0:
        return out
    rows = block_rows_for(n) if block_rows is None else max(1, int(block_rows))
    for r0 in range(0, n, rows):
        r1 = min(n, r0 + rows)
        sims = v[r0:r1] @ v.T
        _mask_window(sims, r0, exclude, -np.inf, segment)
        for s, (c0, c1) in enumerate(bounds):
            # the block's rows of each recording: k matches in their own, w in another
            for g0, g1 in _segment_bounds(segment[r0:r1]):
                kk = min(k if segment[r0 + g0] == s else w, c1 - c0)
                if kk == 0:
                    continue
                top, sim = _top_k(sims[g0:g1, c0:c1], kk)
                cols = base[r0 + g0, s] + np.arange(kk)
                out.index[r0 + g0:r0 + g1, cols] = np.where(top >= 0, top + c0, -1)
                out.sim[r0 + g0:r0 + g1, cols] = sim
    return out


# Approximate path: an inverted file searched with matrix products. Rows are grouped
# into cells by spherical k-means (CELL_ROWS rows per cell on average, centres trained
# on a sample of SAMPLE_PER_CELL rows per cell); each query scans the NPROBE cells
# whose centres are most similar to it, as one (queries of the cell) x (rows of the
# cell) product per cell, and keeps exact full-vector similarities. Cost about
# n * NPROBE * CELL_ROWS * d instead of n * n * d. Measured on 100k x 1024-D random-walk
# descriptors (benchmarks/bench_retrieval.py, one thread, CPU seconds): NPROBE 8 takes
# 10.9 s, recall@10 0.894 against exact, and finds 99.96% of the revisits; NPROBE 16
# takes 20.2 s for recall@10 0.922 and 99.99%: the revisits (what loop closure needs)
# are already found at 8, so 8 it is. faiss-cpu (IVF-flat, HNSW) was measured slower
# (see that benchmark's docstring), so no dependency is added.
CELL_ROWS = 256
SAMPLE_PER_CELL = 32
KMEANS_ITERATIONS = 8
NPROBE = 8


def _kmeans(v: np.ndarray, centre: np.ndarray, cells: int, seed: int) -> np.ndarray:
    """(cells, d) unit centres of spherical k-means on a random sample of rows, centred.

    Centring matters: descriptors share a common direction (unrelated places have cosine
    0.3 or more), and without it one "hub" cell near that direction holds many rows and
    is probed by almost every query (measured: 3.7x the balanced cost at 20k rows)."""
    rng = np.random.default_rng(seed)
    n = v.shape[0]
    sample = v[np.sort(rng.choice(n, min(n, cells * SAMPLE_PER_CELL), replace=False))] - centre
    sample /= np.maximum(np.linalg.norm(sample, axis=1, keepdims=True), 1e-12)
    centres = sample[rng.choice(sample.shape[0], cells, replace=False)].copy()
    for _ in range(KMEANS_ITERATIONS):
        label = np.argmax(sample @ centres.T, axis=1)
        # per-cell sums over the sample sorted by cell (np.add.at is slow; a one-hot product
        # costs cells x sample x d: 16 GFLOP per iteration at 360,000 rows)
        order = np.argsort(label, kind="stable")
        counts = np.bincount(label, minlength=cells)
        sums = np.zeros((cells, sample.shape[1]), np.float32)
        filled = counts > 0
        sums[filled] = np.add.reduceat(sample[order], np.concatenate([[0], np.cumsum(counts)[:-1]])[filled], axis=0)
        norm = np.linalg.norm(sums, axis=1)
        empty = norm == 0   # an empty cell restarts on a random sample row
        sums[empty] = sample[rng.choice(sample.shape[0], int(empty.sum()))]
        centres = sums / np.linalg.norm(sums, axis=1, keepdims=True)
    return centres.astype(np.float32)


def _approximate(v: np.ndarray, k: int, exclude: int, segment: np.ndarray, w: int, nprobe: Optional[int] = None,
                 seed: int = 0) -> Neighbours:
    """k in the row's own recording and w in each other one, as ``_exact``, from the cells each
    query probes."""
    n = v.shape[0]
    nprobe = NPROBE if nprobe is None else nprobe
    cells = int(max(1, min(n // 4, round(n / CELL_ROWS))))
    nprobe = int(min(nprobe, cells))
    centre = v.mean(axis=0)
    centres = _kmeans(v, centre, cells, seed)
    offset = centres @ centre
    # Each row's cell (its best centre) and the nprobe cells it scans, a block at a time.
    # The centred row (v - centre) / |v - centre| scores (v @ c - centre @ c) / |v - centre|
    # against centre c; the row's norm does not change its ranking of centres.
    cell = np.empty(n, np.int64)
    probes = np.empty((n, nprobe), np.int64)
    rows = block_rows_for(cells * 16)
    for r0 in range(0, n, rows):
        sc = v[r0:r0 + rows] @ centres.T - offset
        top = np.argpartition(sc, cells - nprobe, axis=1)[:, cells - nprobe:] if nprobe < cells else \
            np.tile(np.arange(cells), (sc.shape[0], 1))
        probes[r0:r0 + rows] = top
        cell[r0:r0 + rows] = np.argmax(sc, axis=1)
    members_order = np.argsort(cell, kind="stable")   # rows in order within a cell: recordings contiguous
    member_start = np.searchsorted(cell[members_order], np.arange(cells + 1))
    flat = probes.ravel()
    probe_order = np.argsort(flat, kind="stable")
    probe_start = np.searchsorted(flat[probe_order], np.arange(cells + 1))
    # Candidates: the final layout (``_layout``) with nprobe slots per match, kk per
    # (query, recording, probed cell). int32 rows: the table is n x width x nprobe.
    base, width = _layout(segment, k, w)
    cand_i = np.full((n, width * nprobe), -1, np.int32)
    cand_s = np.full((n, width * nprobe), -np.inf, np.float32)
    for c in range(cells):
        mem = members_order[member_start[c]:member_start[c + 1]]
        hits = probe_order[probe_start[c]:probe_start[c + 1]]
        if mem.size == 0 or hits.size == 0:
            continue
        q_all, slot_all = hits // nprobe, hits % nprobe
        vm = v[mem]
        parts = _segment_bounds(segment[mem])
        step = max(1, BLOCK_ELEMENTS // mem.size)   # all of a cell's queries at once, as a rule
        for h0 in range(0, q_all.size, step):
            q, slot = q_all[h0:h0 + step], slot_all[h0:h0 + step]
            sims = v[q] @ vm.T
            sims[temporal_neighbours(q[:, None], mem[None, :], exclude, segment)] = -np.inf
            for m0, m1 in parts:
                s = int(segment[mem[m0]])
                own = segment[q] == s
                for group, kk in ((own, min(k, m1 - m0)), (~own, min(w, m1 - m0))):
                    if kk == 0 or not group.any():
                        continue
                    qs = q[group]
                    part = sims[group, m0:m1]
                    top = np.argpartition(part, m1 - m0 - kk, axis=1)[:, m1 - m0 - kk:]
                    cols = (base[qs, s] * nprobe)[:, None] + slot[group, None] * kk + np.arange(kk)[None, :]
                    cand_i[qs[:, None], cols] = mem[m0 + top]
                    cand_s[qs[:, None], cols] = np.take_along_axis(part, top, axis=1)
    out = _empty(n, width)
    bounds = _segment_bounds(segment)
    for r0, r1 in bounds:   # one layout per recording of the queries
        for s, (c0, c1) in enumerate(bounds):
            full = k if s == segment[r0] else w
            kk = min(full, c1 - c0)
            if kk == 0:
                continue
            lo = int(base[r0, s])
            span = slice(lo * nprobe, (lo + full) * nprobe)
            top, sim = _top_k(cand_s[r0:r1, span], kk)
            idx = np.take_along_axis(cand_i[r0:r1, span], np.maximum(top, 0), axis=1)
            out.index[r0:r1, lo:lo + kk] = np.where(top >= 0, idx, -1)
            out.sim[r0:r1, lo:lo + kk] = sim
    return out


def choose_method(n: int, d: int) -> str:
    """"exact" while n * n * d <= EXACT_MAX_COST, else "approximate"."""
    if float(n) * n * d <= EXACT_MAX_COST:
        return "exact"
    return "approximate"


def nearest(vectors: np.ndarray, k: int, exclude: int, *, block_rows: Optional[int] = None,
            method: str = "auto", segment: Optional[np.ndarray] = None,
            k_across: Optional[int] = None) -> Neighbours:
    """For every row i its k most similar rows j with |i - j| > exclude, best first; with
    several recordings (``segment``) its k best in its own recording (columns [0, k)), then
    ``per_other_recording(k_across, S)`` best in each other recording in order (``k_across``
    None: k in each), the temporal window only within a recording.

    ``vectors`` (n, d) are L2-normalised rows (cosine = dot product). ``method``:
    "exact" (blocked matrix products, memory rows * n <= BLOCK_ELEMENTS), "approximate"
    (an inverted file searched with matrix products, exact similarities of what it
    finds; exact for fewer than 4 * CELL_ROWS rows) or "auto" (``choose_method``). ``block_rows`` overrides the exact block size.
    """
    if method not in METHODS:
        raise ValueError(f"unknown retrieval method {method!r}; choose one of {', '.join(METHODS)}")
    v = np.ascontiguousarray(vectors, dtype=np.float32)
    if v.ndim != 2:
        raise ValueError(f"vectors must be a 2-D array, got shape {v.shape}")
    n, d = v.shape
    k = int(k)
    exclude = max(0, int(exclude))
    segment = segment_labels(n, segment)
    n_seg = int(segment[-1]) + 1 if n else 1
    w = k if k_across is None else per_other_recording(k_across, n_seg)
    if method == "auto":
        method = choose_method(n, d)
    if method == "approximate" and n > 4 * CELL_ROWS:
        return _approximate(v, k, exclude, segment, w)
    return _exact(v, k, exclude, block_rows, segment, w)


def sample_columns(n: int, size: int = BACKGROUND_SAMPLE, seed: int = 0) -> np.ndarray:
    """A fixed random sample of ``size`` column indices (all of them when n <= size), sorted."""
    if n <= size:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size, replace=False))


def sampled_similarities(vectors: np.ndarray, cols: np.ndarray, exclude: int, segment: Optional[np.ndarray] = None):
    """Yield (r0, r1, block) with block = v[r0:r1] @ v[cols].T as float32, NaN where row and
    column are temporal neighbours: the (n, len(cols)) matrix one row block at a time."""
    v = np.asarray(vectors, dtype=np.float32)
    n = v.shape[0]
    segment = segment_labels(n, segment)
    vc = v[cols]
    rows = block_rows_for(max(len(cols), 1) * 16)   # blocks of at most BLOCK_ELEMENTS / 16
    for r0 in range(0, n, rows):
        r1 = min(n, r0 + rows)
        block = v[r0:r1] @ vc.T
        block[temporal_neighbours(np.arange(r0, r1)[:, None], cols[None, :], exclude, segment)] = np.nan
        yield r0, r1, block


def background(vectors: np.ndarray, exclude: int, sample: int = BACKGROUND_SAMPLE, seed: int = 0,
               segment: Optional[np.ndarray] = None) -> Background:
    """Each row's median and MAD spread of its similarities to a random column sample, for
    each recording (``segment``) apart.

    The columns are one fixed random sample of ``sample`` rows per recording (seeded, the
    same for every row; ``sample // S`` per recording with S recordings, at least
    ``MIN_SAMPLE_PER_RECORDING``) rather than the exact search blocks: it costs
    n * sample * d, is the same for the exact and approximate paths, and a robust
    statistic of 1024 values is as good as of all n. Columns within ``exclude`` of the row
    are left out; revisits are a few per row at most, so median and MAD ignore them. Rows
    with no distant column in a recording get the statistics of all values sampled there.
    """
    import warnings

    v = np.asarray(vectors, dtype=np.float32)
    n = v.shape[0]
    segment = segment_labels(n, segment)
    bounds = _segment_bounds(segment) if n else [(0, 0)]
    per = sample if len(bounds) == 1 else max(MIN_SAMPLE_PER_RECORDING, sample // len(bounds))
    mean = np.zeros((n, len(bounds)), np.float32)
    std = np.ones((n, len(bounds)), np.float32)
    for s, (c0, c1) in enumerate(bounds):
        cols = c0 + sample_columns(c1 - c0, per, seed)
        pooled = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            for r0, r1, block in sampled_similarities(v, cols, exclude, segment):
                mu, sd = robust_stats(block, axis=1)
                mean[r0:r1, s], std[r0:r1, s] = mu, sd
                pooled.append(block[::max(1, (r1 - r0) // 64)].ravel())
        allv = np.concatenate(pooled) if pooled else np.zeros(0, np.float32)
        allv = allv[~np.isnan(allv)]
        if allv.size:
            g_mu, g_sd = robust_stats(allv.astype(np.float64))
            miss = np.isnan(mean[:, s])
            mean[miss, s], std[miss, s] = g_mu, g_sd
        else:
            mean[:, s], std[:, s] = 0.0, 1.0
    return Background(mean.astype(np.float32), np.maximum(std, _SD_FLOOR).astype(np.float32), int(exclude),
                      segment)


def zscores(sims: np.ndarray, stats: Background, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Symmetric z of pair (a, b): sim against the mean of both backgrounds,
    z = (s - (mu_a + mu_b) / 2) / sqrt((sd_a^2 + sd_b^2) / 2). A pair is one place
    seen twice, so both rows' ideas of "different place" count equally, and z(a, b) ==
    z(b, a). Same formula as engine.calibrate.zscores. Each row's background is the one
    against the other row's recording."""
    seg = stats.segment
    mu = 0.5 * (stats.mean[a, seg[b]] + stats.mean[b, seg[a]])
    sd = np.sqrt(0.5 * (stats.std[a, seg[b]] ** 2 + stats.std[b, seg[a]] ** 2))
    return ((sims - mu) / sd).astype(np.float32)


def pair_z(vectors: np.ndarray, stats: Background, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Calibrated z-score of arbitrary pairs (a_k, b_k)."""
    a = np.asarray(a, np.int64)
    b = np.asarray(b, np.int64)
    return zscores(pair_similarities(np.asarray(vectors, np.float32), a, b), stats, a, b)


def calibrated(neigh: Neighbours, stats: Background) -> np.ndarray:
    """(n, k) z-scores of the neighbour pairs (NaN where the neighbour is missing)."""
    n, k = neigh.index.shape
    a = np.repeat(np.arange(n), k)
    b = neigh.index.ravel()
    ok = b >= 0
    z = np.full(n * k, np.nan, np.float32)
    z[ok] = zscores(neigh.sim.ravel()[ok], stats, a[ok], b[ok])
    return z.reshape(n, k)


# Pairs whose stretches are scored at once: each stretch is 2 * half index pairs in several
# arrays, so all pairs at once grew with their count (a site of 120,000 nodes has 8.7 million:
# peak 5.8 GB, 2.5 GB in blocks, the same means).
SUPPORT_BLOCK = 1 << 20


def diagonal_support(vectors: np.ndarray, stats: Background, a: np.ndarray, b: np.ndarray,
                     half: int, direction: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean z of the pairs (a + t, b + direction * t), 0 < |t| <= half, and how many were used.

    ``direction`` +1: the stretch around a is driven again the same way around b; -1: in
    reverse. Pairs that leave a's or b's recording or are temporal neighbours are skipped;
    a pair with none left gets NaN and count 0. Row dot products only.
    """
    if direction not in (1, -1):
        raise ValueError("direction must be +1 (same way) or -1 (reverse)")
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    parts = [_diagonal_block(vectors, stats, a[i:i + SUPPORT_BLOCK], b[i:i + SUPPORT_BLOCK], half, direction)
             for i in range(0, a.size, SUPPORT_BLOCK)] or [_diagonal_block(vectors, stats, a, b, half, direction)]
    return np.concatenate([m for m, _ in parts]), np.concatenate([c for _, c in parts])


def _diagonal_block(vectors, stats: Background, a: np.ndarray, b: np.ndarray, half: int, direction: int):
    v = np.asarray(vectors, np.float32)
    n = v.shape[0]
    t = np.concatenate([np.arange(-half, 0), np.arange(1, half + 1)])
    ii = (a[:, None] + t[None, :]).ravel()
    jj = (b[:, None] + direction * t[None, :]).ravel()
    seg = stats.segment
    ok = (ii >= 0) & (ii < n) & (jj >= 0) & (jj < n)
    ok[ok] &= (seg[ii[ok]] == np.repeat(seg[a], t.size)[ok]) & (seg[jj[ok]] == np.repeat(seg[b], t.size)[ok])
    ok[ok] &= ~temporal_neighbours(ii[ok], jj[ok], stats.exclude, seg)
    z = np.zeros(ii.size, np.float32)
    # The stretches of neighbouring matches overlap (a run of matches shares its diagonal): each
    # distinct pair's z once (100k nodes: 3.8M pairs per direction, 1.2M-1.8M distinct).
    cell, inverse = np.unique(ii[ok] * n + jj[ok], return_inverse=True)
    z[ok] = pair_z(v, stats, cell // n, cell % n)[inverse]
    ok = ok.reshape(a.size, t.size)
    count = ok.sum(axis=1)
    total = np.where(ok, z.reshape(a.size, t.size), 0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return mean.astype(np.float32), count.astype(np.int64)
