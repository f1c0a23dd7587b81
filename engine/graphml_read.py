"""GraphML read as a stream: the graph networkx's ``read_graphml`` gives, without its tree.

networkx parses the whole file into an ElementTree first: a site of 360,000 nodes (a 211 MB
file) took 42 s and 4.2 GB to read, most of it the tree, before the graph was built. Here
each node and edge is added as its element ends and the element is dropped, so memory is
the graph's own. The result is what ``networkx.read_graphml`` returns for the GraphML a
panotopo map holds (typed ``data`` by their ``key``, graph attributes, directed or not, an
edge's ``id`` as its attribute; a key's default is not given to the nodes and edges without
it, as networkx does not); what this reader does not take (parallel edges, nested graphs,
hyperedges, ports, yFiles data) is refused with ``GraphMLError`` rather than read
differently.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import networkx as nx

_TYPES = {"int": int, "integer": int, "long": int, "float": float, "double": float, "boolean": bool,
          "string": str}
_BOOL = {"true": True, "false": False, "0": False, "1": True}


class GraphMLError(ValueError):
    """The file is not GraphML this reader takes (the message says what)."""


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _value(kind: type, text: str):
    if kind is bool:
        try:
            return _BOOL[text.strip().lower()]
        except KeyError:
            raise GraphMLError(f"not a boolean: {text[:40]!r}") from None
    return kind(text)


def read_graphml(path: str | Path) -> nx.Graph:
    """The graph in ``path`` (``GraphMLError`` or ``ET.ParseError`` when it cannot be read)."""
    keys: dict[str, tuple[str, type]] = {}     # id -> (name, type)
    graph_data: dict = {}
    g = None
    open_tags: list[str] = []
    data: dict = {}
    graph_elem = None
    for event, elem in ET.iterparse(str(path), events=("start", "end")):
        tag = _local(elem.tag)
        if event == "start":
            open_tags.append(tag)
            if tag == "graph":
                if graph_elem is not None:
                    raise GraphMLError("nested graphs are not read")
                graph_elem = elem
                directed = elem.get("edgedefault", "directed") == "directed"
                g = nx.DiGraph() if directed else nx.Graph()
            elif tag in ("node", "edge"):
                data = {}
            elif tag in ("hyperedge", "port"):
                raise GraphMLError(f"{tag}s are not read")
            continue
        open_tags.pop()
        owner = open_tags[-1] if open_tags else ""
        if tag == "key":
            kind = elem.get("attr.type")
            name = elem.get("attr.name")
            if elem.get("yfiles.type") is not None:
                raise GraphMLError("yFiles data are not read")
            if name is None or (kind or "string") not in _TYPES:
                raise GraphMLError(f"key {elem.get('id')!r} has no name or an unknown type {kind!r}")
            keys[elem.get("id")] = (name, _TYPES[kind or "string"])
        elif tag == "data":
            if len(elem):
                raise GraphMLError("data with sub-elements (yFiles) are not read")
            key = elem.get("key")
            if key not in keys:
                raise GraphMLError(f"data of an undeclared key {key!r}")
            name, kind = keys[key]   # an empty element is "" whatever its type, as networkx reads it
            (graph_data if owner == "graph" else data)[name] = "" if elem.text is None else _value(kind, elem.text)
        elif tag == "node":
            node = elem.get("id")
            if node is None:
                raise GraphMLError("a node without an id")
            g.add_node(node, **data)
            graph_elem.remove(elem)   # the graph keeps no element it has read
        elif tag == "edge":
            u, v = elem.get("source"), elem.get("target")
            if u is None or v is None:
                raise GraphMLError("an edge without source or target")
            attrs = dict(data)
            if elem.get("id") is not None:
                attrs["id"] = elem.get("id")
            if g.has_edge(u, v):   # networkx makes a multigraph: never a panotopo map
                raise GraphMLError(f"parallel edges between {u!r} and {v!r} are not read")
            directed = elem.get("directed")
            if directed is not None and (directed == "true") != g.is_directed():
                raise GraphMLError("edges of both kinds, directed and not, are not read")
            g.add_edge(u, v, **attrs)
            graph_elem.remove(elem)
    if g is None:
        raise GraphMLError("no graph element")
    g.graph.update(graph_data)
    return g
