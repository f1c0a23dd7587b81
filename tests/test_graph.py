import json
import xml.etree.ElementTree as ET

import networkx as nx
import numpy as np
import pytest

from engine.descriptors.base import Descriptors
from engine.errors import InputError
from engine.graph import TopoMap
from engine.loops import LoopCandidate
from engine.params import MapParams

PARAMS = MapParams(method="ours", node_sim_th=0.8, loop_sim_th=0.55, window_size=5,
                   count_th=2, neighbor_node_num=3)


def descriptors(n: int = 40, d: int = 8, seed: int = 0) -> Descriptors:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, d)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return Descriptors(
        stamps=np.arange(n) * 0.5 + 100.0,
        frames=np.arange(n, dtype=np.int64) * 15,          # every 15th source frame
        shifts=(np.arange(n, dtype=np.int64) * 7) % 64,
        vectors=v,
        meta={"descriptor": "test-desc", "interval": 0.5},
    )


def small_map(rows=None, loops=None) -> TopoMap:
    descs = descriptors()
    rows = np.arange(0, 40, 2) if rows is None else np.asarray(rows)   # 20 nodes
    loops = loops if loops is not None else [
        LoopCandidate(2, 15, 0.71, 3, yaw=90.0),
        LoopCandidate(3, 16, 0.66, 4),
        LoopCandidate(5, 12, 0.58, 3, yaw=-10.5),
    ]
    return TopoMap.build(descs, rows, loops, PARAMS, source="/data/run.mp4",
                         extra_meta={"shift": True, "vocabulary": ["a", "b"]})


def test_build_nodes_edges_and_meta():
    tm = small_map()
    g = tm.graph
    assert tm.node_count == 20
    assert tm.node_id(4) == "n4"
    n4 = g.nodes["n4"]
    # Node 4 is descriptor row 8: source frame 8 * 15, stamp 100 + 8 * 0.5, shift 56.
    assert n4 == {"index": 4, "frame": 120, "stamp": 104.0, "shift": 56, "label": ""}
    assert tm.frames().tolist() == [r * 15 for r in range(0, 40, 2)]
    assert tm.stamps()[1] == pytest.approx(101.0)
    seq = [(u, v) for u, v, d in g.edges(data=True) if d["kind"] == "sequential"]
    assert len(seq) == 19
    v = descriptors().vectors
    assert g.edges["n0", "n1"]["similarity"] == pytest.approx(float(v[0] @ v[2]), abs=1e-6)
    loops = tm.loops()
    assert [(u, v) for u, v, _ in loops] == [("n2", "n15"), ("n3", "n16"), ("n5", "n12")]
    assert loops[0][2] == {"kind": "loop", "similarity": 0.71, "status": "auto", "tier": "auto",
                           "window_count": 3, "yaw": 90.0}
    assert "yaw" not in loops[1][2]
    assert tm.meta["generator"].startswith("panotopo ")
    assert tm.meta["descriptor"] == "test-desc" and tm.meta["interval"] == 0.5
    assert tm.meta["method"] == "ours" and tm.meta["window_size"] == 5
    assert tm.meta["shift"] == 1  # bools are stored as 0/1
    assert json.loads(tm.meta["vocabulary"]) == ["a", "b"]
    assert tm.node_rows.tolist() == list(range(0, 40, 2))
    assert tm.node_vectors.shape == (20, 8)


def test_loops_on_path_arcs_or_out_of_range_are_dropped():
    tm = small_map(loops=[LoopCandidate(3, 4, 0.9, 0), LoopCandidate(1, 99, 0.9, 0)])
    assert tm.loops() == []
    assert tm.graph.edges["n3", "n4"]["kind"] == "sequential"


def test_curation_api():
    tm = small_map()
    tm.set_status("n15", "n2", "confirmed")
    tm.set_status("n3", "n16", "rejected")
    assert [u for u, _, _ in tm.loops(["confirmed"])] == ["n2"]
    assert [u for u, _, _ in tm.loops(["rejected", "confirmed"])] == ["n2", "n3"]
    with pytest.raises(InputError):
        tm.set_status("n0", "n1", "rejected")  # a path arc
    with pytest.raises(InputError):
        tm.set_status("n2", "n15", "manual")
    with pytest.raises(InputError):
        tm.set_status("n2", "n9", "confirmed")  # no arc at all

    tm.add_manual_loop("n0", "n19", yaw=180.0)
    d = tm.graph.edges["n0", "n19"]
    assert d["status"] == "manual" and d["yaw"] == 180.0 and d["window_count"] == 0
    v = tm.node_vectors
    assert d["similarity"] == pytest.approx(float(v[0] @ v[19]), abs=1e-6)
    for u, w in [("n0", "n0"), ("n0", "n19"), ("n0", "n1"), ("n0", "n77")]:
        with pytest.raises(InputError):
            tm.add_manual_loop(u, w)
    with pytest.raises(InputError):
        tm.remove_loop("n2", "n15")  # detected loops are rejected, not removed
    with pytest.raises(InputError):
        tm.set_status("n0", "n19", "rejected")
    tm.remove_loop("n19", "n0")
    assert not tm.graph.has_edge("n0", "n19")

    tm.set_label("n7", "kitchen door")
    assert tm.graph.nodes["n7"]["label"] == "kitchen door"
    with pytest.raises(InputError):
        tm.set_label("n70", "x")

    tm.set_positions(np.arange(20) * 1.0, np.zeros(20))
    assert tm.graph.nodes["n3"]["x"] == 3.0
    assert tm.positions()[0][5] == 5.0
    with pytest.raises(InputError):
        tm.set_positions(np.zeros(3), np.zeros(3))


