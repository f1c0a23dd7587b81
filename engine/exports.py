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

``write_map`` picks the format by the output's extension: ``.json`` -> node-link JSON,
anything else -> GraphML (as before). A new format is one function here and one entry in
``WRITERS`` (the lead's g2o export of the pose graph goes here).
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


# extension (lower case) -> writer; anything else is GraphML.
WRITERS: dict[str, Callable[..., Path]] = {
    ".json": write_node_link_json,
}


def format_of(path: str | Path) -> str:
    """The format ``write_map`` writes to ``path``: "json" or "graphml"."""
    return "json" if Path(path).suffix.lower() == ".json" else "graphml"


def write_map(topomap, path: str | Path, keep_rejected: bool = False, keep_candidates: bool = False) -> Path:
    """Write the corrected map in the format named by ``path``'s extension (``WRITERS``)."""
    writer = WRITERS.get(Path(path).suffix.lower(), write_graphml)
    return writer(topomap, path, keep_rejected=keep_rejected, keep_candidates=keep_candidates)
