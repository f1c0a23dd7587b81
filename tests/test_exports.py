"""The node-link JSON export: strict JSON that plain ``json``, networkx and igraph read back, with
the same graph, node and edge attributes (names, values, types) as the GraphML of the same map;
``map -o site.json`` picks it by extension, ``--json PATH`` writes it beside the GraphML."""

from __future__ import annotations

import json
import math

import networkx as nx
import numpy as np
import pytest

from engine.cli import main
from engine.descriptors.base import Descriptors
from engine.exports import NODE_LINK_EDGES, format_of, node_link_data, write_map, write_node_link_json
from engine.graph import TopoMap
from engine.loops import LoopCandidate
from engine.params import MapParams

PARAMS = MapParams(method="ours", node_sim_th=0.8, loop_sim_th=0.55, window_size=5,
                   count_th=2, neighbor_node_num=3)


def descriptors(n: int = 40, d: int = 8, seed: int = 0) -> Descriptors:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, d)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return Descriptors(stamps=np.arange(n) * 0.5 + 100.0, frames=np.arange(n, dtype=np.int64) * 15,
                       shifts=(np.arange(n, dtype=np.int64) * 7) % 64, vectors=v,
                       meta={"descriptor": "test-desc", "interval": 0.5})


def curated_map() -> TopoMap:
    """A map with every kind of arc: auto, confirmed, rejected, manual (one of unknown similarity),
    a label and positions."""
    loops = [LoopCandidate(2, 15, 0.71, 3, yaw=90.0), LoopCandidate(3, 16, 0.66, 4),
             LoopCandidate(5, 12, 0.58, 3, yaw=-10.5)]
    tm = TopoMap.build(descriptors(), np.arange(0, 40, 2), loops, PARAMS, source="/data/run.mp4",
                       extra_meta={"shift": True})
    tm.set_status("n2", "n15", "confirmed")
    tm.set_status("n3", "n16", "rejected")
    tm.add_manual_loop("n0", "n19", yaw=45.0)
    tm.add_manual_loop("n1", "n18", similarity=float("nan"))
    tm.set_label("n7", "door")
    tm.set_positions(np.linspace(0, 19, 20), np.linspace(5, -5, 20))
    return tm


def strict_load(path) -> dict:
    """Plain ``json``, refusing NaN and Infinity (not JSON)."""
    def refuse(name):
        raise ValueError(f"not strict JSON: {name}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


def same_value(a, b) -> bool:
    """Equal values of equal JSON type; GraphML's NaN is JSON's null."""
    if isinstance(a, float) and math.isnan(a):
        return b is None
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("keep_rejected", [False, True])
def test_json_has_the_graphml_attributes(tmp_path, keep_rejected):
    tm = curated_map()
    graphml, js = tmp_path / "site.graphml", tmp_path / "site.json"
    tm.write_graphml(graphml, keep_rejected=keep_rejected)
    write_node_link_json(tm, js, keep_rejected=keep_rejected)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site.graphml", "site.json"]   # no temp file
    g = nx.read_graphml(graphml)
    for reader_only in ("node_default", "edge_default"):   # networkx's GraphML reader adds these
        g.graph.pop(reader_only, None)
    data = strict_load(js)

    assert data["directed"] is False and data["multigraph"] is False
    assert set(data["graph"]) == set(g.graph)
    assert all(same_value(g.graph[k], data["graph"][k]) for k in g.graph)
    nodes = {n["id"]: n for n in data["nodes"]}
    assert set(nodes) == set(g.nodes)
    for n, attrs in g.nodes(data=True):
        assert set(nodes[n]) - {"id"} == set(attrs), n
        assert all(same_value(v, nodes[n][k]) for k, v in attrs.items()), n
    edges = {frozenset((e["source"], e["target"])): e for e in data[NODE_LINK_EDGES]}
    assert len(edges) == len(data[NODE_LINK_EDGES]) == g.number_of_edges()
    for u, v, attrs in g.edges(data=True):
        e = edges[frozenset((u, v))]
        assert set(e) - {"source", "target"} == set(attrs), (u, v)
        assert all(same_value(val, e[k]) for k, val in attrs.items()), (u, v)
    statuses = {e["status"] for e in data[NODE_LINK_EDGES]}
    assert ("rejected" in statuses) == keep_rejected
    assert edges[frozenset(("n1", "n18"))]["similarity"] is None      # NaN written as null


def test_networkx_and_igraph_read_it_back(tmp_path):
    tm = curated_map()
    path = tmp_path / "site.json"
    write_node_link_json(tm, path)
    data = strict_load(path)

    g = nx.node_link_graph(data, edges=NODE_LINK_EDGES)
    want = tm.corrected()
    assert not g.is_directed() and set(g.nodes) == set(want.nodes) and set(g.edges) == set(want.edges)
    assert g.nodes["n7"]["label"] == "door" and g.nodes["n7"]["frame"] == 210
    assert g.edges["n2", "n15"]["status"] == "confirmed" and g.edges["n2", "n15"]["yaw"] == pytest.approx(90.0)
    assert g.graph["method"] == "ours" and g.graph["count_th"] == 2

    igraph = pytest.importorskip("igraph")
    ig = igraph.Graph.DictList(vertices=data["nodes"], edges=data[NODE_LINK_EDGES], directed=False,
                               vertex_name_attr="id", edge_foreign_keys=("source", "target"))
    assert ig.vcount() == want.number_of_nodes() and ig.ecount() == want.number_of_edges()
    ids = ig.vs["id"]
    v7 = ig.vs[ids.index("n7")]
    assert v7["label"] == "door" and v7["index"] == 7 and v7["stamp"] == pytest.approx(107.0)
    assert v7["x"] == pytest.approx(7.0)
    loops = {frozenset((ids[e.source], ids[e.target])) for e in ig.es if e["kind"] == "loop"}
    assert loops == {frozenset(p) for p in [("n2", "n15"), ("n5", "n12"), ("n0", "n19"), ("n1", "n18")]}


def test_format_by_extension(tmp_path):
    tm = curated_map()
    assert format_of("a.JSON") == "json" and format_of("a.graphml") == "graphml" and format_of("a.xml") == "graphml"
    write_map(tm, tmp_path / "a.json")
    write_map(tm, tmp_path / "a.graphml")
    assert strict_load(tmp_path / "a.json") == node_link_data(tm)
    assert nx.read_graphml(tmp_path / "a.graphml").number_of_nodes() == tm.node_count


def test_map_command_writes_json(tmp_path, capsys):
    npz = tmp_path / "run.npz"
    descriptors(n=60, d=16, seed=3).save(npz)   # meta without "shift": read as shifted
    common = ["map", str(npz), "--method", "shift-simple", "--node-sim-th", "0.5", "--loop-sim-th", "0.6", "-q"]
    assert main([*common, "-o", str(tmp_path / "only.json")]) == 0
    assert main([*common, "-o", str(tmp_path / "site.graphml"), "--json", str(tmp_path / "site.json")]) == 0
    only, both = strict_load(tmp_path / "only.json"), strict_load(tmp_path / "site.json")
    assert only == both
    g = nx.read_graphml(tmp_path / "site.graphml")
    assert {n["id"] for n in both["nodes"]} == set(g.nodes) and len(both[NODE_LINK_EDGES]) == g.number_of_edges()
    # the JSON may not replace an input of the command: one line, exit 2
    assert main([*common, "-o", str(tmp_path / "x.graphml"), "--json", str(npz)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "same file as the input" in err[0]
