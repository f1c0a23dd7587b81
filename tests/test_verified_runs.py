"""Step 5 of ``verified``: long runs close a stretch driven back with a lateral offset."""

from dataclasses import replace

import numpy as np
import pytest

from engine.benchmark import Case, describe_case
from engine.evaluate import evaluate
from engine.loops_verified import RUN_LENGTH, run_means
from engine.params import MapParams
from engine.pipeline import build_map


def test_run_means_average_whole_runs_along_either_diagonal():
    rng = np.random.default_rng(0)
    m, h = 40, RUN_LENGTH // 2
    z = rng.normal(size=(m, m)).astype(np.float32)
    back = run_means(z, RUN_LENGTH, -1)
    fwd = run_means(z, RUN_LENGTH, 1)
    i, j = 12, 25
    k = np.arange(-h, h + 1)
    assert back[i, j] == pytest.approx(z[i + k, j - k].mean(), abs=1e-5)
    assert fwd[i, j] == pytest.approx(z[i + k, j + k].mean(), abs=1e-5)
    # A run that leaves the matrix or touches a NaN (temporal neighbour) is not scored.
    assert back[h - 1, 20] == -np.inf and fwd[20, m - h] == -np.inf
    z[i + 2, j - 2] = np.nan
    assert run_means(z, RUN_LENGTH, -1)[i, j] == -np.inf
    assert np.isfinite(run_means(z, RUN_LENGTH, 1)[i, j])


@pytest.fixture(scope="module")
def offset_indoor():
    # Seed 31 of the benchmark: its offset return is found by the long-run step only.
    return describe_case(Case("offset", "indoor", seed=31), shifts=(True,), input_height=128)


def test_offset_return_is_closed_by_a_long_run_and_nothing_else_is(offset_indoor):
    descs = offset_indoor.by_shift[True]
    assert descs.colours is not None and descs.colours.shape == (len(descs), 512)
    topomap = build_map(descs, MapParams(method="verified-rules"))
    ev = evaluate(topomap, offset_indoor.poses, neighbor_node_num=5)
    assert ev.fp == 0
    assert ev.events_total == 1 and ev.events_found == 1
    assert len(topomap.loops()) == 1        # one loop for the one stretch driven twice
    # The return is driven the other way: the loop's yaw says so.
    (yaw,) = [d["yaw"] for _, _, d in topomap.loops() if "yaw" in d][:1]
    assert abs(abs(yaw) - 180.0) < 30.0


def test_without_colour_histograms_the_offset_return_stays_open(offset_indoor):
    """Files written before colour histograms existed map as before (step 5 skipped)."""
    descs = replace(offset_indoor.by_shift[True], colours=None)
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), offset_indoor.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == 0


def test_long_runs_can_be_switched_off_from_the_cli(offset_indoor, tmp_path):
    import igraph

    from engine.cli import main

    npz = tmp_path / "offset.npz"
    offset_indoor.by_shift[True].save(npz)
    loops = {}
    for flag in ([], ["--no-long-runs"]):
        out = tmp_path / f"map{len(flag)}.graphml"
        assert main(["map", str(npz), "-o", str(out), "--method", "verified-rules", *flag]) == 0
        g = igraph.Graph.Read_GraphML(str(out))
        loops[bool(flag)] = sum(1 for e in g.es if e["kind"] == "loop")
        assert int(g["long_runs"]) == (0 if flag else 1)
    assert loops == {False: 1, True: 0}



