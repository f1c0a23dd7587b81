"""A site: one map from several recordings (engine/site.py, ``panotopo map A B C``).

The recordings are rendered second-family routes described in seconds (tests/rendered_routes.py:
real local features, a grey-thumbnail global descriptor): the ``reverse`` route cut in two at
its middle (out along the corridor = A, back = B: B revisits A's places, each recording on its
own), and the start of ``crossing``, another world (C), which revisits none of them."""

import contextlib
import io
import json

import networkx as nx
import numpy as np
import pytest
from rendered_routes import described_route

import engine.synth2 as synth2
from engine.cli import main
from engine.descriptors.base import Descriptors
from engine.graph import TopoMap

SAME_PLACE_M = 1.5   # an exported loop joins views this close (the route's own loops: <= 1 m)


def _part(d: Descriptors, s: int, e: int) -> Descriptors:
    return Descriptors(stamps=d.stamps[s:e].copy(), frames=d.frames[s:e].copy(), shifts=d.shifts[s:e].copy(),
                       vectors=d.vectors[s:e].copy(), meta=dict(d.meta), features=d.features.subset(range(s, e)))


def _poses_csv(path, route: str):
    p = synth2.poses_for(route, 0)
    np.savetxt(path, np.c_[p.t, p.x, p.y], delimiter=",", header="t,x,y", comments="")
    return str(path)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("site")
    rev = described_route("reverse")
    half = len(rev) // 2
    _part(rev, 0, half).save(root / "A.npz")
    _part(rev, half, len(rev)).save(root / "B.npz")
    cross = described_route("crossing")
    _part(cross, 0, 50).save(root / "C.npz")
    return {"root": root, "A": str(root / "A.npz"), "B": str(root / "B.npz"), "C": str(root / "C.npz"),
            "P_rev": _poses_csv(root / "rev.csv", "reverse"), "P_cross": _poses_csv(root / "cross.csv", "crossing")}


def _cli(*argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) for a in argv])
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def site(files):
    """A and B mapped together (candidates kept, so that a person can confirm one)."""
    path = files["root"] / "site.graphml"
    rc, out, err = _cli("map", files["A"], files["B"], "-o", path, "--keep-candidates",
                        "--g2o", files["root"] / "site.g2o", "-q")
    assert rc == 0, err
    return path, err


def _distance(topomap: TopoMap, u: str, v: str) -> float:
    poses = synth2.poses_for("reverse", 0)
    stamps = np.array([topomap.graph.nodes[u]["stamp"], topomap.graph.nodes[v]["stamp"]])
    x, y = poses.at(stamps)
    return float(np.hypot(x[1] - x[0], y[1] - y[0]))


def test_two_recordings_of_one_route_make_one_map_with_loops_across_them(site):
    path, err = site
    topomap = TopoMap.read_graphml(path)
    g = topomap.graph
    assert {d["session"] for _, d in g.nodes(data=True)} == {"A.npz", "B.npz"}
    assert sorted(g.nodes) == sorted(f"n{k}" for k in range(g.number_of_nodes()))   # ids unique, index global
    for u, v, d in g.edges(data=True):
        if d["kind"] == "sequential":   # the path never jumps from one recording to the other
            assert g.nodes[u]["session"] == g.nodes[v]["session"]
            assert abs(g.nodes[u]["index"] - g.nodes[v]["index"]) == 1
    exported = topomap.loops(("auto", "confirmed", "manual"))
    across = [(u, v) for u, v, _ in exported if g.nodes[u]["session"] != g.nodes[v]["session"]]
    assert across, "the drive back (B) revisits the drive out (A): a loop across them"
    for u, v, _ in exported:   # no exported loop joins places far apart
        assert _distance(topomap, u, v) <= SAME_PLACE_M
    assert "joins no other" not in err   # both recordings are one part
    records = topomap.session_records()
    assert [r["session"] for r in records] == ["A.npz", "B.npz"] and all(r["descriptors"] for r in records)


def test_the_site_pose_graph_reads_back_with_gtsam(site, files):
    import gtsam

    graph, initial = gtsam.readG2o(str(files["root"] / "site.g2o"), False)
    topomap = TopoMap.read_graphml(site[0])
    assert initial.size() == topomap.node_count
    sequential = sum(1 for *_, d in topomap.graph.edges(data=True) if d["kind"] == "sequential")
    loops = len(topomap.loops(("auto", "confirmed", "manual", "candidate")))
    assert graph.size() == sequential + loops     # no step between the two recordings


