"""Where to draw the nodes when no ground truth is loaded.

Nodes are placed so that their distances on the drawing follow their distances in
the graph of path arcs and loop arcs (rejected ones left out): stress majorization
(SMACOF) of the hop distances, from the walk drawn straight. A walk with no loops has
hop distances of a straight line, so it is drawn as one and never crosses itself (issue 14, defect 15: the force layout started
on a spiral drew a straight walk as a self-crossing spiral); a loop pulls the two
visits of a place together, so a loop-shaped route looks like a loop. Maps over
``EMBED_MAX_NODES`` are laid out as a serpentine (rows walked left, right, left…),
which does not cross itself either; their loops are curves across it.
"""

from __future__ import annotations

import numpy as np

# Above this the n x n stress iterations cost more than ~0.3 s per rebuild (the map is
# rebuilt on every parameter change; measured 0.29 s at 400 nodes on this project's shared
# 2-core machine under a load of 16): the serpentine takes over.
EMBED_MAX_NODES = 400
SMACOF_ITERATIONS = 60


def path_layout(topomap) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) per node, in node order, scaled so one path step is about 1."""
    n = int(topomap.node_count)
    if n <= 1:
        return np.zeros(n), np.zeros(n)
    index = {node: int(d["index"]) for node, d in topomap.graph.nodes(data=True)}
    loops = np.array([(index[u], index[v]) for u, v, a in topomap.loops() if a.get("status") != "rejected"],
                     dtype=np.int64).reshape(-1, 2)
    if n > EMBED_MAX_NODES:
        xy = serpentine(n)
    elif loops.size == 0:
        xy = np.stack([np.arange(n, dtype=np.float64), np.zeros(n)], axis=1)  # nothing to fold
    else:
        path = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
        xy = _distance_layout(n, np.concatenate([path, loops]))
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    scale = float(np.median(steps)) if steps.size and np.median(steps) > 0 else 1.0
    xy = (xy - xy.mean(axis=0)) / scale
    return xy[:, 0].copy(), xy[:, 1].copy()


def serpentine(n: int) -> np.ndarray:
    """(n, 2): the path walked along rows of unit steps, left to right, then right to left.

    Rows are ``row_gap`` steps apart (room for the loop curves between them) and
    as long as makes the drawing about twice as wide as high, like a graph view;
    the walk turns at alternate ends, so it never crosses itself.
    """
    row_gap = 4
    row = max(int(np.ceil(np.sqrt(2 * n * row_gap))), 2)
    k = np.arange(n)
    r, c = k // row, k % row
    x = np.where(r % 2 == 0, c, row - 1 - c).astype(np.float64)
    return np.stack([x, -row_gap * r.astype(np.float64)], axis=1)


def _distance_layout(n: int, edges: np.ndarray) -> np.ndarray:
    """(n, 2) positions whose distances follow the hop distances over ``edges`` (SMACOF)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import shortest_path

    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    d = shortest_path(graph, directed=False, unweighted=True)
    d[~np.isfinite(d)] = d[np.isfinite(d)].max() + 1
    # Start from the walk drawn straight, bent a little so the loops can fold it sideways
    # (a straight start would stay on its line); SMACOF then folds it.
    t = np.arange(n, dtype=np.float64)
    xy = np.stack([t, 0.1 * n * np.sin(np.pi * t / max(n - 1, 1))], axis=1)
    # SMACOF (Guttman transform, unit weights): each step lowers the stress.
    diag = np.arange(n)
    for _ in range(SMACOF_ITERATIONS):
        sq = (xy * xy).sum(axis=1)
        cur = np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2.0 * (xy @ xy.T), 1e-12))
        ratio = d / cur            # B(X) = -d/cur off the diagonal, row sums on it
        ratio[diag, diag] = 0.0
        xy = (ratio.sum(axis=1)[:, None] * xy - ratio @ xy) / n
    return xy
