"""Node creation (METHOD.md section 3).

Walk the descriptor sequence: the first row is a node and the reference; each later
row j is skipped while cos(ref, v_j) >= node_sim_th, otherwise it becomes a node and
the new reference. The walk is sequential by nature, but between two nodes only the
similarity to one fixed reference matters, so we compare the reference against a
whole block of following rows with one matrix-vector product and jump straight to the
first row below the threshold. The block grows while no node is found (long stops)
and shrinks back near the last gap, so 100k rows take a few hundred products.
"""

from __future__ import annotations

import numpy as np

from .errors import InputError

_MIN_BLOCK = 16
_MAX_BLOCK = 8192


def make_nodes(vectors: np.ndarray, node_sim_th: float) -> np.ndarray:
    """Rows of ``vectors`` (n, d), L2-normalised, that become nodes; int64, increasing."""
    vectors = np.asarray(vectors)
    if vectors.ndim != 2:
        raise InputError(f"descriptors must be a 2-D array, got shape {vectors.shape}")
    n = vectors.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    vectors = vectors.astype(np.float32, copy=False)
    th = np.float32(node_sim_th)

    nodes = [0]
    ref = 0
    pos = 1          # first row not yet compared with the current reference
    block = _MIN_BLOCK
    while pos < n:
        stop = min(n, pos + block)
        sims = vectors[pos:stop] @ vectors[ref]
        below = np.flatnonzero(sims < th)
        if below.size == 0:
            pos = stop
            block = min(block * 2, _MAX_BLOCK)  # a long stop: look further ahead
            continue
        j = pos + int(below[0])
        nodes.append(j)
        # Next gap is probably like this one: size the block to about twice it.
        block = int(min(max(2 * (j - ref), _MIN_BLOCK), _MAX_BLOCK))
        ref = j
        pos = j + 1
    return np.asarray(nodes, dtype=np.int64)
