"""The ``verified`` method end to end on synthetic recordings, its yaw, fallback and defaults."""

import numpy as np
import pytest

from engine.benchmark import Case, describe_case
from engine.cli import build_parser
from engine.descriptors.base import Descriptors
from engine.evaluate import evaluate
from engine.graph import TopoMap
from engine.loops import detect_loops
from engine.nodes import make_nodes
from engine.params import METHODS, MapParams
from engine.pipeline import build_map


@pytest.fixture(scope="module", params=[("crossing", "outdoor"), ("reverse", "indoor")], ids=lambda p: "-".join(p))
def described(request):
    route, look = request.param
    return describe_case(Case(route, look, seed=0, people=2), shifts=(True,), input_height=128)


def heading_change_deg(topomap: TopoMap, poses, i: int, j: int) -> float:
    yaw = np.degrees(np.interp(topomap.stamps(), poses.t, poses.yaw))
    return float((yaw[j] - yaw[i] + 180.0) % 360.0 - 180.0)


def test_default_method_is_verified_and_ours_stays_selectable():
    assert MapParams().method == "verified"
    assert {"simple", "shift-simple", "ours", "verified"} <= set(METHODS)
    args = build_parser().parse_args(["map", "x.mp4", "-o", "y.graphml"])
    assert args.method == MapParams().method
    assert build_parser().parse_args(["map", "x.mp4", "-o", "y.graphml", "--method", "ours"]).method == "ours"


def test_verified_closes_the_revisit_without_false_loops(described):
    """No wrong loop in the exported map, and every revisit is closed automatically or is
    among the first few loops of the review queue (the most confident candidates)."""
    descs = described.by_shift[True]
    topomap = build_map(descs, MapParams())
    ev = evaluate(topomap, described.poses, neighbor_node_num=5)
    assert topomap.meta["method"] == "verified"
    assert ev.fp == 0
    queue = sorted(((d["confidence"], u, v) for u, v, d in topomap.loops() if d.get("status") == "candidate"),
                   reverse=True)
    for _, u, v in queue[5:]:
        topomap.graph.edges[u, v]["status"] = "rejected"     # a person looked at the first five only
    seen = evaluate(topomap, described.poses, neighbor_node_num=5, include_candidates=True)
    assert seen.events_total >= 1 and seen.events_found == seen.events_total


def test_loop_arcs_carry_the_true_relative_heading(described, tmp_path):
    topomap = build_map(described.by_shift[True], MapParams())
    loops = topomap.loops()
    assert loops
    for u, v, attrs in loops:
        i, j = topomap.graph.nodes[u]["index"], topomap.graph.nodes[v]["index"]
        err = (attrs["yaw"] - heading_change_deg(topomap, described.poses, i, j) + 180.0) % 360.0 - 180.0
        assert abs(err) < 15.0
    topomap.write_graphml(tmp_path / "m.graphml")
    back = TopoMap.read_graphml(tmp_path / "m.graphml")
    assert all(isinstance(d["yaw"], float) for _, _, d in back.loops())


def test_without_column_signatures_it_falls_back_without_yaw(described):
    d = described.by_shift[True]
    old = Descriptors(d.stamps, d.frames, d.shifts, d.vectors, dict(d.meta))   # no columns
    topomap = build_map(old, MapParams())
    assert all("yaw" not in attrs for _, _, attrs in topomap.loops())
    ev = evaluate(topomap, described.poses, neighbor_node_num=5)
    assert ev.fp == 0


def test_ours_is_unchanged_by_the_new_default(described):
    d = described.by_shift[True]
    p = MapParams(method="ours", node_sim_th=0.75, loop_sim_th=0.5)
    topomap = build_map(d, p)
    rows = make_nodes(d.vectors, 0.75)
    direct = detect_loops(d.vectors[rows], p)
    got = sorted((topomap.graph.nodes[u]["index"], topomap.graph.nodes[v]["index"]) for u, v, _ in topomap.loops())
    assert got == sorted((lc.a, lc.b) for lc in direct)


def test_demo_route_crossing_and_u_turn_both_closed():
    """The demo drives through a crossing, later back over it at 90 degrees, then turns on
    the spot and drives back: both places get a loop (verified-rules) or are shown for review
    (verified's automatic loops and candidates), and nothing else gets an automatic loop."""
    from engine.benchmark import evaluate_route

    rules, new = evaluate_route("demo", "indoor", seed=0, methods=("verified-rules", "verified"), people=2)
    assert rules.fp == 0
    assert rules.events_total == 2 and rules.events_found == 2
    # The two-tier method: no wrong automatic loop, and both places are in what a person
    # reviewing the queue is shown (automatic loops and candidates).
    assert new.fp == 0
    assert new.events_with_candidates == 2


