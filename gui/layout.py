"""Where to draw the nodes when no ground truth is loaded.

The path starts as a straight line in driving order, then a small vectorised
Fruchterman-Reingold pass with the path arcs and the loop arcs (rejected ones
left out) as springs folds it where the engine believes places are the same, so a
loop-shaped route looks like one. A walk with no loops stays a straight line: it
never crosses itself (issue 14, defect 15: a spiral start drew a straight walk as
a self-crossing spiral). networkx' layouts take seconds for a few hundred nodes
and the map is rebuilt on every parameter change, hence our own. Maps over
``FORCE_MAX_NODES`` are laid out as a serpentine (rows walked left, right, left…),
which does not cross itself either; their loops are curves across it.
"""

from __future__ import annotations

import numpy as np

# Above this the O(n^2) force pass costs more than ~0.5 s per rebuild (measured:
# 0.47 s at 700 nodes, 80 iterations, on this project's shared 2-core machine).
FORCE_MAX_NODES = 700
ITERATIONS = 80


def path_layout(topomap, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) per node, in node order, scaled so one path step is about 1."""
    n = int(topomap.node_count)
    if n <= 1:
        return np.zeros(n), np.zeros(n)
    index = {node: int(d["index"]) for node, d in topomap.graph.nodes(data=True)}
    loops = np.array([(index[u], index[v]) for u, v, a in topomap.loops() if a.get("status") != "rejected"],
                     dtype=np.int64).reshape(-1, 2)
    if n > FORCE_MAX_NODES:
        xy = serpentine(n)
    elif loops.size == 0:
        xy = np.stack([np.arange(n, dtype=np.float64), np.zeros(n)], axis=1)  # nothing to fold
    else:
        path = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
        xy = _force_layout(n, np.concatenate([path, loops]), seed).astype(np.float64)
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


def _force_layout(n: int, edges: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    # Start from the straight path (the order of driving), slightly jittered off the line
    # so the loop springs can fold it sideways.
    xy = np.stack([np.linspace(-1.0, 1.0, n), rng.normal(scale=0.01, size=n)], axis=1).astype(np.float32)
    k = 1.0 / np.sqrt(n)                       # ideal edge length in a unit square
    temperature = 0.1
    a, b = edges[:, 0], edges[:, 1]
    for _ in range(ITERATIONS):
        dx = xy[:, 0, None] - xy[None, :, 0]
        dy = xy[:, 1, None] - xy[None, :, 1]
        inv = (k * k) / (dx * dx + dy * dy + 1e-9)            # repulsion k^2 / d
        disp = np.stack([(dx * inv).sum(axis=1), (dy * inv).sum(axis=1)], axis=1)
        d = xy[a] - xy[b]
        dist = np.linalg.norm(d, axis=1, keepdims=True) + 1e-9
        pull = d * (dist / k)                                  # attraction d^2 / k
        np.add.at(disp, a, -pull)
        np.add.at(disp, b, pull)
        length = np.linalg.norm(disp, axis=1, keepdims=True) + 1e-9
        xy += disp / length * np.minimum(length, temperature)
        temperature *= 0.95
    return xy
