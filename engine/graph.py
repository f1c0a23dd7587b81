"""The map model: a networkx graph of nodes, path arcs and loop arcs, and GraphML I/O.

GraphML contract (DESIGN.md), one attribute = one type everywhere:

* graph: ``generator`` ("panotopo <version>"), ``source``, ``method``,
  ``descriptor`` (str) and every parameter used (``node_sim_th``, ``loop_sim_th``
  float; ``window_size``, ``count_th``, ``neighbor_node_num`` int; ``interval``
  float when known; anything from ``extra_meta``).
* node ``n<k>``: ``index`` int, ``frame`` int, ``stamp`` float, ``shift`` int,
  ``label`` str, ``x``/``y`` float only when positions are known.
* edge: ``kind`` "sequential" | "loop"; ``similarity`` float; ``status``
  "auto" | "candidate" | "confirmed" | "rejected" | "manual"; ``yaw`` float degrees only where
  estimated; ``window_count`` int on loop arcs (an addition to the contract).
* added with the two tiers of loop detection: ``status`` "candidate" (found, not accepted
  automatically, waiting for a person; left out of the exported corrected map unless asked),
  ``tier`` str on detected loop arcs (what detection said, "auto" or "candidate": a reset
  decision goes back to it), and the evidence behind a detected loop where known:
  ``score`` float (calibrated descriptor score, standard deviations above the recording's own
  background), ``support`` float (the same along the matched stretch), ``direction`` int
  (+1 same way, -1 reverse), ``matches`` and ``inliers`` int (local features matched and
  consistent with one two-view model on the sphere), ``inlier_ratio`` float, ``path_inliers``
  int (the same measured between each end and its own path neighbour just outside the
  temporal window: what "a few metres along the path" shares), ``step_inliers`` int (the
  same with the next node along the path, the smaller of the two ends), ``confidence`` float (the
  ranking of the review queue), ``closure`` float (node steps by which the dead-reckoned
  path between the two ends misses meeting again), ``plane_share`` float (share of the
  inliers whose triangulated points lie on one plane), ``distance_steps`` float (how far
  apart the two views are, in node steps, from the geometry scaled by each end's own steps),
  ``bearing`` float (where it has a ``distance_steps``: the direction of the later node seen
  from the earlier one, degrees anticlockwise from the earlier node's heading; the pose graph's
  loop factor puts it there).

Curation ("decisions") is keyed by source frame numbers, not node ids, so a user's
confirmed/rejected/manual loops and labels survive a re-run with other parameters.

Several recordings (a site, ``engine.site``): node ``session`` str (the recording's name),
sequential arcs only between consecutive nodes of one session, graph ``sessions`` (JSON list
of {"session", "source", "descriptors", "nodes"}: where each recording and its descriptors
are) and ``decisions`` (JSON of ``decisions()``, so that rejected loops, left out of the
exported arcs, survive adding a recording). Decisions of a site are keyed by (session, frame):
a loop item carries ``sessions`` [sa, sb] beside ``frames``, a label ``session``; an item
without them belongs to the first session (a one-recording map grown into a site).
"""

from __future__ import annotations

import copy as _copy
import io
import json
from pathlib import Path
from typing import Iterable, Optional, Sequence

import networkx as nx
import numpy as np

from . import __version__
from .descriptors.base import Descriptors
from .errors import InputError
from .loops import LoopCandidate
from .params import PARAMETERS, MapParams

STATUSES = ("auto", "candidate", "confirmed", "rejected", "manual")
SETTABLE_STATUSES = ("auto", "candidate", "confirmed", "rejected")
TIERS = ("auto", "candidate")   # what detection says of a loop before a person decides

# Attributes whose type is fixed by the contract; values are cast on the way in and out.
_NODE_TYPES = {"index": int, "frame": int, "stamp": float, "shift": int, "label": str,
               "x": float, "y": float, "heading": float, "session": str}
_EDGE_TYPES = {"kind": str, "similarity": float, "status": str, "yaw": float,
               "window_count": int, "tier": str, "score": float, "support": float,
               "direction": int, "matches": int, "inliers": int, "inlier_ratio": float,
               "path_inliers": int, "confidence": float, "closure": float, "step_inliers": int,
               "plane_share": float, "distance_steps": float, "bearing": float, "rule": str, "reason": str}
