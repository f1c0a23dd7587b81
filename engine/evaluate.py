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

Several recordings (a site map: nodes carry ``session``): ``poses`` is a dict session ->
Poses (each recording's ground truth on its own clock, all in one world frame). Nodes of
different recordings are never temporal neighbours and never joined by a path arc, so every
pair across recordings counts (pairs = all pairs less the path arcs); the counts across
recordings are also given apart (``cross_tp``, ``cross_fp``, ``cross_fn`` and the revisit
events with a pair across recordings, ``cross_events_found`` / ``cross_events_total``); the
within-recording figures are the totals less these.

The project's own figures (``evaluate_band``; issue 41, the owner's call): the paper's table
above stays at its ``dist_th`` (1 m); beside it, a loop is scored by how far apart its two views
are, with a don't-care band as place-recognition benchmarks have:

* true: within ``found_within`` (1 m), not temporal neighbours (the paper's TP at 1 m);
* don't care: more than ``found_within`` and at most ``false_beyond`` (1-2 m) apart, not temporal
  neighbours: neither right nor false (the two views may well show one place);
* false: more than ``false_beyond`` (2 m) apart, or between temporal neighbours at any distance
  (the paper's rule, kept: such a loop breaks the topology; counted apart too, as
  ``neighbour_loops``). A false loop is therefore always a paper FP; a don't-care loop is a
  paper FP that the band forgives.
* a place (a revisit event at ``found_within``, as above) is found when a true loop joins two
  of its views: places found / places revisited equal the events of ``evaluate`` at
  ``dist_th = found_within``.

Which loops count is as above (rejected never, candidates with ``include_candidates``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from enum import Enum
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
    # Several recordings (a site map): the pairs and events across recordings, apart.
    cross_tp: int = 0
    cross_fp: int = 0
    cross_fn: int = 0
    cross_events_found: int = 0
    cross_events_total: int = 0
    sessions: int = 1

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


def node_positions(topomap: TopoMap, poses) -> tuple[np.ndarray, np.ndarray]:
    """Node (x, y) from ``poses`` (a Poses, or a dict session -> Poses for a site map) at
    the node stamps, else from the nodes' own positions."""
    if isinstance(poses, dict):
        return _session_positions(topomap, poses)
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


def _session_positions(topomap: TopoMap, poses: dict) -> tuple[np.ndarray, np.ndarray]:
    from .validate import poses_cover

    sessions = topomap.node_sessions()
    if sessions is None:
        if len(poses) != 1:
            raise InputError(f"the map is of one recording; give one set of poses, not {len(poses)}")
        return node_positions(topomap, next(iter(poses.values())))
    stamps = topomap.stamps()
    x, y = np.zeros(stamps.size), np.zeros(stamps.size)
    for name in dict.fromkeys(sessions.tolist()):
        if name not in poses:
            raise InputError(f"no ground-truth poses for the recording {name}")
        mine = sessions == name
        if len(poses[name]) == 0:
            raise InputError(f"the ground-truth poses of {name} are empty")
        poses_cover(poses[name], stamps[mine], f"the ground-truth poses of {name}")
        x[mine], y[mine] = poses[name].at(stamps[mine])
    unknown = sorted(set(poses) - set(sessions.tolist()))
    if unknown:
        raise InputError(f"poses given for {unknown[0]}, which is not a recording of this map")
    return x, y


def _session_codes(topomap: TopoMap) -> Optional[np.ndarray]:
    """Each node's recording as an integer (node order), None for a one-recording map."""
    sessions = topomap.node_sessions()
    if sessions is None:
        return None
    return np.unique(sessions.astype(str), return_inverse=True)[1].astype(np.int64)


def _ratio(num: int, den: int) -> float:
    return num / den if den else 0.0


def _positive_pairs(x: np.ndarray, y: np.ndarray, dist_th: float, nn: int,
                    codes: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray]:
    """Same-place pairs (i, j) with j - i > max(nn, 1), or j > i in another recording
    (``codes``), sorted by (i, j); blocked over rows."""
    m = x.size
    gap = max(nn, 1)
    rows = max(1, _BLOCK_ELEMENTS // max(m, 1))
    cols = np.arange(m)
    pi, pj = [], []
    for i0 in range(0, m, rows):
        i1 = min(m, i0 + rows)
        d2 = (x[i0:i1, None] - x[None, :]) ** 2 + (y[i0:i1, None] - y[None, :]) ** 2
        ii = np.arange(i0, i1)[:, None]
        apart = cols[None, :] - ii > gap
        if codes is not None:
            apart |= (cols[None, :] > ii) & (codes[None, :] != codes[i0:i1, None])
        r, c = np.nonzero(_within(d2, dist_th) & apart)
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


def evaluate(topomap: TopoMap, poses=None, dist_th: float = 1.0,
             neighbor_node_num: Optional[int] = None, include_candidates: bool = False) -> Evaluation:
    """Count TP/FP/TN/FN of the map's loop arcs against ground truth (see module doc).

    A map without nodes is refused (InputError): it has nothing to evaluate, and its
    four zeros read like a result."""
    return _evaluate(topomap, poses, dist_th, neighbor_node_num, include_candidates)[0]


def _evaluate(topomap: TopoMap, poses, dist_th: float, neighbor_node_num: Optional[int],
              include_candidates: bool):
    """``evaluate``, and what it measured on the way: (Evaluation, x, y, node index by id,
    recording codes or None)."""
    if not dist_th >= 0 or dist_th == float("inf"):  # NaN compares false
        raise InputError(f"distance threshold must be a finite number >= 0, got {dist_th}")
    if topomap.graph.number_of_nodes() == 0:
        raise InputError("the map has no nodes: there is nothing to evaluate")
    if neighbor_node_num is None:
        neighbor_node_num = int(topomap.meta.get("neighbor_node_num", 0))
    nn = int(neighbor_node_num)
    codes = _session_codes(topomap)
    if codes is not None and isinstance(poses, Poses) and codes.max() > 0:
        raise InputError(f"the map has {int(codes.max()) + 1} recordings, each on its own clock: "
                         f"give one set of poses per recording")
    x, y = (np.asarray(a, dtype=np.float64) for a in node_positions(topomap, poses))
    m = x.size
    index = {n: int(d["index"]) for n, d in topomap.graph.nodes(data=True)}

    def cross(i, j):
        return codes is not None and codes[i] != codes[j]

    # Positive pairs: same place, not temporal neighbours.
    pi, pj = _positive_pairs(x, y, dist_th, nn, codes)
    pos_keys = pi * m + pj

    tp_pairs, fp_pairs, loop_truth = [], [], {}
    for u, v, d in topomap.loops():
        i, j = index[u], index[v]
        if j - i < 2 and not cross(i, j):
            continue  # not a pair we count (a path arc)
        same = _within((x[i] - x[j]) ** 2 + (y[i] - y[j]) ** 2, dist_th)
        positive = bool(same) and (j - i > nn or cross(i, j))
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
    if codes is not None and m >= 2:   # path arcs only within a recording
        total = m * (m - 1) // 2 - int(np.count_nonzero(codes[1:] == codes[:-1]))
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
    across = {}
    if codes is not None:
        event_cross = np.zeros(event_ids.size, bool)
        event_cross[event_of_pair[codes[pi] != codes[pj]]] = True
        across = dict(cross_tp=sum(cross(i, j) for i, j in tp_pairs), cross_fp=sum(cross(i, j) for i, j in fp_pairs),
                      cross_fn=sum(cross(i, j) for i, j in fn_pairs),
                      cross_events_found=int((event_found & event_cross).sum()),
                      cross_events_total=int(event_cross.sum()), sessions=int(codes.max()) + 1)

    ev = Evaluation(
        tp=tp, fp=fp, tn=tn, fn=fn,
        precision=_ratio(tp, tp + fp), recall=_ratio(tp, tp + fn),
        accuracy=_ratio(tp + tn, total), f1=_ratio(2 * tp, 2 * tp + fp + fn),
        tp_pairs=tp_pairs, fp_pairs=fp_pairs, fn_pairs=fn_pairs,
        events_found=found, events_total=events_total,
        loop_truth=loop_truth, dist_th=float(dist_th), neighbor_node_num=nn,
        event_closest=event_closest.tolist(), event_found=event_found.tolist(),
        event_span=event_span.tolist(), **{k: int(v) for k, v in across.items()},
    )
    return ev, x, y, index, codes


# The project's band (issue 41): a place is found by a loop within 1 m, a loop beyond 2 m is false.
FOUND_WITHIN_M = 1.0
FALSE_BEYOND_M = 2.0


class LoopBand(str, Enum):
    """How the project scores one loop by the distance between its two views (module doc)."""

    TRUE = "true"
    DONT_CARE = "don't care"
    FALSE = "false"


def _check_band(found_within: float, false_beyond: float) -> None:
    for name, value in (("found_within", found_within), ("false_beyond", false_beyond)):
        if not value >= 0 or value == float("inf"):  # NaN compares false
            raise InputError(f"{name} must be a finite number of metres >= 0, got {value}")
    if false_beyond < found_within:
        raise InputError(f"false_beyond ({false_beyond:g} m) must be at least found_within ({found_within:g} m)")


def loop_band(distance: float, found_within: float = FOUND_WITHIN_M,
              false_beyond: float = FALSE_BEYOND_M) -> LoopBand:
    """The band of a loop whose two views are ``distance`` metres apart (temporal neighbours
    aside, which ``evaluate_band`` calls false): TRUE up to ``found_within`` (inclusive, the
    nanometre of slack of ``dist_th``), FALSE beyond ``false_beyond``, DONT_CARE between."""
    _check_band(found_within, false_beyond)
    d2 = float(distance) ** 2
    if _within(d2, found_within):
        return LoopBand.TRUE
    return LoopBand.DONT_CARE if _within(d2, false_beyond) else LoopBand.FALSE


@dataclass
class BandEvaluation:
    """The project's figures (module doc): places found / revisited and loops by band."""

    found_within: float
    false_beyond: float
    places_found: int
    places_revisited: int
    true_loops: int
    dont_care_loops: int
    false_loops: int
    neighbour_loops: int = 0      # of the false loops: between temporal neighbours, within false_beyond
    neighbor_node_num: int = 0
    include_candidates: bool = False
    # Band of every counted loop, keyed by node ids (u, v), u lower: "true", "don't care", "false".
    loop_band: dict[tuple[str, str], str] = field(default_factory=dict)

    @property
    def place_recall(self) -> float:
        """places found / places revisited (0.0 when no place is revisited)."""
        return _ratio(self.places_found, self.places_revisited)

    def as_dict(self) -> dict:
        """JSON-ready (loop keys as "u-v")."""
        d = asdict(self)
        d["loop_band"] = {f"{u}-{v}": b for (u, v), b in self.loop_band.items()}
        d["place_recall"] = self.place_recall
        return d

    def text(self) -> str:
        """One line: the band, places found, loops by band."""
        neighbours = f", {self.neighbour_loops} of them between temporal neighbours" if self.neighbour_loops else ""
        return (f"places found {self.places_found}/{self.places_revisited} (a loop within "
                f"{self.found_within:g} m); loops: true {self.true_loops}, "
                f"{self.found_within:g}-{self.false_beyond:g} m (don't care) {self.dont_care_loops}, "
                f"false {self.false_loops} (beyond {self.false_beyond:g} m{neighbours})")


def evaluate_band(topomap: TopoMap, poses=None, found_within: float = FOUND_WITHIN_M,
                  false_beyond: float = FALSE_BEYOND_M, neighbor_node_num: Optional[int] = None,
                  include_candidates: bool = False) -> BandEvaluation:
    """Score the map's loops with the project's don't-care band (module doc): places found /
    revisited at ``found_within``, and every counted loop true, don't care or false.

    ``poses``, ``neighbor_node_num`` and ``include_candidates`` as in ``evaluate``."""
    _check_band(found_within, false_beyond)
    ev, x, y, index, codes = _evaluate(topomap, poses, found_within, neighbor_node_num, include_candidates)
    nn = ev.neighbor_node_num
    counts = {band: 0 for band in LoopBand}
    neighbours = 0
    bands: dict[tuple[str, str], str] = {}
    for u, v, d in topomap.loops():
        status = d.get("status")
        if status == "rejected" or (status == "candidate" and not include_candidates):
            continue
        i, j = index[u], index[v]
        across = codes is not None and codes[i] != codes[j]
        if j - i < 2 and not across:
            continue  # a path arc, not a pair we count
        band = loop_band(float(np.hypot(x[i] - x[j], y[i] - y[j])), found_within, false_beyond)
        if not across and j - i <= nn and band is not LoopBand.FALSE:
            band = LoopBand.FALSE   # temporal neighbours: the paper's rule (module doc)
            neighbours += 1
        counts[band] += 1
        bands[(u, v)] = band.value
    return BandEvaluation(
        found_within=float(found_within), false_beyond=float(false_beyond),
        places_found=ev.events_found, places_revisited=ev.events_total,
        true_loops=counts[LoopBand.TRUE], dont_care_loops=counts[LoopBand.DONT_CARE],
        false_loops=counts[LoopBand.FALSE], neighbour_loops=neighbours, neighbor_node_num=nn,
        include_candidates=bool(include_candidates), loop_band=bands)