def test_copy_is_independent():
    tm = small_map()
    other = tm.copy()
    other.set_status("n2", "n15", "rejected")
    other.set_label("n1", "x")
    assert tm.graph.edges["n2", "n15"]["status"] == "auto"
    assert tm.graph.nodes["n1"]["label"] == ""


def key_types(path) -> dict:
    """{(for, attr.name): set of attr.type} from the GraphML <key> elements."""
    ns = {"g": "http://graphml.graphdrawing.org/xmlns"}
    out: dict = {}
    for key in ET.parse(path).getroot().findall("g:key", ns):
        out.setdefault((key.get("for"), key.get("attr.name")), set()).add(key.get("attr.type"))
    return out


def curated_map() -> TopoMap:
    tm = small_map()
    tm.set_status("n2", "n15", "confirmed")
    tm.set_status("n3", "n16", "rejected")
    tm.add_manual_loop("n0", "n19", yaw=45.0)
    tm.set_label("n7", "door")
    tm.set_positions(np.linspace(0, 19, 20), np.linspace(5, -5, 20))
    return tm


def test_graphml_contract_networkx(tmp_path):
    tm = curated_map()
    path = tmp_path / "map.graphml"
    tm.write_graphml(path)
    assert [p.name for p in tmp_path.iterdir()] == ["map.graphml"]  # no temp file left

    types = key_types(path)
    assert all(len(t) == 1 for t in types.values()), types
    integer = ({"int"}, {"long"})  # networkx writes Python ints as GraphML "long"
    assert types[("node", "index")] in integer and types[("node", "frame")] in integer
    assert types[("node", "stamp")] == {"double"} and types[("node", "label")] == {"string"}
    assert types[("edge", "similarity")] == {"double"} and types[("edge", "yaw")] == {"double"}
    assert types[("edge", "window_count")] in integer
    assert types[("edge", "kind")] == {"string"} and types[("graph", "window_size")] in integer
    assert types[("graph", "loop_sim_th")] == {"double"}

    g = nx.read_graphml(path)
    assert g.number_of_nodes() == 20
    n7 = g.nodes["n7"]
    assert n7["label"] == "door" and n7["frame"] == 210 and isinstance(n7["frame"], int)
    assert isinstance(n7["stamp"], float) and n7["x"] == pytest.approx(7.0)
    assert not g.has_edge("n3", "n16")  # rejected: left out by default
    assert g.edges["n2", "n15"]["status"] == "confirmed"
    assert g.edges["n0", "n19"] == pytest.approx({"kind": "loop", "status": "manual", "yaw": 45.0,
                                                  "window_count": 0,
                                                  "similarity": tm.graph.edges["n0", "n19"]["similarity"]})
    assert g.graph["method"] == "ours" and g.graph["count_th"] == 2
    assert g.graph["generator"].startswith("panotopo")

    tm.write_graphml(path, keep_rejected=True)
    g = nx.read_graphml(path)
    assert g.edges["n3", "n16"]["status"] == "rejected"


def test_graphml_contract_igraph(tmp_path):
    igraph = pytest.importorskip("igraph")
    tm = curated_map()
    path = tmp_path / "map.graphml"
    tm.write_graphml(path)
    ig = igraph.Graph.Read_GraphML(str(path))
    assert ig.vcount() == 20 and not ig.is_directed()
    ids = ig.vs["id"]
    v7 = ig.vs[ids.index("n7")]
    assert v7["label"] == "door" and v7["frame"] == 210 and v7["index"] == 7
    assert v7["stamp"] == pytest.approx(107.0) and v7["x"] == pytest.approx(7.0)
    loops = {frozenset((ids[e.source], ids[e.target])): e for e in ig.es if e["kind"] == "loop"}
    assert set(loops) == {frozenset(p) for p in [("n2", "n15"), ("n5", "n12"), ("n0", "n19")]}
    e = loops[frozenset(("n2", "n15"))]
    assert e["status"] == "confirmed" and e["yaw"] == pytest.approx(90.0) and e["window_count"] == 3
    assert ig["method"] == "ours" and ig["loop_sim_th"] == pytest.approx(0.55)
    assert ig["source"] == "/data/run.mp4"

    tm.write_graphml(path, keep_rejected=True)
    ig = igraph.Graph.Read_GraphML(str(path))
    assert "rejected" in ig.es["status"]


