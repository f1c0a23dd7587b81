"""Loop-closure quality against ground-truth positions (METHOD.md section 6).

How pairs are counted (following the paper):

* Every unordered node pair (i, j), i < j, is considered, except directly
  consecutive nodes (j - i == 1): those are path arcs, never loops. With m nodes
  that is (m - 1)(m - 2) / 2 pairs; TP + FP + TN + FN always equals it.
* Same place: metric distance between the two node positions <= ``dist_th`` (a nanometre
  of slack, so that a pair exactly ``dist_th`` apart is not lost to rounding).
* Temporal neighbours: j - i <= ``neighbor_node_num`` (the map's parameter by default).
* Detected: the pair is joined by a loop arc whose status is not "rejected" nor an
  undecided "candidate" (auto, confirmed and manual arcs count: what the exported map
  holds); ``include_candidates=True`` counts candidates too (what a person reviewing the
  queue would be shown).
* TP: detected, same place, not temporal neighbours.
* FP: detected, and different places OR temporal neighbours (a loop between
  temporal neighbours breaks the topology, so the paper counts it as FP even when
  the two nodes are close).
* FN: same place, not temporal neighbours, not detected.
* TN: all other pairs (not detected, and different places or temporal neighbours).

precision = TP / (TP + FP), recall = TP / (TP + FN), accuracy = (TP + TN) / pairs,
F1 = 2 TP / (2 TP + FP + FN); each is 0.0 when its denominator is 0.

Revisit events: the positive pairs (same place, not temporal neighbours) form
connected groups in the (i, j) grid when 8-neighbouring (i and j each differing by
at most one node); each group is one revisit event (driving along a stretch a second
time gives a diagonal run of pairs). An event is found when any TP falls in it.

Node positions: from ``poses`` at the node stamps when poses are given, else from
the nodes' own ``x``/``y`` attributes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Optional

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .errors import InputError
from .graph import TopoMap
from .poses import Poses

# Bound the per-block distance matrix to about 32 MB of float64.
_BLOCK_ELEMENTS = 4_000_000
# "Within dist_th" includes dist_th itself: a pair 0.6 m along and 0.8 m across is 1.0 m
# apart, but its squared distance computes as 1 + 2e-15. A nanometre of slack absorbs that.
_DIST_SLACK = 1e-9


def _within(d2, dist_th: float):
    """Squared distances ``d2`` within ``dist_th`` metres (rounding errors included)."""
    return d2 <= (dist_th + _DIST_SLACK) ** 2


@dataclass
class Evaluation:
    tp: int
    fp: int
    tn: int
    fn: int
    precision: float
    recall: float
    accuracy: float
    f1: float
    tp_pairs: list[tuple[int, int]] = field(default_factory=list)   # node indices (i, j), i < j
    fp_pairs: list[tuple[int, int]] = field(default_factory=list)
    fn_pairs: list[tuple[int, int]] = field(default_factory=list)
    events_found: int = 0
    events_total: int = 0
    # Truth of every loop arc, rejected ones included, keyed by node ids (u, v), u lower:
    # "TP"/"FP" for detected arcs, "FN" (a true loop was rejected) / "TN" for rejected ones.
    loop_truth: dict[tuple[str, str], str] = field(default_factory=dict)
    dist_th: float = 1.0
    neighbor_node_num: int = 0
    # Per revisit event: how close the two visits came (metres, its closest same-place pair)
    # and whether it was found; a benchmark reads how recall depends on that distance.
    event_closest: list[float] = field(default_factory=list)
    event_found: list[bool] = field(default_factory=list)
    # ... and how long the robot was away: the most nodes along the path between the two
    # nodes of one of its same-place pairs (a tight turn comes back within a few nodes).
    event_span: list[int] = field(default_factory=list)

    def undefined(self) -> tuple[str, ...]:
        """The ratios with a zero denominator (no detections: precision; no positives: recall).

        Their stored value is 0.0 (kept for old readers); shown, they read "n/a", not 0 %.
        """
        denominators = {"precision": self.tp + self.fp, "recall": self.tp + self.fn,
                        "accuracy": self.tp + self.fp + self.tn + self.fn,
                        "f1": 2 * self.tp + self.fp + self.fn}
        return tuple(name for name, den in denominators.items() if den == 0)

    def ratio_text(self, name: str, percent: bool = False, digits: int = 3) -> str:
        """``name`` ("precision", "recall", "accuracy", "f1") as text: "n/a" when undefined."""
        if name in self.undefined():
            return "n/a"
        value = float(getattr(self, name))
        return f"{100 * value:.{max(digits - 2, 0)}f} %" if percent else f"{value:.{digits}f}"

    @property
    def event_coverage(self) -> float:
        return self.events_found / self.events_total if self.events_total else 0.0

    def as_dict(self) -> dict:
        """JSON-ready (pairs as lists, loop keys as "u-v")."""
        d = asdict(self)
        d["loop_truth"] = {f"{u}-{v}": t for (u, v), t in self.loop_truth.items()}
        for k in ("tp_pairs", "fp_pairs", "fn_pairs"):
            d[k] = [list(p) for p in d[k]]
        d["event_coverage"] = self.event_coverage
        return d


def node_positions(topomap: TopoMap, poses: Optional[Poses]) -> tuple[np.ndarray, np.ndarray]:
    if poses is not None:
        if len(poses) == 0:
            raise InputError("the ground-truth poses are empty")
        from .validate import poses_cover

        poses_cover(poses, topomap.stamps(), "the ground-truth poses")
        return poses.at(topomap.stamps())
    pos = topomap.positions()
    if pos is None:
        raise InputError("no ground-truth poses given and the map's nodes have no x, y positions")
    return pos


def _ratio(num: int, den: int) -> float:
    return num / den if den else 0.0


def _positive_pairs(x: np.ndarray, y: np.ndarray, dist_th: float, nn: int) -> tuple[np.ndarray, np.ndarray]:
    """Same-place pairs (i, j) with j - i > max(nn, 1), sorted by (i, j); blocked over rows."""
    m = x.size
    gap = max(nn, 1)
    rows = max(1, _BLOCK_ELEMENTS // max(m, 1))
    cols = np.arange(m)
    pi, pj = [], []
    for i0 in range(0, m, rows):
        i1 = min(m, i0 + rows)
        d2 = (x[i0:i1, None] - x[None, :]) ** 2 + (y[i0:i1, None] - y[None, :]) ** 2
        ii = np.arange(i0, i1)[:, None]
        r, c = np.nonzero(_within(d2, dist_th) & (cols[None, :] - ii > gap))
        pi.append(r + i0)
        pj.append(c)
    if not pi:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(pi).astype(np.int64), np.concatenate(pj).astype(np.int64)


def _events(pi: np.ndarray, pj: np.ndarray, m: int) -> np.ndarray:
    """Event label per positive pair: connected components with 8-neighbourhood in (i, j)."""
    n = pi.size
    if n == 0:
        return np.zeros(0, np.int64)
    keys = pi * m + pj  # sorted, since pairs come row by row with increasing j
    src, dst = [np.arange(n)], [np.arange(n)]
    for di, dj in ((0, 1), (1, -1), (1, 0), (1, 1)):  # half the 8 neighbours suffice (undirected)
        ni, nj = pi + di, pj + dj
        ok = (ni < m) & (nj >= 0) & (nj < m)
        probe = ni * m + nj
        at = np.minimum(np.searchsorted(keys, probe), n - 1)
        hit = ok & (keys[at] == probe)
        src.append(np.flatnonzero(hit))
        dst.append(at[hit])
    s, d = np.concatenate(src), np.concatenate(dst)
    adj = coo_matrix((np.ones(s.size, np.int8), (s, d)), shape=(n, n))
    return connected_components(adj, directed=False)[1].astype(np.int64)


def evaluate(topomap: TopoMap, poses: Optional[Poses] = None, dist_th: float = 1.0,
             neighbor_node_num: Optional[int] = None, include_candidates: bool = False) -> Evaluation:
    """Count TP/FP/TN/FN of the map's loop arcs against ground truth (see module doc).

    A map without nodes is refused (InputError): it has nothing to evaluate, and its
    four zeros read like a result."""
    if not dist_th >= 0 or dist_th == float("inf"):  # NaN compares false
        raise InputError(f"distance threshold must be a finite number >= 0, got {dist_th}")
    if topomap.graph.number_of_nodes() == 0:
        raise InputError("the map has no nodes: there is nothing to evaluate")
    if neighbor_node_num is None:
        neighbor_node_num = int(topomap.meta.get("neighbor_node_num", 0))
    nn = int(neighbor_node_num)
    x, y = (np.asarray(a, dtype=np.float64) for a in node_positions(topomap, poses))
    m = x.size
    index = {n: int(d["index"]) for n, d in topomap.graph.nodes(data=True)}

    # Positive pairs: same place, not temporal neighbours.
    pi, pj = _positive_pairs(x, y, dist_th, nn)
    pos_keys = pi * m + pj

    tp_pairs, fp_pairs, loop_truth = [], [], {}
    for u, v, d in topomap.loops():
        i, j = index[u], index[v]
        if j - i < 2:
            continue  # not a pair we count (a path arc)
        same = _within((x[i] - x[j]) ** 2 + (y[i] - y[j]) ** 2, dist_th)
        positive = bool(same) and j - i > nn
        if d.get("status") == "rejected" or (d.get("status") == "candidate" and not include_candidates):
            loop_truth[(u, v)] = "FN" if positive else "TN"
        elif positive:
            loop_truth[(u, v)] = "TP"
            tp_pairs.append((i, j))
        else:
            loop_truth[(u, v)] = "FP"
            fp_pairs.append((i, j))

    tp_keys = np.asarray([i * m + j for i, j in tp_pairs], dtype=np.int64)
    missed = ~np.isin(pos_keys, tp_keys)
    fn_pairs = [(int(i), int(j)) for i, j in zip(pi[missed], pj[missed])]

    tp, fp, fn = len(tp_pairs), len(fp_pairs), len(fn_pairs)
    total = (m - 1) * (m - 2) // 2 if m >= 2 else 0
    tn = total - tp - fp - fn

    labels = _events(pi, pj, m)
    event_ids, event_of_pair = np.unique(labels, return_inverse=True)
    event_closest = np.full(event_ids.size, np.inf)
    np.minimum.at(event_closest, event_of_pair, np.hypot(x[pi] - x[pj], y[pi] - y[pj]))
    event_found = np.zeros(event_ids.size, bool)
    event_found[event_of_pair[~missed]] = True
    event_span = np.zeros(event_ids.size, np.int64)
    np.maximum.at(event_span, event_of_pair, (pj - pi).astype(np.int64))
    found, events_total = int(event_found.sum()), int(event_ids.size)

    return Evaluation(
        tp=tp, fp=fp, tn=tn, fn=fn,
        precision=_ratio(tp, tp + fp), recall=_ratio(tp, tp + fn),
        accuracy=_ratio(tp + tn, total), f1=_ratio(2 * tp, 2 * tp + fp + fn),
        tp_pairs=tp_pairs, fp_pairs=fp_pairs, fn_pairs=fn_pairs,
        events_found=found, events_total=events_total,
        loop_truth=loop_truth, dist_th=float(dist_th), neighbor_node_num=nn,
        event_closest=event_closest.tolist(), event_found=event_found.tolist(),
        event_span=event_span.tolist(),
    )
