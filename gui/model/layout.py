"""Where to draw the nodes when no ground truth is loaded: the map as decided (no Qt).

``decided_layout(topomap)`` draws the DECIDED graph only: the path's sequential arcs
and the loops kept (auto, confirmed, manual), never a candidate nobody has accepted
nor a rejected loop (issue 43, defect 2: 35 undecided candidates tied the path into a
knot, and rejecting them all left it). The window solves it again after each decision.
When the map carries positions estimated by the pose graph (``engine/loops``: node
``x``, ``y`` and the graph attribute ``positions`` == "estimated") and no decision has
changed since they were estimated, those are used as they are.

Nodes are placed so that their distances on the drawing follow their distances in
the graph of path arcs and kept loop arcs: stress majorization
(SMACOF) of the hop distances, from the walk drawn straight. A walk with no loops has
hop distances of a straight line, so it is drawn as one and never crosses itself (issue 14, defect 15: the force layout started
on a spiral drew a straight walk as a self-crossing spiral); a loop pulls the two
visits of a place together, so a loop-shaped route looks like a loop. Maps over
``EMBED_MAX_NODES`` are laid out as a serpentine (rows walked left, right, left…),
which does not cross itself either; their loops are curves across it.

A site (several recordings, ``engine.site``) has one path per recording: no path arc
joins the last node of one recording to the first of the next (``DecidedGraph.breaks``),
so recordings are placed by the loops that join them; recordings no loop joins are
drawn one below the other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

# Above this the n x n stress iterations cost more than ~0.3 s per rebuild (the map is
# rebuilt on every parameter change; measured 0.29 s at 400 nodes on this project's shared
# 2-core machine under a load of 16): the serpentine takes over.
EMBED_MAX_NODES = 400
SMACOF_ITERATIONS = 60


# The loops that are part of the map as decided: accepted by detection or by a person.
KEPT = ("auto", "confirmed", "manual")


def estimated_positions(topomap, decided_since: bool = False) -> Optional[np.ndarray]:
    """(n, 2) positions the pose graph estimated for this map, or None: when the map has
    none, or a decision changed since (``decided_since``) so they no longer hold."""
    if decided_since or topomap.graph.graph.get("positions") != "estimated":
        return None
    xy = topomap.positions(estimated=True)
    return None if xy is None else np.stack(xy, axis=1).astype(np.float64)


@dataclass(frozen=True)
class DecidedGraph:
    """What the layout needs of a map, copied out of it (a worker thread may solve it while
    the user goes on deciding: it never reads the live map)."""

    n: int
    loops: np.ndarray                        # (k, 2) node indices of the kept loops
    estimated: Optional[np.ndarray] = None   # (n, 2) the pose graph's positions, still valid
    breaks: tuple = ()                       # a site: node indices where another recording starts


def chain_breaks(topomap) -> tuple:
    """Node indices where a site's next recording starts (() for one recording)."""
    sessions = topomap.node_sessions()
    if sessions is None or len(sessions) < 2:
        return ()
    return tuple(int(k) for k in np.flatnonzero(sessions[1:] != sessions[:-1]) + 1)


def path_pairs(n: int, breaks: tuple = ()) -> np.ndarray:
    """(m, 2) node indices of the path arcs: consecutive nodes of one recording."""
    starts = np.arange(n - 1)
    keep = ~np.isin(starts + 1, np.asarray(breaks, np.int64)) if breaks else np.ones(starts.size, bool)
    return np.stack([starts[keep], starts[keep] + 1], axis=1) if n > 1 else np.zeros((0, 2), np.int64)


def decided_graph(topomap, decided_since: bool = False) -> DecidedGraph:
    """The decided graph of ``topomap`` as plain arrays (cheap: run it on the UI thread)."""
    n = int(topomap.node_count)
    estimated = estimated_positions(topomap, decided_since)
    index = {node: int(d["index"]) for node, d in topomap.graph.nodes(data=True)}
    loops = np.array([(index[u], index[v]) for u, v, _a in topomap.loops(KEPT)],
                     dtype=np.int64).reshape(-1, 2)
    return DecidedGraph(n, loops, estimated, chain_breaks(topomap))


def solve_layout(graph: DecidedGraph, start: Optional[np.ndarray] = None) -> np.ndarray:
    """(n, 2) drawing positions of ``graph``, one path step about 1 (safe in a worker)."""
    n = graph.n
    if graph.estimated is not None:
        return graph.estimated
    if n <= 1:
        return np.zeros((n, 2))
    if n > EMBED_MAX_NODES:
        xy = serpentine(n)
    elif graph.loops.size == 0:   # nothing to fold: each recording a straight row of its own
        chain = np.searchsorted(np.asarray(graph.breaks, np.int64), np.arange(n), side="right")
        first = np.concatenate([[0], np.asarray(graph.breaks, np.int64)])[chain]
        xy = np.stack([np.arange(n, dtype=np.float64) - first, -4.0 * chain], axis=1)
    else:
        xy = _distance_layout(n, np.concatenate([path_pairs(n, graph.breaks), graph.loops]),
                              start if start is not None and start.shape == (n, 2) else None)
    steps = np.linalg.norm(xy[path_pairs(n, graph.breaks)[:, 1]] - xy[path_pairs(n, graph.breaks)[:, 0]], axis=1)
    scale = float(np.median(steps)) if steps.size and np.median(steps) > 0 else 1.0
    return (xy - xy.mean(axis=0)) / scale


def decided_layout(topomap, decided_since: bool = False, start: Optional[np.ndarray] = None) -> np.ndarray:
    """(n, 2) drawing positions of the map as decided, in node order, one path step about 1.

    ``decided_since``: a decision was made after the map's positions were estimated;
    ``start``: the drawing shown now, to start from (the layout moves little per decision).
    """
    return solve_layout(decided_graph(topomap, decided_since), start)


def path_layout(topomap) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) per node of ``decided_layout`` (the graph view's form)."""
    xy = decided_layout(topomap)
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


def _distance_layout(n: int, edges: np.ndarray, start: Optional[np.ndarray] = None) -> np.ndarray:
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
    if start is not None:   # the drawing shown, scaled to hop units: a decision moves it a little
        centred = start - start.mean(axis=0)
        spread = np.linalg.svd(centred, compute_uv=False)
        if spread[-1] > 1e-3 * spread[0]:   # a straight drawing would stay on its line: bent start
            steps = np.linalg.norm(np.diff(start, axis=0), axis=1)
            scale = float(np.median(steps)) if steps.size and np.median(steps) > 0 else 1.0
            xy = centred / scale
    # SMACOF (Guttman transform, unit weights): each step lowers the stress.
    diag = np.arange(n)
    for _ in range(SMACOF_ITERATIONS):
        sq = (xy * xy).sum(axis=1)
        cur = np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2.0 * (xy @ xy.T), 1e-12))
        ratio = d / cur            # B(X) = -d/cur off the diagonal, row sums on it
        ratio[diag, diag] = 0.0
        xy = (ratio.sum(axis=1)[:, None] * xy - ratio @ xy) / n
    return xy
