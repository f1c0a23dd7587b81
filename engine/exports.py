"""Map exports a navigation stack can read, one function per format.

Every format writes the same corrected graph as the GraphML (``TopoMap.corrected``: the
contract's attributes with their types; rejected loops and undecided candidates left out
unless asked), atomically (``engine.outputs.write_atomically``).

* GraphML (``write_graphml``): the contract of DESIGN.md.
* networkx node-link JSON (``write_node_link_json``): one JSON object
  ``{"directed": false, "multigraph": false, "graph": {...}, "nodes": [{"id": "n0", ...}],
  "edges": [{"source": "n0", "target": "n1", ...}]}`` as ``networkx.node_link_data`` writes it
  with its current default key ``"edges"`` (networkx >= 3.4 reads it with
  ``node_link_graph(data, edges="edges")``, 3.6 by default; older readers that expect
  ``"links"`` can rename the key). Graph, node and edge attributes are exactly the GraphML's,
  same names and JSON types (int, float, str); a float that is not finite (a hand-made loop's
  unknown similarity) is written as ``null``, so the file is strict JSON.

* g2o (``write_g2o``, extension ``.g2o``): the pose graph as g2o's 2-D text format, read by
  g2o, GTSAM (``gtsam.readG2o(path, is3D=False)``), SLAM++ and others. One line per vertex
  ``VERTEX_SE2 k x y theta``: node ``n<k>``'s estimated pose (x, y in node steps as the pose
  graph solves them, theta in radians, counter-clockwise), then one line per edge
  ``EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33``: the relative pose of j in i's frame
  and the upper triangle of its information matrix (inverse covariance), row by row. Edges:
  every sequential arc (i, i + 1) with the step the pose graph used
  (``engine.loops.pose_graph.step_factors``: the two-view step, or the direction
  carried on where a step had none), then every loop arc the corrected map holds (auto,
  confirmed, manual; candidates and rejected ones with ``keep_candidates`` /
  ``keep_rejected``) as the pose graph's loop factor: the measured offset (``distance_steps``
  along ``bearing``; none where the views did not measure it; sigma ``loop_sigma_steps``, both
  times the step's length in a metric map, as the pose graph scales them) and
  the loop's ``yaw`` (sigma ``loop_turn_sigma_deg``; a loop
  without yaw has an information of 1e-6 on the turn). The pairs the pose graph also used
  because their views measured their offset, but which are not loops (``verified._measured_apart``),
  are not in the map and not in the file. A map whose steps are not in memory
  (read from a file) gives each step the relative pose of the estimated poses with the
  ``step_sigma_steps`` / ``step_turn_sigma_deg`` sigmas. Needs estimated poses (graph
  ``positions`` "estimated", method verified with local features): otherwise one line.

``write_map`` picks the format by the output's extension (``WRITERS``: ``.json`` -> node-link
JSON, ``.g2o`` -> g2o), anything else -> GraphML (as before). A new format is one function
here and one entry in ``WRITERS``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable, Iterable, Optional

import networkx as nx

# Key of the edge list in the node-link JSON (networkx's own default since 3.6).
NODE_LINK_EDGES = "edges"


def _finite_or_none(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def node_link_data(topomap, keep_rejected: bool = False, keep_candidates: bool = False) -> dict:
    """The corrected map as a node-link dict (see the module docstring): plain JSON data."""
    g = topomap.corrected(keep_rejected=keep_rejected, keep_candidates=keep_candidates)
    data = nx.node_link_data(g, edges=NODE_LINK_EDGES)

    def clean(d: dict) -> dict:
        return {str(k): _finite_or_none(v) for k, v in d.items()}

    data["graph"] = clean(data.get("graph", {}))
    data["nodes"] = [clean(n) for n in data["nodes"]]
    data[NODE_LINK_EDGES] = [clean(e) for e in data[NODE_LINK_EDGES]]
    return data


def write_node_link_json(topomap, path: str | Path, keep_rejected: bool = False,
                         keep_candidates: bool = False,
                         inputs: Iterable[Optional[str | Path]] = ()) -> Path:
    """Write the corrected map as networkx node-link JSON (UTF-8, strict JSON); returns the
    file written. ``inputs``: files the command read, which the output may not replace."""
    from .outputs import write_text

    data = node_link_data(topomap, keep_rejected=keep_rejected, keep_candidates=keep_candidates)
    text = json.dumps(data, indent=1, allow_nan=False, ensure_ascii=False) + "\n"
    return write_text(path, text, inputs)


def write_graphml(topomap, path: str | Path, keep_rejected: bool = False, keep_candidates: bool = False,
                  inputs: Iterable[Optional[str | Path]] = ()) -> Path:
    """Write the corrected map as GraphML (``TopoMap.write_graphml``)."""
    topomap.write_graphml(path, keep_rejected=keep_rejected, keep_candidates=keep_candidates)
    return Path(path)


# Information of a quantity the pose graph leaves free (sigma 1e3).
_FREE_INFORMATION = 1e-6


def _information(sigma_x: float, sigma_y: float, sigma_theta: float) -> list[float]:
    """Upper triangle (I11 I12 I13 I22 I23 I33) of a diagonal information matrix."""
    def inv(sigma: float) -> float:
        return 1.0 / sigma ** 2 if sigma > 0 and math.isfinite(sigma) else _FREE_INFORMATION
    return [inv(sigma_x), 0.0, 0.0, inv(sigma_y), 0.0, inv(sigma_theta)]


def _wrap(theta: float) -> float:
    return (theta + math.pi) % (2 * math.pi) - math.pi


def _step_unit(g, pose, steps) -> float:
    """Length of one node step in the poses' units: 1, or with metric factors (graph
    ``metric``) the median step in metres, as the pose graph scaled it."""
    import numpy as np

    from .metric_factors import median_step

    if not g.graph.get("metric"):
        return 1.0
    if steps is not None:
        return median_step(steps[0], steps[1])
    moves = np.diff(pose[:, :2], axis=0)
    return median_step(moves[:, 0], moves[:, 1])


def _loop_offset(d: dict, unit: float) -> tuple[float, float]:
    """A loop's measured offset in the lower node's frame: ``distance_steps`` along ``bearing``
    (0, 0 where the views did not measure it), as the pose graph's loop factor has it."""
    dist, bearing = d.get("distance_steps"), d.get("bearing")
    if dist is None or bearing is None or not (math.isfinite(float(dist)) and math.isfinite(float(bearing))):
        return 0.0, 0.0
    rad = math.radians(float(bearing))
    return float(dist) * unit * math.cos(rad), float(dist) * unit * math.sin(rad)


