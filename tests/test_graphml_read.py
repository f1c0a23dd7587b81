"""The streamed GraphML reader gives the graph networkx's reader gives, and refuses in one line
what it does not read."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from engine.graphml_read import GraphMLError, read_graphml


def _same(a: nx.Graph, b: nx.Graph) -> None:
    assert type(a) is type(b)
    assert {k: v for k, v in a.graph.items() if k not in ("node_default", "edge_default")} == b.graph
    assert list(a.nodes(data=True)) == list(b.nodes(data=True))
    assert list(a.edges(data=True)) == list(b.edges(data=True))


def test_a_map_written_by_panotopo_reads_back_as_networkx_reads_it(tmp_path):
    from engine.descriptors.base import Descriptors
    from engine.loops import LoopCandidate
    from engine.params import MapParams
    from engine.graph import TopoMap

    n = 30
    rng = np.random.default_rng(0)
    v = rng.standard_normal((n, 16)).astype(np.float32)
    descs = Descriptors(stamps=np.arange(n, dtype=float), frames=np.arange(n), shifts=np.zeros(n, np.int64),
                        vectors=v / np.linalg.norm(v, axis=1, keepdims=True), meta={"descriptor": "x"})
    loops = [LoopCandidate(a=2, b=20, similarity=0.9, window_count=0, yaw=12.5, score=4.0, status="auto",
                           evidence={"rule": "geometry confirms", "inliers": 55}),
             LoopCandidate(a=5, b=25, similarity=0.7, window_count=0, yaw=None, score=3.1, status="candidate")]
    topomap = TopoMap.build(descs, np.arange(n), loops, MapParams(), source="a <&> \"b\".mp4",
                            sessions=["one.mp4"] * 15 + ["two, é.mp4"] * 15)
    topomap.set_label("n3", "door & stairs")
    topomap.set_status("n5", "n25", "rejected")
    path = tmp_path / "map.graphml"
    topomap.write_graphml(path, keep_rejected=True)
    _same(nx.read_graphml(path), read_graphml(path))


def test_key_defaults_booleans_directed_graphs_and_edge_ids_as_networkx(tmp_path):
    text = """<?xml version='1.0' encoding='utf-8'?>
<graphml xmlns="http://graphml.graphdrawing.org/xmlns">
  <key id="k0" for="node" attr.name="colour" attr.type="string"><default>red</default></key>
  <key id="k1" for="edge" attr.name="ok" attr.type="boolean" />
  <key id="k2" for="edge" attr.name="w" attr.type="double" />
  <key id="k3" for="graph" attr.name="name" attr.type="string" />
  <graph edgedefault="directed">
    <node id="a"><data key="k0">blue</data></node>
    <node id="b" />
    <edge source="a" target="b"><data key="k1">True</data><data key="k2">1.5</data></edge>
    <edge source="b" target="a" id="e2"><data key="k1">0</data></edge>
    <data key="k3">site</data>
  </graph>
</graphml>"""
    path = tmp_path / "g.graphml"
    path.write_text(text)
    _same(nx.read_graphml(path), read_graphml(path))


@pytest.mark.parametrize("body, words", [
    ('<graph edgedefault="undirected"><node id="a"><graph edgedefault="undirected" /></node></graph>', "nested"),
    ('<graph edgedefault="undirected"><hyperedge /></graph>', "hyperedge"),
    ('<graph edgedefault="undirected"><node id="a" /><node id="b" /><edge source="a" target="b" />'
     '<edge source="b" target="a" /></graph>', "parallel"),
    ('<graph edgedefault="undirected"><node id="a"><data key="nope">1</data></node></graph>', "undeclared"),
    ('<key id="k" for="node" attr.name="n" attr.type="long" />'
     '<graph edgedefault="undirected"><node id="a"><data key="k">one</data></node></graph>', "invalid literal"),
])
def test_what_it_does_not_read_is_refused(tmp_path, body, words):
    path = tmp_path / "bad.graphml"
    path.write_text(f'<graphml xmlns="http://graphml.graphdrawing.org/xmlns">{body}</graphml>')
    with pytest.raises((GraphMLError, ValueError), match=words):
        read_graphml(path)