def _edited(site, files):
    """The site with a person's decisions: one automatic loop across the recordings
    rejected, another loop confirmed, a place named."""
    topomap = TopoMap.read_graphml(site[0])
    g = topomap.graph
    auto = [(u, v) for u, v, d in topomap.loops(("auto",))]
    across = [(u, v) for u, v in auto if g.nodes[u]["session"] != g.nodes[v]["session"]]
    rejected = across[0]
    others = [(u, v) for u, v, _ in topomap.loops(("auto", "candidate")) if (u, v) != rejected]
    assert others, "the site has a second loop to confirm"
    confirmed = others[0]
    topomap.set_status(*rejected, "rejected")
    topomap.set_status(*confirmed, "confirmed")
    named = [n for n, d in g.nodes(data=True) if d["session"] == "B.npz"][3]
    topomap.set_label(named, "stairs")
    path = files["root"] / "site_edited.graphml"
    topomap.write_graphml(path, keep_candidates=True)

    def key(u, v):
        return tuple((g.nodes[n]["session"], g.nodes[n]["frame"]) for n in (u, v))

    return path, key(*rejected), key(*confirmed), (g.nodes[named]["session"], g.nodes[named]["frame"])


def test_adding_a_recording_keeps_the_decisions_and_one_that_joins_nothing_is_said(site, files):
    edited, rejected, confirmed, named = _edited(site, files)
    out_path = files["root"] / "site2.graphml"
    rc, out, err = _cli("map", edited, files["C"], "-o", out_path, "-q")
    assert rc == 0, err
    lines = [line for line in err.splitlines() if "C.npz" in line]
    assert len(lines) == 1 and "joins no other recording" in lines[0]
    topomap = TopoMap.read_graphml(out_path)
    g = topomap.graph
    assert {d["session"] for _, d in g.nodes(data=True)} == {"A.npz", "B.npz", "C.npz"}
    at = {(d["session"], d["frame"]): n for n, d in g.nodes(data=True)}
    # the recording that joins nothing: no exported loop touches it
    for u, v, _ in topomap.loops(("auto", "confirmed", "manual")):
        assert "C.npz" not in (g.nodes[u]["session"], g.nodes[v]["session"])
    u, v = (at[k] for k in confirmed)
    assert g.has_edge(u, v) and g.edges[u, v]["status"] == "confirmed"
    u, v = (at[k] for k in rejected)
    assert not g.has_edge(u, v)                       # the rejected loop is not in the map ...
    kept = json.loads(g.graph["decisions"])
    assert {"frames": [rejected[0][1], rejected[1][1]], "status": "rejected",
            "sessions": [rejected[0][0], rejected[1][0]]} in kept["loops"]   # ... and stays rejected
    assert g.nodes[at[named]]["label"] == "stairs"

    # evaluation: each recording's poses by name, the places across recordings reported apart
    rc, out, err = _cli("eval", out_path, "--poses", f"A.npz={files['P_rev']}", "--poses",
                        f"B.npz={files['P_rev']}", "--poses", f"C.npz={files['P_cross']}", "--json")
    assert rc == 0, err
    result = json.loads(out)
    assert result["recordings"] == 3
    assert result["across"]["events_found"] >= 1 and result["across"]["fp"] == 0
    for k in ("tp", "fp", "fn", "events_found", "events_total"):
        assert result["within"][k] + result["across"][k] == result[k if k != "events_total" else k]
    rc, out, err = _cli("eval", out_path, "--poses", files["P_rev"])
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "one --poses per recording" in err


def test_recordings_described_by_different_models_are_refused_in_one_line(files):
    a = Descriptors.load(files["A"])
    v = a.vectors[:, :64].copy()
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    other = Descriptors(stamps=a.stamps, frames=a.frames, shifts=a.shifts, vectors=v,
                        meta={**a.meta, "descriptor": "another-model"})
    other.save(files["root"] / "X.npz")
    rc, out, err = _cli("map", files["A"], files["root"] / "X.npz", "-o", files["root"] / "x.graphml")
    assert rc == 2
    assert len(err.strip().splitlines()) == 1 and "another-model" in err and "Traceback" not in err
    assert not (files["root"] / "x.graphml").exists()


