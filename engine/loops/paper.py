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

The "ours" check is vectorised: queries are processed in blocks of rows of the
similarity matrix; window counts come from a cumulative sum along each row, and the
argmax is taken only inside candidate windows.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..errors import InputError
from ..params import METHODS, MapParams
from ..retrieval import pair_similarities

# Bound the similarity block (rows x m float32) to about 32 MB.
_BLOCK_ELEMENTS = 8_000_000


@dataclass
class LoopCandidate:
    a: int                        # node index, a < b
    b: int
    similarity: float             # cos(node a, node b)
    window_count: int             # "ours": largest candidate-window count; 0 otherwise
    yaw: Optional[float] = None   # relative heading in degrees, when estimated
    score: Optional[float] = None  # any later verification score
    status: str = "auto"          # tier: "auto" (accepted) or "candidate" (for a person to review)
    evidence: dict = field(default_factory=dict)  # named numbers behind it (graph.EVIDENCE_KEYS)


def similarity_matrix(node_vectors: np.ndarray) -> np.ndarray:
    """(m, m) float32 cosine similarities of L2-normalised rows."""
    v = np.asarray(node_vectors, dtype=np.float32)
    return v @ v.T


def detect_loops(node_vectors: np.ndarray, params: MapParams) -> list[LoopCandidate]:
    """Loop candidates for ``params.method``, sorted by (a, b)."""
    v = np.asarray(node_vectors, dtype=np.float32)
    if v.ndim != 2:
        raise InputError(f"node descriptors must be a 2-D array, got shape {v.shape}")
    _check_params(params)
    if params.method == "verified":
        # Without the recording's column signatures: no yaw verification (see loops_verified).
        from ..loops_verified import verified_loops

        return verified_loops(v, params)
    if params.method == "ours":
        a, b, counts = _ours_pairs(v, params)
    else:
        a, b = _simple_pairs(v, float(params.loop_sim_th))
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


def _simple_pairs(v: np.ndarray, th: float) -> tuple[np.ndarray, np.ndarray]:
    m = v.shape[0]
    th32 = np.float32(th)
    a_parts, b_parts = [], []
    for q0, q1 in _row_blocks(m):
        sims = v[q0:q1] @ v.T
        qi, cj = np.nonzero(sims >= th32)
        qi = qi + q0
        keep = cj >= qi + 2  # one entry per unordered pair; b - a == 1 is a path arc
        a_parts.append(qi[keep])
        b_parts.append(cj[keep])
    if not a_parts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(a_parts).astype(np.int64), np.concatenate(b_parts).astype(np.int64)


def _ours_pairs(v: np.ndarray, params: MapParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    m = v.shape[0]
    w = int(params.window_size)
    nn = int(params.neighbor_node_num)
    th32 = np.float32(params.loop_sim_th)
    empty = np.zeros(0, np.int64)
    if m < w:
        return empty, empty, empty
    n_windows = m - w + 1
    offsets = np.arange(w)

    q_parts, c_parts, n_parts = [], [], []
    for q0, q1 in _row_blocks(m):
        sims = v[q0:q1] @ v.T                                   # (b, m)
        hits = np.zeros((q1 - q0, m + 1), dtype=np.int32)
        np.cumsum(sims >= th32, axis=1, out=hits[:, 1:])
        counts = hits[:, w:] - hits[:, :n_windows]              # counts[q, s] of window [s, s+w)
        qi, s = np.nonzero(counts > params.count_th)
        q = qi + q0
        # Window [s, s+w-1] meets the neighbourhood [q-nn, q+nn] -> skipped.
        keep = (s > q + nn) | (s + w - 1 < q - nn)
        qi, s, q = qi[keep], s[keep], q[keep]
        if q.size == 0:
            continue
        cols = s[:, None] + offsets                              # (k, w) node indices
        best = np.argmax(sims[qi[:, None], cols], axis=1)        # first max on ties
        q_parts.append(q)
        c_parts.append(s + best)
        n_parts.append(counts[qi, s])
    if not q_parts:
        return empty, empty, empty

    q = np.concatenate(q_parts).astype(np.int64)
    c = np.concatenate(c_parts).astype(np.int64)
    n = np.concatenate(n_parts).astype(np.int64)
    # The set of directed pairs (q, c), each with its largest window count.
    key = q * m + c
    uniq, inv = np.unique(key, return_inverse=True)
    best_count = np.zeros(uniq.size, dtype=np.int64)
    np.maximum.at(best_count, inv, n)
    # Mutual check: (c, q) must be stored too.
    uq, uc = uniq // m, uniq % m
    rev = uc * m + uq
    pos = np.searchsorted(uniq, rev)
    pos = np.minimum(pos, uniq.size - 1)
    mutual = uniq[pos] == rev
    lower = mutual & (uq < uc)
    a, b = uq[lower], uc[lower]
    counts = np.maximum(best_count[lower], best_count[pos[lower]])
    keep = b - a >= 2  # b - a == 1 is a path arc already
    return a[keep], b[keep], counts[keep]