EVIDENCE_KEYS = ("score", "support", "direction", "matches", "inliers", "inlier_ratio", "path_inliers",
                 "step_inliers", "confidence", "closure", "plane_share", "distance_steps", "bearing", "rule",
                 "reason")
# Graph attributes: every map parameter with its declared type (bools stored as 0/1).
_GRAPH_TYPES = {"generator": str, "source": str, "descriptor": str, "interval": float, "positions": str,
                "sessions": str, "decisions": str,
                **{p.name: (int if p.type is bool else p.type) for p in PARAMETERS}}


def _plain(value, kind=None):
    """A GraphML-safe Python value: int, float or str (no numpy, no bool, no None)."""
    if kind is not None:
        return kind(value)
    if isinstance(value, (bool, np.bool_)):
        return int(value)  # bools are read back inconsistently; store 0/1
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, str):
        return value
    return json.dumps(value, default=str)  # lists, dicts: one string


# networkx's own GraphML bookkeeping (read_graphml puts it into the graph's attributes; its
# writer takes it as dicts): never a map attribute.
_NETWORKX_KEYS = ("node_default", "edge_default")


# GraphML as networkx writes it (``nx.write_graphml(g, f, infer_numeric_types=False)``, its
# ElementTree writer, prettyprinted): its type names for the values ``_plain`` gives, and
# ElementTree's escapes for text and for attribute values.
_XML_TYPES = {int: "long", float: "double", str: "string"}
_XML_TEXT = str.maketrans({"&": "&amp;", "<": "&lt;", ">": "&gt;"})
_XML_ATTR = str.maketrans({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "\r": "&#13;",
                           "\n": "&#10;", "\t": "&#09;"})


def _write_graphml(g: nx.Graph, f) -> None:
    """Write ``g`` (values int, float or str) to the binary file ``f`` byte for byte as networkx
    does, streamed. Without lxml networkx builds an ElementTree of the whole map first: 100k
    nodes and 35k loops took 50 of the map's 270 s under cProfile, and the tree's memory
    (benchmarks/bench_scale.py)."""
    def plain(d: dict) -> dict:   # a numpy number or a bool set by hand: as _plain stores it
        return d if all(type(v) in _XML_TYPES for v in d.values()) else {k: _plain(v) for k, v in d.items()}

    graph = plain({k: v for k, v in g.graph.items() if k not in _NETWORKX_KEYS})
    gid = graph.pop("id", None)   # networkx writes a graph attribute "id" as the graph's own id
    nodes = [(n, plain(d)) for n, d in g.nodes(data=True)]
    edges = [(u, v, plain(d)) for u, v, d in g.edges(data=True)]
    scopes = (("graph", [graph]), ("node", [d for _, d in nodes]), ("edge", [d for _, _, d in edges]))
    keys = {}   # (name, type, scope) -> key id, numbered in the order networkx meets them
    for scope, dicts in scopes:
        for d in dicts:
            for k, v in d.items():
                key = (str(k), _XML_TYPES[type(v)], scope)
                if key not in keys:
                    keys[key] = f"d{len(keys)}"
    out = io.TextIOWrapper(f, encoding="utf-8", errors="xmlcharrefreplace", newline="\n")
    w = out.write

    def data(pad: str, values: dict, scope: str) -> str:
        lines = []
        for k, v in values.items():
            text = v.translate(_XML_TEXT) if type(v) is str else str(v)
            key = keys[str(k), _XML_TYPES[type(v)], scope]
            lines.append(f'{pad}<data key="{key}">{text}</data>\n' if text else f'{pad}<data key="{key}" />\n')
        return "".join(lines)

    def element(pad: str, head: str, tag: str, values: dict, scope: str) -> str:
        return f"{pad}<{head}>\n{data(pad + '  ', values, scope)}{pad}</{tag}>\n" if values else f"{pad}<{head} />\n"

    w("<?xml version='1.0' encoding='utf-8'?>\n<graphml xmlns=\"http://graphml.graphdrawing.org/xmlns\" "
      "xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" xsi:schemaLocation=\"http://graphml.graphdrawing."
      "org/xmlns http://graphml.graphdrawing.org/xmlns/1.0/graphml.xsd\">\n")
    for (name, kind, scope), key in reversed(keys.items()):
        w(f'  <key id="{key}" for="{scope}" attr.name="{name.translate(_XML_ATTR)}" attr.type="{kind}" />\n')
    head = 'graph edgedefault="undirected"' + ("" if gid is None else f' id="{str(gid).translate(_XML_ATTR)}"')
    if g.number_of_nodes() == 0:
        w(element("  ", head, "graph", graph, "graph"))
    else:   # the graph's own data come after its nodes and edges
        w(f"  <{head}>\n")
        for n, d in nodes:
            w(element("    ", f'node id="{str(n).translate(_XML_ATTR)}"', "node", d, "node"))
        for u, v, d in edges:
            w(element("    ", f'edge source="{str(u).translate(_XML_ATTR)}" target="{str(v).translate(_XML_ATTR)}"',
                      "edge", d, "edge"))
        w(data("    ", graph, "graph"))
        w("  </graph>\n")
    w("</graphml>\n")
    out.flush()
    out.detach()   # leave ``f`` open for the caller