def test_a_corridor_return_whose_alignment_flips_is_still_parallel():
    """Indoors the column alignment says 0 degrees on most pairs of a true return driven the
    other way (a corridor looks alike both ways): only the yaw's axis is checked."""
    case = describe_case(Case("offset", "indoor", seed=40), shifts=(True,), input_height=128)
    ev = evaluate(build_map(case.by_shift[True], MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == ev.events_total == 1


def test_runs_the_alignment_says_went_the_other_way_are_not_loops():
    """Second laps of an outdoor loop also make backward runs between two streets; the
    alignment is sure those pairs face the same way, so they are rejected."""
    case = describe_case(Case("loop", "outdoor", seed=72, people=3, noise=0.01), shifts=(True,), input_height=128)
    ev = evaluate(build_map(case.by_shift[True], MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == ev.events_total == 2


def test_in_open_spaces_local_alignment_picks_the_diagonal_of_the_same_place(monkeypatch):
    """Outdoors the mean score of the three parallel diagonals can favour the one a node
    off (1.3 m away with the 0.8 m offset); local alignment finds the views least displaced."""
    import engine.loops_verified as lv

    case = describe_case(Case("offset", "outdoor", seed=92, people=3, noise=0.01), shifts=(True,),
                         input_height=128)
    descs = case.by_shift[True]
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == ev.events_total == 1
    monkeypatch.setattr(lv, "LOCAL_STEP_MAX", 0.0)   # the descriptor's mean decides everywhere
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 1 and ev.events_found == 0


@pytest.mark.parametrize("look", ["indoor", "outdoor"])
def test_mirror_alike_streets_of_a_crossing_route_are_not_loops(look):
    """The crossing route's corridors mirror each other (same layout, other walls): runs
    between them match the descriptor but not the walls' colours (indoors), or face the
    wrong way to the column alignment (outdoors, where it is reliable)."""
    case = describe_case(Case("crossing", look, seed=94, people=4, lighting_drift=0.3, noise=0.01),
                         shifts=(True,), input_height=128)
    ev = evaluate(build_map(case.by_shift[True], MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0


def test_turning_between_nodes_is_measured_from_consecutive_alignments():
    """On the reverse route (out, left, a U-turn at the dead end, right, back: 360 degrees in
    all) the U-turn shows as a half circle, and the straight way out stays well below it."""
    from engine.calibrate import node_threshold
    from engine.nodes import make_nodes
    from engine.verify import cumulative_turning

    case = describe_case(Case("reverse", "outdoor", seed=0), shifts=(True,), input_height=128)
    descs = case.by_shift[True]
    rows = make_nodes(descs.vectors, node_threshold(descs.vectors))
    turned = cumulative_turning(descs.columns[rows], descs.shifts[rows], int(descs.meta["frame_width"]))
    x, y = case.poses.at(descs.stamps[rows])
    assert turned.shape == (rows.size,) and np.all(np.diff(turned) >= 0)
    assert turned[-1] >= 300.0
    dead_end = int(np.argmax(y))
    assert turned[dead_end + 8] - turned[dead_end - 8] >= 150.0   # the U-turn
    straight = int(np.flatnonzero(x >= 25.0)[0])                   # 25 m along the way out
    assert turned[straight] < 90.0


def test_a_street_that_looks_alike_along_its_length_is_not_a_loop(monkeypatch):
    """Seed 182's crossing street matches itself 24 m further on the same pass, with
    sequence support and no rotation: the robot drove straight in between, so it never
    came back."""
    import engine.loops_verified as lv

    case = describe_case(Case("crossing", "outdoor", seed=182, people=3, noise=0.01), shifts=(True,),
                         input_height=128)
    descs = case.by_shift[True]
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == ev.events_total == 1
    monkeypatch.setattr(lv, "MIN_TURN_SAME_WAY", 0.0)
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 1


def test_a_sequence_loop_is_placed_on_the_diagonal_of_the_same_place(monkeypatch):
    """Seed 202's return after the U-turn has sequence support on two parallel diagonals; its
    strongest pair is one node off (1.3 m). Outdoors, local alignment over the stretch finds
    the diagonal whose views are least displaced, as for long runs."""
    import engine.loops_verified as lv

    case = describe_case(Case("reverse", "outdoor", seed=202, people=3, noise=0.01), shifts=(True,),
                         input_height=128)
    descs = case.by_shift[True]
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == ev.events_total == 1
    monkeypatch.setattr(lv, "_PARALLEL_AXIS", -1.0)   # no sequence loop is moved
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 1


def test_a_place_passed_a_third_time_is_joined_to_the_first_pass(monkeypatch):
    """Seed 31's loop route starts a third lap: loops join laps 1-2 and 2-3, and with them
    the start of lap 3 is also joined to lap 1, where its own evidence alone is moderate."""
    import engine.loops_verified as lv

    case = describe_case(Case("loop", "indoor", seed=31), shifts=(True,), input_height=128)
    descs = case.by_shift[True]
    topomap = build_map(descs, MapParams(method="verified-rules"))
    ev = evaluate(topomap, case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == ev.events_total == 2
    index = topomap.graph.nodes
    lags = [index[v]["index"] - index[u]["index"] for u, v, _ in topomap.loops()]
    assert max(lags) > 1.5 * np.median(lags)   # a loop across two laps
    monkeypatch.setattr(lv, "_visits_again", lambda *args: [])
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == 1


def test_pairs_on_the_diagonal_line_through_a_crossing_are_not_loops(monkeypatch):
    """Seed 244's 4-way crossing looks alike from every side: a pair 5 nodes along the mirror
    diagonal through the crossing (6 m away) has sequence support and yaw 180. Next to a
    stronger crossing loop on its line it is not a place."""
    import engine.loops_verified as lv

    case = describe_case(Case("crossing", "outdoor", seed=244, people=4, lighting_drift=0.3, noise=0.01),
                         shifts=(True,), input_height=128)
    descs = case.by_shift[True]
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == ev.events_total == 1
    monkeypatch.setattr(lv, "_CROSSING_AXIS", 90.0)   # no loop counts as a crossing
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 1


def test_one_u_turn_is_not_enough_to_pass_a_place_the_same_way_again(monkeypatch):
    """Seed 250's offset route has a lone pair just before and after its U-turn whose views
    face the same way (3.1 m apart): one U-turn (about 200 degrees measured) is not the
    full circle a same-way pass needs."""
    import engine.loops_verified as lv

    case = describe_case(Case("offset", "outdoor", seed=250), shifts=(True,), input_height=128)
    descs = case.by_shift[True]
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 0 and ev.events_found == ev.events_total == 1
    monkeypatch.setattr(lv, "MIN_TURN_SAME_WAY", 180.0)   # half a circle, as before
    ev = evaluate(build_map(descs, MapParams(method="verified-rules")), case.poses, neighbor_node_num=5)
    assert ev.fp == 1
