"""Pictures of a map for reports and benchmarks (matplotlib, Agg backend, no Qt).

``plot_map`` draws, side by side: the nodes and arcs on ground-truth positions
(or a layout of the graph when positions are unknown) with loops coloured by their
truth, and the node similarity matrix with the loops marked on it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import networkx as nx
import numpy as np

from .evaluate import Evaluation, node_positions
from .graph import TopoMap
from .limits import MAX_DENSE_NODES
from .loops import similarity_matrix
from .poses import Poses

COLOURS = {"TP": "tab:green", "FP": "tab:red", "FN": "tab:orange", "TN": "tab:gray",
           None: "tab:blue"}


def _layout(topomap: TopoMap, poses: Optional[Poses]) -> tuple[np.ndarray, np.ndarray, bool]:
    """(x, y, metric): ground-truth positions when known, else a spring layout."""
    if poses is not None or topomap.positions() is not None:
        x, y = node_positions(topomap, poses)
        return np.asarray(x), np.asarray(y), True
    ids = [topomap.node_id(k) for k in range(topomap.node_count)]
    if not ids:
        return np.zeros(0), np.zeros(0), False
    pos = nx.spring_layout(topomap.graph, seed=0, iterations=100)
    xy = np.array([pos[n] for n in ids])
    return xy[:, 0], xy[:, 1], False


def plot_map(topomap: TopoMap, poses: Optional[Poses], evaluation: Optional[Evaluation],
             path: str | Path) -> None:
    """Save a PNG: the map (left) and the similarity matrix with loops (right)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    x, y, metric = _layout(topomap, poses)
    index = {n: int(d["index"]) for n, d in topomap.graph.nodes(data=True)}
    truth = evaluation.loop_truth if evaluation is not None else {}

    fig = Figure(figsize=(13, 6), dpi=100)
    ax, axm = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.15, 1]})

    # Missed same-place pairs first, faint, so everything else draws over them.
    if evaluation is not None and evaluation.fn_pairs:
        fn = np.asarray(evaluation.fn_pairs)
        segs = np.stack([np.c_[x[fn[:, 0]], y[fn[:, 0]]], np.c_[x[fn[:, 1]], y[fn[:, 1]]]], axis=1)
        from matplotlib.collections import LineCollection

        ax.add_collection(LineCollection(segs, colors="tab:orange", alpha=0.25, linewidths=0.8,
                                         linestyles="dotted", zorder=1))
    ax.plot(x, y, "-", color="0.55", lw=1.0, zorder=2)
    ax.scatter(x, y, s=9, c=np.arange(x.size), cmap="viridis", zorder=3)
    if x.size:
        ax.annotate("start", (x[0], y[0]), xytext=(4, 4), textcoords="offset points", fontsize=8)

    loop_marks = []
    for u, v, d in topomap.loops():
        i, j = index[u], index[v]
        t = truth.get((u, v))
        rejected = d.get("status") == "rejected"
        colour = COLOURS[t] if (t or not rejected) else "0.6"
        # Over the nodes: at a revisit the two nodes are close and the arc is short.
        # True loops on top of false ones, so a crowd of FPs cannot hide them.
        ax.plot([x[i], x[j]], [y[i], y[j]], color=colour, lw=2.0,
                ls="--" if rejected else "-", alpha=0.6 if rejected else 0.9,
                zorder=5 if t == "TP" else 4)
        loop_marks.append((i, j, colour, rejected))

    handles = [Line2D([], [], color="0.55", label="path")]
    if evaluation is not None:
        handles += [Line2D([], [], color=COLOURS["TP"], label=f"loop TP ({evaluation.tp})"),
                    Line2D([], [], color=COLOURS["FP"], label=f"loop FP ({evaluation.fp})"),
                    Line2D([], [], color=COLOURS["FN"], ls=":", alpha=0.6,
                           label=f"missed same place ({evaluation.fn})")]
    else:
        handles.append(Line2D([], [], color=COLOURS[None], label="loop"))
    if any(r for *_, r in loop_marks):
        handles.append(Line2D([], [], color="0.4", ls="--", label="rejected (dashed)"))
    ax.legend(handles=handles, loc="best", fontsize=8)
    ax.set_aspect("equal" if metric else "auto", adjustable="datalim")
    title = "map on ground-truth positions (m)" if metric else "map (graph layout, no positions)"
    if evaluation is not None:
        title += (f"\nprecision {evaluation.ratio_text('precision', digits=2)}  "
                  f"recall {evaluation.ratio_text('recall', digits=2)}  "
                  f"F1 {evaluation.ratio_text('f1', digits=2)}  events {evaluation.events_found}/{evaluation.events_total}")
    ax.set_title(title, fontsize=10)
    if not metric:
        ax.set_xticks([])
        ax.set_yticks([])

    # Right: similarity matrix (when descriptors are at hand) with loops overlaid.
    m = topomap.node_count
    if topomap.node_vectors is not None and 0 < m <= MAX_DENSE_NODES:  # an m x m picture
        img = axm.imshow(similarity_matrix(topomap.node_vectors), cmap="magma", vmin=-0.2, vmax=1.0,
                         interpolation="nearest")
        fig.colorbar(img, ax=axm, fraction=0.046, pad=0.04, label="cosine similarity")
        axm.set_title("node similarity with loops", fontsize=10)
    else:
        axm.set_xlim(-0.5, m - 0.5)
        axm.set_ylim(m - 0.5, -0.5)
        axm.set_aspect("equal")
        why = "no descriptors" if topomap.node_vectors is None or not m else f"over {MAX_DENSE_NODES:,} nodes"
        axm.set_title(f"loops by node index ({why})", fontsize=10)
    if evaluation is not None and evaluation.fn_pairs:
        fn = np.asarray(evaluation.fn_pairs)
        axm.scatter(fn[:, 1], fn[:, 0], s=6, color=COLOURS["FN"], alpha=0.5, marker="s",
                    linewidths=0, label="missed")
    if loop_marks:
        li, lj, lc, _ = zip(*loop_marks)
        # Both triangles, so the pair shows whichever way one reads the matrix.
        axm.scatter(lj + li, li + lj, s=18, facecolors="none", edgecolors=lc + lc, linewidths=1.2)
    axm.set_xlabel("node")
    axm.set_ylabel("node")

    fig.tight_layout()
    from .outputs import write_atomically

    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in fig.canvas.get_supported_filetypes():
        suffix = "png"
    write_atomically(path, lambda f: fig.savefig(f, format=suffix))
