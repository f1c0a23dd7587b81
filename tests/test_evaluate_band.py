"""The project's figures beside the paper's table (issue 41): a place is found by a loop within
1 m, a loop 1-2 m apart is neither right nor false (a don't-care band), beyond 2 m it is false."""

import json

import numpy as np
import pytest

from engine.cli import _evaluation_dict, _evaluation_lines, main
from engine.descriptors.base import Descriptors
from engine.errors import InputError
from engine.evaluate import (FALSE_BEYOND_M, FOUND_WITHIN_M, LoopBand, evaluate, evaluate_band,
                             loop_band)
from engine.graph import TopoMap
from engine.loops import LoopCandidate
from engine.params import MapParams
from engine.poses import Poses
from tests.test_evaluate import hand_map, hand_poses, site_map, site_poses

NN = 2   # temporal neighbours of the maps below


def return_map(apart: float, loops=((1, 8),), statuses=None) -> tuple[TopoMap, Poses]:
    """Out along y = 0 (nodes 0-4, 3 m apart), across at y = 6 (nodes 5-7), and back: node 8
    passes ``apart`` metres north of node 1 and nowhere near anything else."""
    pos = np.array([(0, 0), (3, 0), (6, 0), (9, 0), (12, 0), (12, 6), (6, 6), (0, 6), (3, apart)], float)
    m = len(pos)
    v = np.random.default_rng(0).normal(size=(m, 8)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    descs = Descriptors(stamps=np.arange(m, dtype=float), frames=np.arange(m), shifts=np.zeros(m, np.int64),
                        vectors=v, meta={"descriptor": "t"})
    params = MapParams(method="ours", node_sim_th=0.8, loop_sim_th=0.5, neighbor_node_num=NN)
    tm = TopoMap.build(descs, np.arange(m), [LoopCandidate(a, b, 0.6, 3) for a, b in loops], params)
    for (a, b), status in (statuses or {}).items():
        tm.set_status(f"n{a}", f"n{b}", status)
    return tm, Poses(t=np.arange(m, dtype=float), x=pos[:, 0], y=pos[:, 1])


def test_the_defaults_are_the_owners_call():
    assert (FOUND_WITHIN_M, FALSE_BEYOND_M) == (1.0, 2.0)


def test_a_loop_half_a_metre_apart_finds_the_place():
    band = evaluate_band(*return_map(0.5))
    assert (band.places_found, band.places_revisited) == (1, 1)
    assert (band.true_loops, band.dont_care_loops, band.false_loops) == (1, 0, 0)
    assert band.loop_band == {("n1", "n8"): "true"} and band.place_recall == 1.0


def test_a_loop_one_and_a_half_metres_apart_is_neither_right_nor_false():
    band = evaluate_band(*return_map(1.5))
    assert (band.true_loops, band.dont_care_loops, band.false_loops) == (0, 1, 0)
    assert band.loop_band == {("n1", "n8"): "don't care"}
    assert (band.places_found, band.places_revisited) == (0, 0)   # no two views within 1 m


def test_a_loop_two_and_a_half_metres_apart_is_false():
    band = evaluate_band(*return_map(2.5))
    assert (band.true_loops, band.dont_care_loops, band.false_loops) == (0, 0, 1)
    assert band.neighbour_loops == 0


def test_the_paper_table_at_one_metre_is_unaffected_by_the_band():
    """The paper counts the 1.5 m loop a false positive, whatever the band says; and the band
    options change nothing in ``evaluate``."""
    tm, poses = return_map(1.5)
    ev = evaluate(tm, poses, dist_th=1.0)
    assert (ev.tp, ev.fp) == (0, 1)
    before = ev.as_dict()
    for found, false in ((1.0, 2.0), (0.5, 3.0), (2.0, 2.0)):
        evaluate_band(tm, poses, found_within=found, false_beyond=false)
        assert evaluate(tm, poses, dist_th=1.0).as_dict() == before
    # The hand-counted map of test_evaluate keeps its paper counts too.
    assert (lambda e: (e.tp, e.fp, e.fn, e.tn))(evaluate(hand_map(), hand_poses())) == (2, 2, 3, 59)


@pytest.mark.parametrize("apart, expected", [(0.0, "true"), (0.5, "true"), (1.0, "true"), (1.001, "don't care"),
                                             (1.5, "don't care"), (2.0, "don't care"), (2.001, "false"),
                                             (2.5, "false"), (100.0, "false")])
def test_loop_band_by_distance(apart, expected):
    assert loop_band(apart) == LoopBand(expected)
    assert evaluate_band(*return_map(apart)).loop_band == {("n1", "n8"): expected}


def test_the_band_limits_are_options():
    tm, poses = return_map(1.5)
    band = evaluate_band(tm, poses, found_within=2.0, false_beyond=3.0)
    assert (band.true_loops, band.places_found, band.places_revisited) == (1, 1, 1)
    band = evaluate_band(tm, poses, found_within=0.5, false_beyond=1.0)
    assert band.false_loops == 1
    for found, false in ((2.0, 1.0), (float("nan"), 2.0), (1.0, float("inf")), (-1.0, 2.0)):
        with pytest.raises(InputError):
            evaluate_band(tm, poses, found_within=found, false_beyond=false)


def test_temporal_neighbours_stay_false_and_rejected_or_queued_loops_do_not_count():
    # Node 6 moved 0.6 m from node 4, two nodes later (NN = 2): a loop between temporal
    # neighbours within 2 m is false all the same (the paper's rule), and counted apart.
    tm, poses = return_map(0.5, loops=((1, 8), (4, 6), (0, 7)), statuses={(0, 7): "candidate"})
    x, y = poses.x.copy(), poses.y.copy()
    x[6], y[6] = 12.0, 0.6
    poses = Poses(t=poses.t, x=x, y=y)
    band = evaluate_band(tm, poses)
    assert band.loop_band == {("n1", "n8"): "true", ("n4", "n6"): "false"}
    assert (band.false_loops, band.neighbour_loops) == (1, 1)
    assert evaluate(tm, poses).fp == 1        # the paper calls it false as well
    with_queue = evaluate_band(tm, poses, include_candidates=True)
    assert with_queue.loop_band[("n0", "n7")] == "false" and with_queue.false_loops == 2   # 6 m apart
    tm.set_status("n1", "n8", "rejected")
    band = evaluate_band(tm, poses)
    assert (band.true_loops, band.places_found, band.places_revisited) == (0, 0, 1)


def test_hand_counted_map():
    band = evaluate_band(hand_map(), hand_poses())
    # (2,6) 0.5 m and (0,8) 0.4 m: true; (1,10) far: false; (3,5) 0.94 m but two nodes apart
    # (neighbor_node_num 2): false by the paper's rule; (4,12) and (6,11) rejected: not counted.
    assert band.loop_band == {("n0", "n8"): "true", ("n2", "n6"): "true", ("n1", "n10"): "false",
                              ("n3", "n5"): "false"}
    assert (band.places_found, band.places_revisited) == (1, 2)
    assert (band.false_loops, band.neighbour_loops) == (2, 1)
    json.dumps(band.as_dict())


def test_a_site_scores_loops_across_recordings():
    band = evaluate_band(site_map(), site_poses())
    # across: (0,11) (5,6) (2,9) 0.3 m apart: true; (1,7) 6 m: false; (0,3) within A, 6 m: false.
    assert (band.true_loops, band.dont_care_loops, band.false_loops) == (3, 0, 2)


@pytest.mark.parametrize("seed", range(3))
def test_the_band_agrees_with_the_paper_counts_on_random_maps(seed):
    """Every counted loop is a paper TP or FP at found_within; true loops are its TPs; a false
    loop is always a paper FP; the places are its revisit events."""
    rng = np.random.default_rng(seed)
    m = 60
    xy = np.cumsum(rng.normal(size=(m, 2)), axis=0) * 0.4
    v = rng.normal(size=(m, 4)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    descs = Descriptors(np.arange(m, dtype=float), np.arange(m), np.zeros(m, np.int64), v, {})
    pairs = sorted({(int(a), int(b)) for a, b in rng.integers(0, m, size=(80, 2)) if b - a >= 2})
    tm = TopoMap.build(descs, np.arange(m), [LoopCandidate(a, b, 0.5, 0) for a, b in pairs],
                       MapParams(loop_sim_th=0.5, node_sim_th=0.8))
    tm.set_positions(xy[:, 0], xy[:, 1])
    ev = evaluate(tm, dist_th=1.0, neighbor_node_num=3)
    band = evaluate_band(tm, neighbor_node_num=3)
    assert band.true_loops == ev.tp
    assert band.true_loops + band.dont_care_loops + band.false_loops == ev.tp + ev.fp
    assert (band.places_found, band.places_revisited) == (ev.events_found, ev.events_total)
    for (u, v_), b in band.loop_band.items():
        i, j = int(u[1:]), int(v_[1:])
        d = float(np.hypot(*(xy[i] - xy[j])))
        if d > 2.0 or j - i <= 3:       # beyond 2 m, or temporal neighbours
            expected = "false"
        else:
            expected = "true" if d <= 1.0 else "don't care"
        assert b == expected, (i, j, d)


# ----- panotopo eval: the paper's table unchanged, the band added -----------------------------

def write_case(tmp_path, apart: float):
    tm, poses = return_map(apart)
    path, csv = tmp_path / "m.graphml", tmp_path / "poses.csv"
    tm.write_graphml(path)
    csv.write_text("t,x,y\n" + "".join(f"{t},{x},{y}\n" for t, x, y in zip(poses.t, poses.x, poses.y)))
    return tm, poses, path, csv


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_eval_adds_the_band_and_keeps_the_paper_table(tmp_path, capsys):
    tm, poses, path, csv = write_case(tmp_path, 1.5)
    ev = evaluate(TopoMap.read_graphml(path), poses, dist_th=1.0)
    code, text, err = run_cli(capsys, "eval", path, "--poses", csv, "--json")
    assert code == 0, err
    d = json.loads(text)
    paper = _evaluation_dict(ev)
    assert {k: d[k] for k in paper} == paper                  # every old key, its old value
    assert set(d) == set(paper) | {"band"}
    assert d["band"]["found_within"] == 1.0 and d["band"]["false_beyond"] == 2.0
    assert (d["band"]["true_loops"], d["band"]["dont_care_loops"], d["band"]["false_loops"]) == (0, 1, 0)
    code, text, err = run_cli(capsys, "eval", path, "--poses", csv)
    assert code == 0, err
    assert text.startswith(_evaluation_lines(ev) + "\n")     # the paper's lines first, as they were
    assert "don't care) 1" in text.splitlines()[-1] and text.splitlines()[-1].startswith("project:")


def test_eval_band_options(tmp_path, capsys):
    _, _, path, csv = write_case(tmp_path, 1.5)
    code, text, err = run_cli(capsys, "eval", path, "--poses", csv, "--json", "--found-within", "2",
                              "--false-beyond", "3", "--dist-th", "0.5")
    assert code == 0, err
    d = json.loads(text)
    assert d["band"]["true_loops"] == 1 and d["band"]["places_found"] == 1
    assert (d["tp"], d["fp"]) == (0, 1)                        # the paper's table at --dist-th 0.5
    code, _, err = run_cli(capsys, "eval", path, "--poses", csv, "--found-within", "2", "--false-beyond", "1")
    assert code != 0 and "--false-beyond" in err


# ----- the benchmarks: the band in their rows and in the runs table ---------------------------

def test_benchmark_rows_carry_the_band():
    from types import SimpleNamespace

    from benchmarks.harness import score_map, sum_rows

    case = SimpleNamespace(route="r", look="l", seed=0, family="f")
    rows = []
    for apart in (0.5, 1.5, 2.5):
        tm, poses = return_map(apart, loops=((1, 8), (0, 7)), statuses={(0, 7): "candidate"})
        rows.append(score_map(tm, poses, case, "m", eval_nn=NN))
    assert [(r.true_loops, r.dont_care_loops, r.band_false_loops) for r in rows] == [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
    assert [r.fp for r in rows] == [0, 1, 1]                  # the paper's 1 m, unchanged
    assert all(r.band_false_candidates == 1 for r in rows)    # (0, 7) is 6 m apart
    t = sum_rows(rows, "m")
    assert (t["true_loops"], t["dont_care_loops"], t["band_false_loops"], t["band_false_candidates"]) == (1, 1, 1, 3)


def test_the_runs_table_gains_the_band_columns_and_old_rows_stay_readable(tmp_path):
    from benchmarks.runs import COLUMNS, append_run, read_runs

    old = COLUMNS[:COLUMNS.index("notes") + 1]
    path = tmp_path / "runs.csv"
    path.write_text(",".join(old) + "\n2026-11-22,abc,first,0-4,ours,40,10,8,1,9,3,2,\"a note, with a comma\"\n")
    append_run({"family": "first", "seeds": [0, 1], "method": "verified", "places": 10, "places_found": 9,
                "false_loops": 2, "true_loops": 30, "dont_care_loops": 2, "band_false_loops": 0}, path)
    rows = read_runs(path)
    assert path.read_text().splitlines()[0] == ",".join(COLUMNS)
    assert rows[0]["notes"] == "a note, with a comma" and rows[0]["false_loops"] == "1"
    assert (rows[0]["true_loops"], rows[0]["dont_care_loops"], rows[0]["band_false_loops"]) == ("", "", "")
    assert (rows[1]["true_loops"], rows[1]["dont_care_loops"], rows[1]["band_false_loops"]) == ("30", "2", "0")
    append_run({"family": "first", "seeds": "0", "method": "ours"}, path)
    assert len(read_runs(path)) == 3
