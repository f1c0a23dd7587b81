"""Loop-closure candidates between nodes (METHOD.md sections 4 and 5).

Methods (``params.method``):

* ``simple`` and ``shift-simple``: every node pair (a, b), a < b, with
  cos >= loop_sim_th is a loop. The two differ only in the descriptors (shifted
  panoramas or not), not here. ``window_count`` is 0.
* ``ours``: the spatial consistency check, exactly as the paper words it. For each
  query q, windows [s, s + window_size) for s = 0 .. m - window_size; a window is
  skipped if it holds any node t with |t - q| <= neighbor_node_num (this includes q);
  the window's count is the number of nodes with cos(q, t) >= loop_sim_th; if
  count > count_th the window's most similar node to q (the first one on ties) is a
  candidate c of q. A query may get several candidates from several windows; the
  set of stored (q, c) is kept, and only mutual pairs ((q, c) and (c, q) both
  stored) become loops. ``window_count`` is the largest count among all candidate
  windows that produced the pair, from either side (max over (q, c) and (c, q)).

For every method a pair of directly consecutive nodes (b - a == 1) is dropped: it is
already a path arc, so it can never be a loop arc.

The "ours" check is exact and vectorised: the similarity matrix is computed in square
tiles of its upper triangle (it is symmetric, so each tile serves its rows and, transposed,
its columns: half the products of row blocks), never whole; within a tile the candidate
windows are enumerated from the thresholded matches (a window can only count more than
count_th matches if its first match is followed by count_th more within it), so the cost
beyond the matrix product grows with the matches, not with every window. Its cost is still
that of all m^2 / 2 similarities (benchmarks/bench_ours_scale.py, d = 256, two shared cores:
50,000 nodes in 51 s, was 140 s; 200,000 nodes about 11 min, extrapolated from 300 of 5,050
tiles): progress is reported per tile through the ``progress`` callback (``engine.progress``:
the command line shows a bar with the time left) and ``cancel`` is checked between tiles.
"""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

from ..errors import InputError
from ..params import METHODS, MapParams
from ..progress import check, report
from ..retrieval import pair_similarities
from .pairs import LoopCandidate

# Bound the similarity block (rows x m float32, or a square tile of about half this for
# "ours") to about 32 MB: large enough for an efficient matrix product, small beside memory.
_BLOCK_ELEMENTS = 8_000_000

# The progress stages of the O(m^2) loop search ("ours": done/total similarity tiles;
# "simple": done/total query nodes), with the unit a progress bar shows for each.
OURS_STAGE = "finding loops (similarity tiles)"
SIMPLE_STAGE = "finding loops (query nodes)"
PROGRESS_UNITS = {OURS_STAGE: "tile", SIMPLE_STAGE: "node"}

# (progress, cancel) for callers that cannot pass them down (the command line sets them
# around ``engine.run.run`` with ``loop_progress``); explicit arguments win.
_CONTEXT: ContextVar = ContextVar("panotopo_loop_progress", default=(None, None))


@contextmanager
def loop_progress(progress=None, cancel=None):
    """Within this block, ``detect_loops`` called without ``progress``/``cancel`` reports
    to ``progress`` and checks ``cancel`` (an ``engine.progress`` callback and token)."""
    token = _CONTEXT.set((progress, cancel))
    try:
        yield
    finally:
        _CONTEXT.reset(token)


def similarity_matrix(node_vectors: np.ndarray) -> np.ndarray:
    """(m, m) float32 cosine similarities of L2-normalised rows."""
    v = np.asarray(node_vectors, dtype=np.float32)
    return v @ v.T


def detect_loops(node_vectors: np.ndarray, params: MapParams, progress=None,
                 cancel=None) -> list[LoopCandidate]:
    """Loop candidates for ``params.method``, sorted by (a, b).

    ``progress(done, total, stage)`` (``OURS_STAGE`` or ``SIMPLE_STAGE``) is called as the similarity matrix is
    worked through and ``cancel`` (``engine.progress.CancelToken``) is checked between
    blocks; both default to those set by ``loop_progress``."""
    if progress is None and cancel is None:
        progress, cancel = _CONTEXT.get()
    v = np.asarray(node_vectors, dtype=np.float32)
    if v.ndim != 2:
        raise InputError(f"node descriptors must be a 2-D array, got shape {v.shape}")
    _check_params(params)
    if params.method == "ours":
        a, b, counts = _ours_pairs(v, params, progress, cancel)
    else:
        a, b = _simple_pairs(v, float(params.loop_sim_th), progress, cancel)
        counts = np.zeros(a.size, dtype=np.int64)
    order = np.lexsort((b, a))
    a, b, counts = a[order], b[order], counts[order]
    sims = pair_similarities(v, a, b)
    return [
        LoopCandidate(int(i), int(j), float(s), int(c))
        for i, j, s, c in zip(a, b, sims, counts)
    ]