def _clean_meta(meta: dict) -> dict:
    return {str(k): _plain(v, _GRAPH_TYPES.get(k)) for k, v in meta.items()
            if v is not None and k not in _NETWORKX_KEYS}


class TopoMap:
    """Nodes, path arcs and loop arcs, with the user's curation."""

    def __init__(self, graph: nx.Graph, meta: dict, node_rows: Optional[np.ndarray] = None,
                 node_vectors: Optional[np.ndarray] = None):
        self.graph = graph
        self.meta = meta
        self.node_rows = node_rows          # rows of the Descriptors that are nodes
        self.node_vectors = node_vectors    # (m, d) descriptors of the nodes, when known
        self.unapplied: dict[str, list] = {"loops": [], "manual": [], "labels": []}
        # The pose graph's step measurements (engine.loops.pose_graph.step_factors:
        # dx, dy, dtheta, sigma_xy, sigma_theta per consecutive node pair), in memory only,
        # for the g2o export; None when the map was read from a file or had no geometry.
        self.step_measurements = None

    # ----- construction -------------------------------------------------------------
    @classmethod
    def build(cls, descs: Descriptors, node_rows: np.ndarray, loops: list[LoopCandidate],
              params: MapParams, source: str = "", extra_meta: Optional[dict] = None,
              sessions: Optional[Sequence[str]] = None) -> "TopoMap":
        """``sessions``: each node's recording name (a site): stored as node ``session``, and
        sequential arcs join only consecutive nodes of one session."""
        node_rows = np.asarray(node_rows, dtype=np.int64)
        m = node_rows.size
        vectors = np.asarray(descs.vectors, dtype=np.float32)[node_rows]
        if sessions is not None and len(sessions) != m:
            raise InputError(f"sessions must name one recording per node ({m})")
        g = nx.Graph()
        for k, row in enumerate(node_rows):
            g.add_node(f"n{k}", index=k, frame=int(descs.frames[row]),
                       stamp=float(descs.stamps[row]), shift=int(descs.shifts[row]), label="")
            if sessions is not None:
                g.nodes[f"n{k}"]["session"] = str(sessions[k])
        if m > 1:
            path_sims = np.einsum("ij,ij->i", vectors[:-1], vectors[1:])
            for k in range(m - 1):
                if sessions is not None and sessions[k] != sessions[k + 1]:
                    continue   # a new recording: no path between them
                g.add_edge(f"n{k}", f"n{k + 1}", kind="sequential",
                           similarity=float(path_sims[k]), status="auto")
        for lc in loops:
            if not (0 <= lc.a < m and 0 <= lc.b < m) or lc.a == lc.b:
                continue  # out of range
            if abs(lc.b - lc.a) < 2 and (sessions is None or sessions[lc.a] == sessions[lc.b]):
                continue  # already a path arc
            tier = lc.status if lc.status in TIERS else "auto"
            attrs = dict(kind="loop", similarity=float(lc.similarity), status=tier, tier=tier,
                         window_count=int(lc.window_count))
            if lc.yaw is not None:
                attrs["yaw"] = float(lc.yaw)
            for k, v in (lc.evidence or {}).items():
                if k in EVIDENCE_KEYS and v is not None and (isinstance(v, str) or np.isfinite(v)):
                    attrs[k] = _EDGE_TYPES[k](v)
            g.add_edge(f"n{lc.a}", f"n{lc.b}", **attrs)

        dmeta = descs.meta or {}
        meta = {
            "generator": f"panotopo {__version__}",
            "source": source,
            "descriptor": str(dmeta.get("descriptor", dmeta.get("name", ""))),
        }
        if dmeta.get("interval") is not None:
            meta["interval"] = dmeta["interval"]
        meta.update(params.as_dict())
        meta.update(extra_meta or {})
        meta = _clean_meta(meta)
        g.graph.update(meta)
        return cls(g, meta, node_rows, vectors)

    # ----- queries ------------------------------------------------------------------
    @staticmethod
    def node_id(k: int) -> str:
        return f"n{int(k)}"

    @property
    def node_count(self) -> int:
        return self.graph.number_of_nodes()

    def _ordered(self) -> list[str]:
        return sorted(self.graph.nodes, key=lambda n: self.graph.nodes[n]["index"])

    def _node_array(self, key: str, dtype) -> np.ndarray:
        return np.asarray([self.graph.nodes[n][key] for n in self._ordered()], dtype=dtype)

    def frames(self) -> np.ndarray:
        return self._node_array("frame", np.int64)

    def stamps(self) -> np.ndarray:
        return self._node_array("stamp", np.float64)

    def node_sessions(self) -> Optional[np.ndarray]:
        """Each node's ``session`` (str array, node order), or None for a one-recording map."""
        nodes = self._ordered()
        if not nodes or "session" not in self.graph.nodes[nodes[0]]:
            return None
        return np.asarray([str(self.graph.nodes[n].get("session", "")) for n in nodes], dtype=object)

    def session_records(self) -> list[dict]:
        """The graph's ``sessions`` list (name, source, descriptors, nodes), [] without one."""
        raw = self.graph.graph.get("sessions")
        if not raw:
            return []
        try:
            records = json.loads(raw) if isinstance(raw, str) else list(raw)
        except ValueError:
            raise InputError("the map's 'sessions' attribute is not a JSON list") from None
        if not isinstance(records, list) or not all(isinstance(r, dict) and "session" in r for r in records):
            raise InputError("the map's 'sessions' attribute is not a list of recordings")
        return records

    def positions(self, estimated: bool = False) -> Optional[tuple[np.ndarray, np.ndarray]]:
        """Node (x, y) when every node has one, else None; positions the pose graph estimated
        (graph ``positions`` "estimated") only when ``estimated`` (they are no ground truth)."""
        if self.graph.graph.get("positions") == "estimated" and not estimated:
            return None
        nodes = self._ordered()
        if not nodes or not all("x" in self.graph.nodes[n] and "y" in self.graph.nodes[n] for n in nodes):
            return None
        return self._node_array("x", np.float64), self._node_array("y", np.float64)

    def loops(self, statuses: Optional[Iterable[str]] = None) -> list[tuple[str, str, dict]]:
        """Loop arcs (u, v, attributes) with u the lower index, sorted by index."""
        wanted = None if statuses is None else set(statuses)
        index = dict(self.graph.nodes(data="index"))   # one table: the node view is slow per lookup
        out = []
        for u, v, d in self.graph.edges(data=True):
            if d.get("kind") != "loop" or (wanted is not None and d.get("status") not in wanted):
                continue
            if index[u] > index[v]:
                u, v = v, u
            out.append((u, v, d))
        out.sort(key=lambda e: (index[e[0]], index[e[1]]))
        return out

    def _loop_attrs(self, u: str, v: str) -> dict:
        if not self.graph.has_edge(u, v) or self.graph.edges[u, v].get("kind") != "loop":
            raise InputError(f"there is no loop arc between {u} and {v}")
        return self.graph.edges[u, v]

    def _check_node(self, n: str) -> None:
        if n not in self.graph:
            raise InputError(f"there is no node {n}")

    # ----- curation -----------------------------------------------------------------
    def set_status(self, u: str, v: str, status: str) -> None:
        if status not in SETTABLE_STATUSES:
            raise InputError(f"status must be one of {', '.join(SETTABLE_STATUSES)}, got {status!r}")
        attrs = self._loop_attrs(u, v)
        if attrs["status"] == "manual":
            raise InputError(f"the loop {u}-{v} was added by hand; remove it instead")
        attrs["status"] = status

    def reset_status(self, u: str, v: str) -> None:
        """Undo a person's decision: the loop goes back to the tier detection gave it."""
        self.set_status(u, v, self._loop_attrs(u, v).get("tier", "auto"))

    def add_manual_loop(self, u: str, v: str, yaw: Optional[float] = None,
                        similarity: Optional[float] = None) -> None:
        self._check_node(u)
        self._check_node(v)
        if u == v:
            raise InputError("a loop needs two different nodes")
        if self.graph.has_edge(u, v):
            raise InputError(f"nodes {u} and {v} are already joined")
        if similarity is None:
            similarity = self._similarity(u, v)
        attrs = dict(kind="loop", similarity=float(similarity), status="manual", window_count=0)
        if yaw is not None:
            attrs["yaw"] = float(yaw)
        self.graph.add_edge(u, v, **attrs)

    def _similarity(self, u: str, v: str) -> float:
        if self.node_vectors is None:
            return float("nan")
        i, j = self.graph.nodes[u]["index"], self.graph.nodes[v]["index"]
        return float(self.node_vectors[i] @ self.node_vectors[j])

    def remove_loop(self, u: str, v: str) -> None:
        attrs = self._loop_attrs(u, v)
        if attrs["status"] != "manual":
            raise InputError(f"the loop {u}-{v} was detected, not added by hand; reject it instead")
        self.graph.remove_edge(u, v)

    def set_label(self, node: str, label: str) -> None:
        self._check_node(node)
        self.graph.nodes[node]["label"] = str(label)

    def set_positions(self, x: np.ndarray, y: np.ndarray, heading: Optional[np.ndarray] = None,
                      kind: str = "ground truth") -> None:
        """Node positions (and headings, degrees) with where they came from (graph attribute
        ``positions``: "ground truth", "gps" or "estimated", the pose graph's)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if x.shape != (self.node_count,) or y.shape != (self.node_count,):
            raise InputError(f"positions must have one value per node ({self.node_count})")
        if not (np.isfinite(x).all() and np.isfinite(y).all()):
            raise InputError("positions must be finite numbers")
        for n, xi, yi in zip(self._ordered(), x, y):
            self.graph.nodes[n]["x"] = float(xi)
            self.graph.nodes[n]["y"] = float(yi)
            self.graph.nodes[n].pop("heading", None)
        if heading is not None:
            for n, hi in zip(self._ordered(), np.asarray(heading, np.float64)):
                self.graph.nodes[n]["heading"] = float(hi)
        self.graph.graph["positions"] = str(kind)

    # ----- decisions (curation keyed by source frames) --------------------------------
    def decisions(self) -> dict:
        """The user's curation as JSON-ready data keyed by source frame numbers.

        Decisions that could not be applied to this map (``unapplied``) are kept so
        they are never lost across re-runs.
        """
        frame = {n: int(d["frame"]) for n, d in self.graph.nodes(data=True)}
        site = self.node_sessions() is not None
        session = {n: str(d.get("session", "")) for n, d in self.graph.nodes(data=True)}

        def keyed(item: dict, *nodes: str) -> dict:
            if site:   # a site: decisions keyed by (session, frame)
                if len(nodes) == 1:
                    item["session"] = session[nodes[0]]
                else:
                    item["sessions"] = [session[n] for n in nodes]
            return item

        loops, manual = [], []
        for u, v, d in self.loops():
            if d["status"] == "manual":
                manual.append(keyed({"frames": [frame[u], frame[v]],
                                     "yaw": float(d["yaw"]) if "yaw" in d else None}, u, v))
            elif d["status"] != d.get("tier", "auto"):
                loops.append(keyed({"frames": [frame[u], frame[v]], "status": d["status"]}, u, v))
        labels = [keyed({"frame": frame[n], "label": self.graph.nodes[n]["label"]}, n)
                  for n in self._ordered() if self.graph.nodes[n].get("label")]
        return {"loops": loops + _copy.deepcopy(self.unapplied["loops"]),
                "manual": manual + _copy.deepcopy(self.unapplied["manual"]),
                "labels": labels + _copy.deepcopy(self.unapplied["labels"])}

    def apply_decisions(self, dec: dict) -> None:
        """Re-apply ``decisions()`` (possibly from another run) onto this map.

        * status: to the loop arc whose node frames are exactly (fa, fb), else to the
          loop arc between the nodes nearest in frame to fa and fb, if there is one;
        * manual loop: between the nodes nearest in frame; an existing loop arc there
          becomes manual (the user asserted it);
        * label: on the node nearest in frame.
        Whatever cannot be applied goes to ``unapplied`` (and back out in decisions()).
        """
        self.unapplied = {"loops": [], "manual": [], "labels": []}
        if self.node_count == 0:
            self.unapplied = {k: list(_copy.deepcopy(dec.get(k, []))) for k in self.unapplied}
            return
        order = np.asarray(self._ordered(), dtype=object)
        frames = self.frames()
        sessions = self.node_sessions()
        if sessions is None:
            sessions = np.full(order.size, "", dtype=object)
        first_session = str(sessions[0])
        recordings = {}   # session -> (its nodes in order, their frames, frame -> node)
        for name in dict.fromkeys(sessions.tolist()):
            mine = sessions == name
            recordings[name] = (order[mine], frames[mine],
                                {int(f): n for f, n in zip(frames[mine], order[mine])})

        def session_of(item: dict, k: int) -> str:
            """The session an item's k-th frame belongs to (the first session when unsaid)."""
            if self.node_sessions() is None:
                return ""
            if "sessions" in item:
                return str(item["sessions"][k])
            return str(item.get("session", first_session))

        def inside(s: str, f: int) -> bool:
            """A decision on frames outside the recording's mapped span (or on a recording
            not in this map) is kept as unapplied, not snapped to the end node (a crafted
            n0-n99 loop, issue 16)."""
            if s not in recordings:
                return False
            fs = recordings[s][1]
            return int(fs.min()) <= f <= int(fs.max())

        def nearest(s: str, f: int) -> str:  # the first of two equally near nodes
            nodes, fs, _ = recordings[s]
            return str(nodes[int(np.argmin(np.abs(fs - f)))])

        def is_loop(u: str, v: str) -> bool:
            return self.graph.has_edge(u, v) and self.graph.edges[u, v].get("kind") == "loop"

        for item in dec.get("loops", []):
            fa, fb = (int(f) for f in item["frames"])
            sa, sb = session_of(item, 0), session_of(item, 1)
            status = item.get("status")
            if not (inside(sa, fa) and inside(sb, fb)):
                self.unapplied["loops"].append(_copy.deepcopy(item))
                continue
            u, v = recordings[sa][2].get(fa), recordings[sb][2].get(fb)
            if u is None or v is None or not is_loop(u, v):
                u, v = nearest(sa, fa), nearest(sb, fb)
            if (status in SETTABLE_STATUSES and u != v and is_loop(u, v)
                    and self.graph.edges[u, v]["status"] != "manual"):
                self.graph.edges[u, v]["status"] = status
            else:
                self.unapplied["loops"].append(_copy.deepcopy(item))

        for item in dec.get("manual", []):
            fa, fb = (int(f) for f in item["frames"])
            sa, sb = session_of(item, 0), session_of(item, 1)
            if not (inside(sa, fa) and inside(sb, fb)):
                self.unapplied["manual"].append(_copy.deepcopy(item))
                continue
            u, v = nearest(sa, fa), nearest(sb, fb)
            yaw = item.get("yaw")
            if u != v and is_loop(u, v):
                attrs = self.graph.edges[u, v]
                attrs["status"] = "manual"
                if yaw is not None:
                    attrs["yaw"] = float(yaw)
            elif u != v and not self.graph.has_edge(u, v):
                self.add_manual_loop(u, v, yaw=yaw)
            else:  # same node, or a path arc: nothing to add
                self.unapplied["manual"].append(_copy.deepcopy(item))

        for item in dec.get("labels", []):
            s = session_of(item, 0)
            if not inside(s, int(item["frame"])):
                self.unapplied["labels"].append(_copy.deepcopy(item))
                continue
            self.graph.nodes[nearest(s, int(item["frame"]))]["label"] = str(item["label"])

    # ----- copies and export --------------------------------------------------------------
    def copy(self) -> "TopoMap":
        out = TopoMap(_copy.deepcopy(self.graph), dict(self.meta),
                      None if self.node_rows is None else self.node_rows.copy(),
                      None if self.node_vectors is None else self.node_vectors.copy())
        out.unapplied = _copy.deepcopy(self.unapplied)
        out.step_measurements = self.step_measurements
        return out

    def corrected(self, keep_rejected: bool = False, keep_candidates: bool = False) -> nx.Graph:
        """The graph for export, attributes cast to their contract types.

        Rejected loops and undecided candidates are left out unless asked for: the
        corrected map holds what was accepted (automatically, confirmed or added by hand)."""
        g = nx.Graph()
        g.graph.update(_clean_meta(self.graph.graph))
        if self.node_sessions() is not None:   # a site: its decisions, rejected ones included
            dec = self.decisions()
            if any(dec.values()):
                g.graph["decisions"] = json.dumps(dec)
            else:
                g.graph.pop("decisions", None)
        for n in self._ordered():
            d = self.graph.nodes[n]
            g.add_node(n, **{k: _plain(v, _NODE_TYPES.get(k)) for k, v in d.items() if v is not None})
        for u, v, d in self.graph.edges(data=True):
            if d.get("status") == "rejected" and not keep_rejected:
                continue
            if d.get("status") == "candidate" and not keep_candidates:
                continue
            g.add_edge(u, v, **{k: _plain(val, _EDGE_TYPES.get(k)) for k, val in d.items()
                                if val is not None})
        return g

    def write_graphml(self, path: str | Path, keep_rejected: bool = False,
                      keep_candidates: bool = False) -> None:
        """Write the corrected map; atomic (a temporary file replaced into place)."""
        from .outputs import write_atomically

        g = self.corrected(keep_rejected, keep_candidates)
        write_atomically(path, lambda f: _write_graphml(g, f))

    @classmethod
    def read_graphml(cls, path: str | Path) -> "TopoMap":
        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: no such file")
        from .graphml_read import read_graphml

        try:
            g = read_graphml(path)   # streamed: networkx's reader holds the whole XML tree
        except Exception as exc:  # XML or GraphML errors all mean the same to a user
            raise InputError(f"{path}: cannot read GraphML ({exc.__class__.__name__})") from None
        if not str(g.graph.get("generator", "")).startswith("panotopo"):
            raise InputError(f"{path}: not a panotopo map (no panotopo generator attribute)")
        if g.is_directed() or g.is_multigraph():
            g = nx.Graph(g)
        for n, d in g.nodes(data=True):
            if "index" not in d or "frame" not in d or "stamp" not in d:
                raise InputError(f"{path}: node {n} lacks index/frame/stamp")
            d.setdefault("label", "")
            d.setdefault("shift", 0)
        _check_nodes(g, path)
        for _, _, d in g.edges(data=True):
            d.setdefault("status", "auto")
            d.setdefault("kind", "sequential")
        for key in _NETWORKX_KEYS:
            g.graph.pop(key, None)
        meta = dict(g.graph)
        return cls(g, meta, None, None)


def _check_nodes(g: nx.Graph, path: Path) -> None:
    """The contract's node numbering, checked (issue 16): indices are the integers
    0..m-1, each once; frames are integers >= 0; stamps are finite. Duplicate or negative
    indices made evaluation count pairs that do not exist."""
    seen: dict[int, str] = {}
    for n, d in g.nodes(data=True):
        try:
            k, frame, stamp = int(d["index"]), int(d["frame"]), float(d["stamp"])
        except (TypeError, ValueError):
            raise InputError(f"{path}: node {n} has a non-numeric index, frame or stamp") from None
        if k < 0 or k >= g.number_of_nodes():
            raise InputError(f"{path}: node {n} has index {k}, outside 0..{g.number_of_nodes() - 1}")
        if k in seen:
            raise InputError(f"{path}: nodes {seen[k]} and {n} have the same index {k}")
        if frame < 0 or not np.isfinite(stamp):
            raise InputError(f"{path}: node {n} has a negative frame or a non-finite stamp")
        seen[k] = n
        d["index"], d["frame"], d["stamp"] = k, frame, stamp