def g2o_text(topomap, keep_rejected: bool = False, keep_candidates: bool = False) -> str:
    """The map's pose graph in g2o's 2-D format (module notes)."""
    import numpy as np

    from .errors import InputError
    from .params import MapParams

    g = topomap.corrected(keep_rejected=keep_rejected, keep_candidates=keep_candidates)
    nodes = sorted(g.nodes, key=lambda n: g.nodes[n]["index"])
    if not nodes or g.graph.get("positions") != "estimated" or \
            not all("heading" in g.nodes[n] and "x" in g.nodes[n] for n in nodes):
        raise InputError("the g2o export needs the pose graph's estimated poses: map with method "
                         "verified from descriptors with local features (a map positioned by ground "
                         "truth or GPS has no pose graph to export)")
    defaults = MapParams()

    def param(name: str) -> float:
        return float(g.graph.get(name, getattr(defaults, name)))

    idx = {n: int(g.nodes[n]["index"]) for n in nodes}
    pose = np.array([[float(g.nodes[n]["x"]), float(g.nodes[n]["y"]), math.radians(float(g.nodes[n]["heading"]))]
                     for n in nodes])
    lines = [f"VERTEX_SE2 {k} {p[0]:.9g} {p[1]:.9g} {_wrap(p[2]):.9g}" for k, p in enumerate(pose)]
    steps = topomap.step_measurements
    if steps is not None and len(steps[0]) != len(nodes) - 1:
        steps = None
    step_sigma = (param("step_sigma_steps"), math.radians(param("step_turn_sigma_deg")))
    sequential = sorted((min(idx[u], idx[v]), max(idx[u], idx[v])) for u, v, d in g.edges(data=True)
                        if d.get("kind") == "sequential")
    for i, j in sequential:
        if steps is not None and j == i + 1:
            dx, dy, dt, sxy, st = (float(a[i]) for a in steps)
        else:   # the estimated poses' own relative pose
            c, s = math.cos(pose[i, 2]), math.sin(pose[i, 2])
            ex, ey = pose[j, 0] - pose[i, 0], pose[j, 1] - pose[i, 1]
            dx, dy, dt = c * ex + s * ey, -s * ex + c * ey, pose[j, 2] - pose[i, 2]
            sxy, st = step_sigma
        info = _information(sxy, sxy, st)
        lines.append(f"EDGE_SE2 {i} {j} {dx:.9g} {dy:.9g} {_wrap(dt):.9g} " + " ".join(f"{v:.9g}" for v in info))
    loop_sigma = param("loop_sigma_steps")
    turn_sigma = math.radians(param("loop_turn_sigma_deg"))
    unit = _step_unit(g, pose, steps)
    loops = sorted((min(idx[u], idx[v]), max(idx[u], idx[v]), d) for u, v, d in g.edges(data=True)
                   if d.get("kind") == "loop")
    for i, j, d in loops:   # yaw: the heading of the higher index relative to the lower one
        yaw = d.get("yaw")
        known = yaw is not None and math.isfinite(float(yaw))
        turn = math.radians(float(yaw)) if known else 0.0
        info = _information(loop_sigma * unit, loop_sigma * unit, turn_sigma if known else float("inf"))
        ox, oy = _loop_offset(d, unit)
        lines.append(f"EDGE_SE2 {i} {j} {ox:.9g} {oy:.9g} {_wrap(turn):.9g} " + " ".join(f"{v:.9g}" for v in info))
    return "\n".join(lines) + "\n"


def write_g2o(topomap, path: str | Path, keep_rejected: bool = False, keep_candidates: bool = False,
              inputs: Iterable[Optional[str | Path]] = ()) -> Path:
    """Write the map's pose graph as g2o (module notes); returns the file written."""
    from .outputs import write_text

    return write_text(path, g2o_text(topomap, keep_rejected, keep_candidates), inputs)


# extension (lower case) -> writer; anything else is GraphML.
WRITERS: dict[str, Callable[..., Path]] = {
    ".json": write_node_link_json,
    ".g2o": write_g2o,
}


def format_of(path: str | Path) -> str:
    """The format ``write_map`` writes to ``path``: "json", "g2o" or "graphml"."""
    return {".json": "json", ".g2o": "g2o"}.get(Path(path).suffix.lower(), "graphml")


def write_map(topomap, path: str | Path, keep_rejected: bool = False, keep_candidates: bool = False) -> Path:
    """Write the corrected map in the format named by ``path``'s extension (``WRITERS``)."""
    writer = WRITERS.get(Path(path).suffix.lower(), write_graphml)
    return writer(topomap, path, keep_rejected=keep_rejected, keep_candidates=keep_candidates)
