"""Where to draw the nodes when no ground truth is loaded.

A force layout of the driven path plus its loop candidates (rejected ones left
out): the path reads as a line, and places the engine believes are the same are
pulled together, so a loop-shaped route looks like one. It is a small vectorised
Fruchterman-Reingold (networkx' layouts take seconds for a few hundred nodes and
the map is rebuilt on every parameter change). Very large maps fall back to a
circle, where loops are chords.
"""

from __future__ import annotations

import numpy as np

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
    path = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    if n > FORCE_MAX_NODES:
        t = 2 * np.pi * np.arange(n) / n
        xy = np.stack([np.cos(t), np.sin(t)], axis=1) * n / (2 * np.pi)
    else:
        xy = _force_layout(n, np.concatenate([path, loops]), seed)
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    scale = float(np.median(steps)) if steps.size and np.median(steps) > 0 else 1.0
    xy = ((xy - xy.mean(axis=0)) / scale).astype(np.float64)
    return xy[:, 0].copy(), xy[:, 1].copy()


def _force_layout(n: int, edges: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    # Start on a spiral: the path is untangled from the first iteration on.
    t = np.linspace(0, 4 * np.pi, n)
    xy = np.stack([np.cos(t) * (1 + t), np.sin(t) * (1 + t)], axis=1)
    xy += rng.normal(scale=0.01, size=xy.shape)
    xy = (xy / np.abs(xy).max()).astype(np.float32)
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
