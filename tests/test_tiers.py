"""The two tiers of detected loops: accepted automatically, or candidates for a person."""

import igraph
import numpy as np
import pytest

from engine.evaluate import evaluate
from engine.graph import TopoMap
from engine.loops import LoopCandidate
from engine.poses import Poses
from test_graph import PARAMS, descriptors


def tiered_map() -> TopoMap:
    loops = [
        LoopCandidate(2, 15, 0.71, 0, yaw=90.0, status="auto",
                      evidence={"score": 6.5, "inliers": 120, "matches": 180, "inlier_ratio": 0.66,
                                "support": 3.1, "direction": 1, "confidence": 9.0, "distance_steps": 0.4}),
        LoopCandidate(5, 12, 0.58, 0, status="candidate", evidence={"score": 3.2, "support": float("nan")}),
    ]
    return TopoMap.build(descriptors(), np.arange(0, 40, 2), loops, PARAMS)


def test_candidates_stay_out_of_the_exported_map_unless_asked(tmp_path):
    tm = tiered_map()
    tm.write_graphml(tmp_path / "map.graphml")
    g = igraph.Graph.Read_GraphML(str(tmp_path / "map.graphml"))
    statuses = [e["status"] for e in g.es if e["kind"] == "loop"]
    assert statuses == ["auto"]
    tm.write_graphml(tmp_path / "all.graphml", keep_candidates=True)
    g = igraph.Graph.Read_GraphML(str(tmp_path / "all.graphml"))
    assert sorted(e["status"] for e in g.es if e["kind"] == "loop") == ["auto", "candidate"]


def test_evidence_is_typed_in_graphml_and_missing_numbers_are_left_out(tmp_path):
    tm = tiered_map()
    tm.write_graphml(tmp_path / "all.graphml", keep_candidates=True)
    back = TopoMap.read_graphml(tmp_path / "all.graphml")
    auto = back.graph.edges["n2", "n15"]
    assert isinstance(auto["inliers"], int) and auto["inliers"] == 120
    assert auto["inlier_ratio"] == pytest.approx(0.66)
    assert auto["direction"] == 1 and auto["tier"] == "auto"
    assert auto["distance_steps"] == pytest.approx(0.4)
    g = igraph.Graph.Read_GraphML(str(tmp_path / "all.graphml"))   # an independent reader
    assert [e["distance_steps"] for e in g.es if e["kind"] == "loop" and e["status"] == "auto"] == [pytest.approx(0.4)]
    cand = back.graph.edges["n5", "n12"]
    assert "support" not in cand          # NaN evidence is not written as a number
    assert cand["tier"] == "candidate"


def test_a_decision_on_a_candidate_is_kept_and_a_reset_goes_back_to_its_tier():
    tm = tiered_map()
    assert tm.decisions()["loops"] == []           # nothing decided yet
    tm.set_status("n5", "n12", "confirmed")
    dec = tm.decisions()
    assert dec["loops"] == [{"frames": [10 * 15, 24 * 15], "status": "confirmed"}]
    again = tiered_map()
    again.apply_decisions(dec)
    assert again.graph.edges["n5", "n12"]["status"] == "confirmed"
    again.reset_status("n5", "n12")
    assert again.graph.edges["n5", "n12"]["status"] == "candidate"
    assert again.decisions()["loops"] == []


def test_evaluation_counts_undecided_candidates_only_when_asked():
    tm = tiered_map()
    # Node k sits at x = k except node 12, which is where node 5 is: the candidate is true.
    n = tm.node_count
    x = np.arange(n, dtype=float)
    x[12] = 5.0
    x[15] = 2.0
    poses = Poses(t=tm.stamps(), x=x, y=np.zeros(n), yaw=np.zeros(n))
    without = evaluate(tm, poses, dist_th=0.5)
    with_candidates = evaluate(tm, poses, dist_th=0.5, include_candidates=True)
    assert with_candidates.tp == without.tp + 1