def test_scoring_only_what_a_rule_could_accept_keeps_the_same_loops(described):
    from engine.calibrate import node_threshold
    from engine.loops_verified import DEFAULT_THRESHOLDS, score_pairs, select

    d = described.by_shift[True]
    rows = make_nodes(d.vectors, node_threshold(d.vectors))
    full = score_pairs(d.vectors[rows], d.columns[rows], 5)
    lean = score_pairs(d.vectors[rows], d.columns[rows], 5, only_for=DEFAULT_THRESHOLDS)
    assert lean.a.size < full.a.size            # the filter drops pairs before alignment ...
    pick_full, pick_lean = select(full), select(lean)
    assert pick_full.size > 0                   # ... and the accepted loops stay the same
    assert set(zip(full.a[pick_full], full.b[pick_full])) == set(zip(lean.a[pick_lean], lean.b[pick_lean]))
    np.testing.assert_allclose(full.verify[pick_full], lean.verify[pick_lean], rtol=1e-5)


def test_a_lone_pair_far_above_the_recordings_own_tail_needs_no_verification():
    """People walking through a crossing spoil the column alignment: a pair whose z-score
    stands far above the recording's best unrelated matches is accepted without it."""
    from engine.loops_verified import DEFAULT_THRESHOLDS as th
    from engine.loops_verified import PairScores, select

    a, b = np.array([10, 40]), np.array([80, 45])      # the second pair: 5 nodes apart

    def scores(z_tail, z=7.0):
        return PairScores(a, b, np.full(2, z, np.float32), np.full(2, -np.inf, np.float32),
                          np.full(2, -1.0, np.float32), np.zeros(2, np.int64), np.zeros(2, np.float32),
                          100, 20, z_tail)

    assert list(select(scores(z_tail=7.0 / th.lone_tail_ratio - 0.2))) == [0]
    assert list(select(scores(z_tail=7.0 / th.lone_tail_ratio + 0.2))) == []   # not far enough above
    assert list(select(scores(z_tail=1.0, z=th.lone_z - 0.1))) == []     # below lone_z


def test_a_verified_single_pair_must_also_stand_above_the_recordings_tail():
    """A dead end looks like every other dead end of a building: a lone pair with a good
    alignment is a loop only when its z-score is above the recording's 99.9th percentile."""
    from engine.loops_verified import DEFAULT_THRESHOLDS as th
    from engine.loops_verified import PairScores, select

    a, b = np.array([10]), np.array([80])
    z = th.single_z + 0.3   # above single_z, below lone_z * ... (no lone rule)

    def scores(z_tail):
        return PairScores(a, b, np.full(1, z, np.float32), np.full(1, -np.inf, np.float32),
                          np.full(1, th.single_verify_z + 0.5, np.float32), np.zeros(1, np.int64),
                          np.zeros(1, np.float32), 100, 20, z_tail)

    assert z < th.lone_tail_ratio * (z - 1.0)          # the lone rule does not apply below
    assert list(select(scores(z_tail=z - 1.0))) == [0]
    assert list(select(scores(z_tail=z + 1.0))) == []


def test_sequence_support_from_fewer_pairs_counts_for_less():
    """At the recording's ends a diagonal has fewer pairs: their mean is scaled by
    sqrt(pairs / full run), so three good pairs do not pass for five."""
    from engine.loops_verified import SEQ_HALF, _sequence_scores

    m = 30
    z = np.zeros((m, m), np.float32)
    k = np.arange(-SEQ_HALF, SEQ_HALF + 1)
    z[10 + k, 20 + k] = 4.0                    # a whole forward run of 5 pairs
    z[0 + k[SEQ_HALF:], 29 - k[SEQ_HALF:]] = 4.0   # a backward run cut by the matrix corner: 3 pairs
    seq = _sequence_scores(z, np.array([10, 0]), np.array([20, 29]), SEQ_HALF)
    assert seq[0] == pytest.approx(4.0)
    assert seq[1] == pytest.approx(4.0 * np.sqrt((SEQ_HALF + 1) / (2 * SEQ_HALF + 1)))


def test_pairs_on_one_diagonal_line_with_overlapping_windows_keep_one_loop():
    """Sequence support of pairs 4 nodes apart on one diagonal line is the same evidence
    counted twice (a crossing's look-alike approaches): only the stronger pair stays; a
    pair on another line, or further along, stays too."""
    from engine.loops_verified import DEFAULT_THRESHOLDS as th
    from engine.loops_verified import PairScores, select

    a = np.array([20, 24, 24, 40])
    b = np.array([116, 120, 128, 136])    # 20/24 on the line b - a = 96; (24, 128) not; 40 is 16 on
    seq = np.array([4.0, 4.5, 4.0, 4.0], np.float32)
    ps = PairScores(a, b, np.full(4, 4.0, np.float32), seq, np.full(4, 2.5, np.float32),
                    np.zeros(4, np.int64), np.zeros(4, np.float32), 200, 20, 10.0)
    assert th.seq_z <= 4.0 and 4.0 + 2.5 >= th.seq_sum_z
    assert sorted(zip(ps.a[select(ps)].tolist(), ps.b[select(ps)].tolist())) == [(24, 120), (24, 128), (40, 136)]