def test_a_site_whose_recording_is_gone_and_a_recording_given_twice_are_one_line(site, files):
    g = nx.read_graphml(site[0])
    records = json.loads(g.graph["sessions"])
    records[1]["descriptors"] = records[1]["source"] = str(files["root"] / "gone.npz")
    g.graph["sessions"] = json.dumps(records)
    nx.write_graphml(g, files["root"] / "broken.graphml")
    rc, out, err = _cli("map", files["root"] / "broken.graphml", "-o", files["root"] / "y.graphml")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "B.npz" in err and "gone.npz" in err
    rc, out, err = _cli("map", files["A"], files["A"], "-o", files["root"] / "z.graphml")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "twice" in err
    rc, out, err = _cli("map", site[0], files["B"], "-o", files["root"] / "z.graphml")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "already in the site" in err
    rc, out, err = _cli("map", files["A"], files["C"], "--poses", files["P_rev"], "-o", files["root"] / "z.graphml")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "NAME=PATH" in err


def test_a_one_recording_map_grown_into_a_site_keeps_its_decisions_on_its_own_recording(tmp_path):
    from engine.loops import LoopCandidate
    from engine.params import MapParams
    from engine.site import read_site

    rng = np.random.default_rng(0)
    v = rng.normal(size=(12, 8)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    descs = Descriptors(stamps=np.arange(12.0), frames=np.arange(12) * 10, shifts=np.zeros(12, np.int64),
                        vectors=v, meta={"descriptor": "t"})
    topomap = TopoMap.build(descs, np.arange(12), [LoopCandidate(1, 9, 0.7, 3)],
                            MapParams(method="ours", node_sim_th=0.8, loop_sim_th=0.5),
                            source=str(tmp_path / "day1.mp4"))
    topomap.set_status("n1", "n9", "confirmed")
    topomap.set_label("n4", "lift")
    topomap.write_graphml(tmp_path / "day1.graphml")
    sessions, decisions = read_site(tmp_path / "day1.graphml")
    assert [s.name for s in sessions] == ["day1.mp4"]
    # keyed to its own recording, so that 'map NEW day1.graphml' (the new one first) cannot
    # put them on the new recording
    assert decisions["loops"] == [{"frames": [10, 90], "status": "confirmed", "sessions": ["day1.mp4", "day1.mp4"]}]
    assert decisions["labels"] == [{"frame": 40, "label": "lift", "session": "day1.mp4"}]



def test_recordings_described_apart_over_their_own_vocabularies_are_refused_in_one_line():
    from engine.errors import InputError
    from engine.site import check_vocabularies

    def descs(vocabulary):
        return Descriptors(stamps=np.arange(3.0), frames=np.arange(3), shifts=np.zeros(3, np.int64),
                           vectors=np.eye(3, dtype=np.float32),
                           meta={"descriptor": "effnet-vlad", "settings": {"vocabulary": vocabulary}})

    with pytest.raises(InputError, match="own vocabulary"):
        check_vocabularies([("a.npz", descs("map")), ("b.npz", descs("map"))])
    with pytest.raises(InputError, match="own vocabulary"):
        check_vocabularies([("a.npz", descs("map")), ("b.mp4", descs("sha1:1"))], fitted_on="b.mp4")
    check_vocabularies([("a.mp4", descs("sha1:1")), ("b.mp4", descs("sha1:1"))])


def test_a_site_describes_its_recordings_over_one_vocabulary(tmp_path):
    # effnet-vlad's default vocabulary is clustered from the recording itself: a site fits it
    # on the first recording and pools every other one over the same centres.
    import cv2

    import engine.synth as synth
    from engine.params import MapParams
    from engine.pipeline import DescribeSettings, method_settings
    from engine.site import _SharedVocabulary

    folders = []
    for seed in (0, 1):
        rec = synth.make_recording(route="crossing", look="indoor", seed=seed, width=128, height=64, max_frames=12)
        folder = tmp_path / f"day{seed}"
        folder.mkdir()
        for k, rgb in enumerate(rec.frames[:12:3]):
            cv2.imwrite(str(folder / f"{k:03d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        folders.append(folder)
    shared = _SharedVocabulary(method_settings(MapParams(), DescribeSettings(options={"input_height": 64})))
    first, second = (shared.describe(str(f)) for f in folders)
    vocab = first.meta["settings"]["vocabulary"]
    assert vocab.startswith("sha1:") and second.meta["settings"]["vocabulary"] == vocab
    assert shared.fitted_on == str(folders[0])