def _check_params(params: MapParams) -> None:
    if params.method not in METHODS:
        raise InputError(f"unknown method {params.method!r}; choose one of {', '.join(METHODS)}")
    if params.loop_sim_th is None:
        raise InputError("loop_sim_th is not set (resolve the descriptor's defaults first)")
    if params.window_size < 1:
        raise InputError(f"window size must be at least 1, got {params.window_size}")
    if params.count_th < 0:
        raise InputError(f"count threshold must be >= 0, got {params.count_th}")
    if params.neighbor_node_num < 0:
        raise InputError(f"neighbour node number must be >= 0, got {params.neighbor_node_num}")


def _row_blocks(m: int):
    rows = int(min(1024, max(16, _BLOCK_ELEMENTS // max(m, 1))))
    for q0 in range(0, m, rows):
        yield q0, min(m, q0 + rows)


def _simple_pairs(v: np.ndarray, th: float, progress=None, cancel=None) -> tuple[np.ndarray, np.ndarray]:
    m = v.shape[0]
    th32 = np.float32(th)
    a_parts, b_parts = [], []
    for q0, q1 in _row_blocks(m):
        check(cancel)
        report(progress, q0, m, SIMPLE_STAGE)
        sims = v[q0:q1] @ v.T
        qi, cj = np.nonzero(sims >= th32)
        qi = qi + q0
        keep = cj >= qi + 2  # one entry per unordered pair; b - a == 1 is a path arc
        a_parts.append(qi[keep])
        b_parts.append(cj[keep])
    report(progress, m, m, SIMPLE_STAGE)
    if not a_parts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(a_parts).astype(np.int64), np.concatenate(b_parts).astype(np.int64)


def _ours_pairs(v: np.ndarray, params: MapParams, progress=None,
                cancel=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mutual pairs (a, b), a < b - 1, of the spatial consistency check and their
    window counts (module notes), computed tile by tile over the upper triangle of the
    similarity matrix (each tile serves both its rows and, transposed, its columns).

    Exactly the check of ``reference`` semantics (tests/test_loops.py compares it with
    plain loops): every window is counted from the thresholded similarities; only the
    bookkeeping is sparse (a window can only be a candidate if its first match is followed
    by ``count_th`` more matches within it, so windows are enumerated from the matches)."""
    m = v.shape[0]
    w = int(params.window_size)
    empty = np.zeros(0, np.int64)
    if m < w:
        return empty, empty, empty
    th32 = np.float32(params.loop_sim_th)
    side = _tile_side()
    starts = list(range(0, m, side))
    total = len(starts) * (len(starts) + 1) // 2
    done = 0
    report(progress, 0, total, OURS_STAGE)
    keys, counts = [], []

    def keep(found):
        q, c, n = found
        if q.size:
            key, n = _max_per_key(q * m + c, n)
            keys.append(key)
            counts.append(n)

    for qi, q0 in enumerate(starts):
        q1 = min(m, q0 + side)
        qe = min(m, q1 + w - 1)  # the last windows starting in the tile reach w - 1 beyond it
        for c0 in starts[:qi + 1]:
            check(cancel)
            c1 = min(m, c0 + side)
            ce = min(m, c1 + w - 1)
            sims = v[c0:ce] @ v[q0:qe].T                        # (c rows + halo, q rows + halo)
            # The matches, sorted by (r, t) (1-D nonzero and divmod: 5x faster than 2-D nonzero).
            r, t = np.divmod(np.flatnonzero(sims >= th32), sims.shape[1])
            # Queries c0..c1-1, windows starting at q0..q1-1.
            mine = r < c1 - c0
            keep(_window_candidates(sims, r[mine], t[mine], params, c0, q0, q1 - q0, m))
            if c0 != q0:  # and transposed: queries q0..q1-1, windows starting at c0..c1-1
                mine = t < q1 - q0
                rt, tt = t[mine], r[mine]
                order = np.lexsort((tt, rt))
                keep(_window_candidates(sims.T, rt[order], tt[order], params, q0, c0, c1 - c0, m))
            done += 1
            report(progress, done, total, OURS_STAGE)
    if not keys:
        return empty, empty, empty

    # The set of directed pairs (q, c), each with its largest window count.
    uniq, best_count = _max_per_key(np.concatenate(keys), np.concatenate(counts))
    # Mutual check: (c, q) must be stored too.
    uq, uc = uniq // m, uniq % m
    rev = uc * m + uq
    pos = np.searchsorted(uniq, rev)
    pos = np.minimum(pos, uniq.size - 1)
    mutual = uniq[pos] == rev
    lower = mutual & (uq < uc)
    a, b = uq[lower], uc[lower]
    n = np.maximum(best_count[lower], best_count[pos[lower]])
    keep_ = b - a >= 2  # b - a == 1 is a path arc already
    return a[keep_], b[keep_], n[keep_]


def _tile_side() -> int:
    """Rows (and columns) of one similarity tile of the "ours" check: about
    ``_BLOCK_ELEMENTS`` / 2 float32 values, never fewer than 16 rows."""
    return max(16, int(np.sqrt(_BLOCK_ELEMENTS // 2)))


def _max_per_key(key: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique ``key`` and the largest ``count`` of each."""
    order = np.lexsort((count, key))
    key, count = key[order], count[order]
    last = np.ones(key.size, dtype=bool)
    last[:-1] = key[1:] != key[:-1]
    return key[last], count[last]


def _window_candidates(sims: np.ndarray, r: np.ndarray, t: np.ndarray, params: MapParams, r0: int,
                       s0: int, n_starts: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stored pairs (q, c) and window counts for the queries ``r0 + row`` (rows of ``sims``)
    and the windows starting at nodes ``s0 .. s0 + n_starts - 1``.

    ``sims[row, col]`` is the similarity of query ``r0 + row`` to node ``s0 + col``, for
    every node of those windows (col < min(n_starts + window_size - 1, m - s0)); (r, t)
    are the (row, col) of the matches (similarity >= loop_sim_th) of those rows and
    columns, sorted by row, then column.

    A window [s, s + w) is a candidate iff it holds more than count_th matches. Take its
    first match, hit i of its row (matches sorted by column): the window holds hits
    i .. i + count_th, so hit i + count_th lies in the same row within w - 1 columns of
    hit i, and s lies in (previous match, t_i] and in [t_{i+count_th} - w + 1, t_i].
    Enumerating, for every such i, those s gives each candidate window exactly once; its
    count is the number of matches in [s, s + w). The neighbourhood skip and the argmax
    (first most similar node of the window, as np.argmax) are then the paper's.
    """
    w, ct, nn = int(params.window_size), int(params.count_th), int(params.neighbor_node_num)
    empty = np.zeros(0, np.int64)
    last_start = min(n_starts, m - w - s0 + 1) - 1           # local index of the last window start
    if last_start < 0:
        return empty, empty, empty
    k = r.size
    if k <= ct:
        return empty, empty, empty
    i = np.arange(k - ct)
    j = i + ct
    first = i[(r[j] == r[i]) & (t[j] - t[i] <= w - 1)]        # hits that open a candidate window
    if first.size == 0:
        return empty, empty, empty
    ri, ti = r[first], t[first]
    lo = t[first + ct] - (w - 1)
    before = first - 1
    same_row = (first > 0) & (r[np.maximum(before, 0)] == ri)
    lo = np.maximum(lo, np.where(same_row, t[np.maximum(before, 0)] + 1, 0))
    hi = np.minimum(ti, last_start)
    s = lo[:, None] + np.arange(w)                           # at most w starts per opening hit
    ok = s <= hi[:, None]
    opener = np.broadcast_to(first[:, None], s.shape)[ok]
    s = s[ok]
    rows = r[opener]
    q, sg = rows + r0, s + s0
    ok = (sg > q + nn) | (sg + w - 1 < q - nn)                # the window meets [q - nn, q + nn]: skipped
    opener, s, rows, q, sg = opener[ok], s[ok], rows[ok], q[ok], sg[ok]
    if s.size == 0:
        return empty, empty, empty
    stride = int(sims.shape[1]) + 1                           # > any column + w: keys never spill rows
    key = r.astype(np.int64) * stride + t
    count = np.searchsorted(key, rows.astype(np.int64) * stride + s + w) - opener
    best = np.argmax(sims[rows[:, None], s[:, None] + np.arange(w)], axis=1)  # first max on ties
    return q.astype(np.int64), (sg + best).astype(np.int64), count.astype(np.int64)