def test_read_back_into_a_topomap(tmp_path):
    tm = curated_map()
    path = tmp_path / "map.graphml"
    tm.write_graphml(path, keep_rejected=True)
    back = TopoMap.read_graphml(path)
    assert back.node_rows is None and back.node_count == 20
    assert back.frames().tolist() == tm.frames().tolist()
    assert back.decisions() == tm.decisions()
    assert back.meta["neighbor_node_num"] == 3
    assert back.positions()[1][0] == pytest.approx(5.0)


def test_read_bad_files(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        TopoMap.read_graphml(tmp_path / "missing.graphml")
    junk = tmp_path / "junk.graphml"
    junk.write_text("this is not xml <<<")
    with pytest.raises(InputError, match="cannot read"):
        TopoMap.read_graphml(junk)
    foreign = tmp_path / "foreign.graphml"
    nx.write_graphml(nx.path_graph(3), foreign)
    with pytest.raises(InputError, match="not a panotopo map"):
        TopoMap.read_graphml(foreign)


def test_decisions_survive_a_rerun_with_other_nodes():
    tm = curated_map()
    tm.set_status("n5", "n12", "rejected")
    dec = json.loads(json.dumps(tm.decisions()))  # JSON round trip, like a session file
    # Source frames: node k of this map is descriptor row 2k, frame 30k.
    assert {"frames": [60, 450], "status": "confirmed"} in dec["loops"]
    assert {"frames": [0, 570], "yaw": 45.0} in dec["manual"]
    assert dec["labels"] == [{"frame": 210, "label": "door"}]

    # Re-run with every descriptor row a node (40 nodes); the detector now finds
    # the first loop on exactly the same frames (rows 4, 30), the second one a row
    # off (rows 6, 33 instead of 6, 32) and the third not at all.
    rerun = small_map(rows=np.arange(40), loops=[LoopCandidate(4, 30, 0.7, 3),
                                                 LoopCandidate(6, 33, 0.6, 3),
                                                 LoopCandidate(20, 35, 0.6, 3)])
    rerun.apply_decisions(dec)
    g = rerun.graph
    assert g.edges["n4", "n30"]["status"] == "confirmed"   # exact frames 60, 450
    # Frames 90 and 480 are nodes n6 and n32: no loop there, so the nearest-node rule
    # also finds no loop: the rejection cannot be applied and is kept.
    assert g.edges["n6", "n33"]["status"] == "auto"
    assert g.edges["n20", "n35"]["status"] == "auto"
    assert g.edges["n0", "n38"]["status"] == "manual" and g.edges["n0", "n38"]["yaw"] == 45.0
    assert g.nodes["n14"]["label"] == "door"
    assert rerun.unapplied["loops"] == [{"frames": [90, 480], "status": "rejected"},
                                        {"frames": [150, 360], "status": "rejected"}]
    again = rerun.decisions()
    for item in dec["loops"] + dec["manual"] + dec["labels"]:
        # Manual loop frames move to the nearest nodes; everything else is kept verbatim.
        if "yaw" in item:
            assert {"frames": [0, 570], "yaw": 45.0} in again["manual"]
        else:
            assert item in again["loops"] + again["labels"]


def test_decisions_nearest_node_rule():
    tm = small_map()  # nodes at frames 0, 30, 60, ...
    tm.apply_decisions({"loops": [{"frames": [62, 455], "status": "rejected"}],
                        "manual": [{"frames": [1, 2], "yaw": None},        # same node: unapplied
                                   {"frames": [150, 359], "yaw": None}],   # n5-n12 is a loop: made manual
                        "labels": [{"frame": 44, "label": "hall"}]})
    assert tm.graph.edges["n2", "n15"]["status"] == "rejected"  # 62 -> n2 (60), 455 -> n15 (450)
    assert tm.graph.edges["n5", "n12"]["status"] == "manual"
    assert tm.graph.nodes["n1"]["label"] == "hall"              # 44 is nearer 30 than 60
    assert tm.unapplied == {"loops": [], "manual": [{"frames": [1, 2], "yaw": None}], "labels": []}
    assert {"frames": [1, 2], "yaw": None} in tm.decisions()["manual"]


def test_decisions_outside_the_mapped_frames_are_kept_unapplied_not_snapped():
    """Issue 16 (finding 11): frames beyond the recording made a manual loop n0-n99 appear."""
    tm = small_map()  # nodes at frames 0, 30, ..., 570
    last = int(tm.frames().max())
    outside = {"loops": [{"frames": [0, last + 5000], "status": "rejected"}],
               "manual": [{"frames": [0, 10**9], "yaw": None}],
               "labels": [{"frame": last + 1, "label": "far away"}]}
    before = {(u, v) for u, v, _ in tm.loops()}
    tm.apply_decisions(outside)
    assert {(u, v) for u, v, _ in tm.loops()} == before
    assert not any(d.get("label") for _, d in tm.graph.nodes(data=True))
    assert tm.unapplied == outside          # kept, so a later map can still use them
