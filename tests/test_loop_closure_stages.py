"""Stages 4-9 of the verified method on plain arrays (engine.loop_closure)."""

import numpy as np

from engine.loop_closure import GEOMETRY_MARGIN_Z, Matches, closed_places, consistency, one_per_place, tiers
from engine.params import MapParams
from tests.sphere_views import fitted

P = MapParams()


def matches(a, b, score, inliers=None, ratio=None, support=None, yaw=None, confidence=None, path=None, step=None):
    n = len(a)
    arr = lambda v, default, dt=np.float64: np.asarray(v if v is not None else [default] * n, dt)  # noqa: E731
    return Matches(a=np.asarray(a, np.int64), b=np.asarray(b, np.int64), cosine=arr(None, 0.5, np.float32),
                   score=arr(score, 0.0), support=arr(support, 0.0), direction=np.ones(n, np.int64),
                   matches=arr(inliers, -1, np.int64) * 2, inliers=arr(inliers, -1, np.int64),
                   inlier_ratio=arr(ratio, np.nan), yaw=arr(yaw, np.nan), path_inliers=arr(path, -1, np.int64),
                   step_inliers=arr(step, -1, np.int64), confidence=arr(confidence if confidence is not None else score, 0.0))


def test_one_loop_per_place_keeps_the_most_confident_of_a_cluster_and_separate_places():
    c = matches(a=[10, 11, 12, 50], b=[80, 81, 82, 120], score=[4, 6, 5, 4])
    keep = one_per_place(c, radius=4)
    assert keep.tolist() == [False, True, False, True]


def test_a_candidate_beside_an_automatic_loop_leaves_the_queue_and_one_at_another_place_stays():
    # Stage 7b moved the loop of the place at (40, 120) two nodes along; the candidate it left
    # beside it asks about a place the map has closed. The candidates at (40, 122 + radius + 1)
    # (further along the other pass) and (90, 170) are other places.
    r = P.place_radius
    c = matches(a=[42, 40, 40, 90], b=[122, 120, 122 + r + 1, 170], score=[4.0] * 4)
    status = np.array(["auto", "candidate", "candidate", "candidate"])
    assert closed_places(c, status, P).tolist() == ["auto", "", "candidate", "candidate"]
    # without an automatic loop there is nothing closed
    status = np.array(["candidate"] * 4)
    assert closed_places(c, status, P).tolist() == ["candidate"] * 4


def test_strong_geometry_makes_an_automatic_loop_and_weak_evidence_a_candidate():
    c = matches(a=[0, 0, 0, 0], b=[20, 40, 60, 80],
                score=[P.candidate_z + 0.5, P.candidate_z + 0.5, P.candidate_z - 0.5, 1.0],
                inliers=[P.auto_inliers * 2, 5, 5, 2], ratio=[0.6, 0.1, 0.1, 0.05],
                confidence=[P.candidate_confidence + 10, P.candidate_confidence, 20, 20])
    assert tiers(c, P).tolist() == ["auto", "candidate", "", ""]


def test_two_views_sharing_less_than_one_node_step_are_not_an_automatic_loop():
    # Views a couple of metres apart share many inliers, but fewer than each end shares with
    # its next node along its own path: the same scene, not the same place.
    strong = P.auto_inliers * 3
    c = matches(a=[0, 30], b=[60, 90], score=[P.candidate_z + 1] * 2, inliers=[strong, strong],
                ratio=[0.8, 0.8], step=[strong - 1, int(strong / P.auto_step_share) + 20],
                confidence=[P.candidate_confidence + 10] * 2)
    assert tiers(c, P).tolist() == ["auto", "candidate"]


def test_views_measured_closer_than_one_node_step_are_one_place_though_they_share_less():
    # A revisit half a step away, in other light and with other people about, can share
    # fewer inliers than a step made a second apart; its measured distance says one place.
    strong = P.auto_inliers * 3
    step = int(strong / (P.auto_measured_share + 0.5 * (1 - P.auto_measured_share)))   # shares less than a step
    c = matches(a=[0, 30, 60], b=[100, 130, 160], score=[P.auto_geometry_z] * 3, inliers=[strong] * 3,
                ratio=[0.8] * 3, step=[step] * 3, confidence=[P.candidate_confidence + 10] * 3)
    c.distance_steps = np.array([0.5 * P.auto_distance_steps, 1.5 * P.auto_distance_steps, np.nan])
    assert tiers(c, P).tolist() == ["auto", "candidate", "candidate"]


def test_views_measured_close_that_share_little_of_a_step_were_fitted_to_a_repeated_texture():
    # Two corridor views metres apart, fitted to a texture they both see, measure a fraction
    # of a step apart but share a third of what a step shares: not one place, whatever the score.
    strong = P.auto_inliers * 2
    c = matches(a=[0, 30], b=[100, 130], score=[P.auto_geometry_z + 2, P.auto_geometry_z + 2], inliers=[strong] * 2,
                ratio=[0.8] * 2, step=[strong * 3, strong], confidence=[P.candidate_confidence + 10] * 2)
    c.distance_steps = np.array([0.3, 0.3])
    assert tiers(c, P).tolist() == ["candidate", "auto"]


def test_views_measured_within_a_step_need_only_the_queues_score():
    # Strong geometry at a score between candidate_z and auto_geometry_z: automatic where the
    # two views measure within a step (sharing what a near view does), left to a person where
    # only the inliers vouch for it.
    strong = P.auto_inliers * 3
    z = (P.candidate_z + P.auto_geometry_z) / 2
    near_view = int(strong / (P.auto_measured_share + 0.5 * (1 - P.auto_measured_share)))   # less than a step
    c = matches(a=[0, 30, 60], b=[100, 130, 160], score=[z, z, P.candidate_z - 0.1], inliers=[strong] * 3,
                ratio=[0.8] * 3, step=[near_view, strong - 1, near_view], confidence=[P.candidate_confidence + 10] * 3)
    c.distance_steps = np.array([0.5 * P.auto_distance_steps, np.nan, 0.5 * P.auto_distance_steps])
    assert tiers(c, P).tolist() == ["auto", "candidate", ""]


def test_views_that_measure_within_a_step_and_share_a_full_step_need_only_the_geometry_floor():
    # A junction's other arm seen from a quarter step away: a low score, but the count and the
    # measured distance both say one place. Either reading alone, or a score below the floor
    # at which geometry is looked at, is not enough.
    strong = P.auto_inliers * 3
    low = P.candidate_z - GEOMETRY_MARGIN_Z / 2
    close = 0.3 * P.auto_distance_steps
    c = matches(a=[0, 30, 60, 90], b=[200, 230, 260, 290],
                score=[low, low, low, P.candidate_z - GEOMETRY_MARGIN_Z - 0.1], inliers=[strong] * 4, ratio=[0.8] * 4,
                step=[strong // 2, int(strong / (P.auto_measured_share + 0.1)), strong // 2, strong // 2],
                confidence=[P.candidate_confidence + 10] * 4)
    c.distance_steps = np.array([close, close, np.nan, close])
    assert tiers(c, P).tolist() == ["auto", "", "", ""]


def test_a_tight_turns_return_measured_within_a_step_needs_only_the_geometry_floor():
    # A robot turns round and passes within a step of where it was seven nodes before: the
    # two views face opposite ways and score low, but every node between them is a temporal
    # neighbour of one end, so no look-alike place can lie between them. The same evidence
    # across a long stretch of path, a tight turn measured further than a step, or a score
    # under the floor at which geometry is looked at, is not enough.
    strong = P.auto_inliers * 3
    low = P.candidate_z - GEOMETRY_MARGIN_Z / 2
    tight = 2 * P.neighbor_node_num + 1
    c = matches(a=[40, 100, 200, 300], b=[40 + tight, 200, 200 + tight, 300 + tight],
                score=[low, low, low, P.candidate_z - GEOMETRY_MARGIN_Z - 0.1], inliers=[strong] * 4,
                ratio=[0.8] * 4, step=[int(strong / (P.auto_measured_share + 0.1))] * 4,
                confidence=[P.candidate_confidence + 10] * 4)
    c.distance_steps = np.array([0.9, 0.9, 1.5, 0.9]) * P.auto_distance_steps
    assert tiers(c, P).tolist() == ["auto", "", "", ""]


def test_views_measured_further_apart_than_a_step_are_not_one_place_however_much_they_share():
    # An offset return 1.4 m to the side can share as many inliers as a step; where the
    # distance is measured, it decides.
    strong = P.auto_inliers * 3
    c = matches(a=[0, 30, 60], b=[100, 130, 160], score=[P.candidate_z + 1] * 3, inliers=[strong] * 3,
                ratio=[0.8] * 3, step=[strong - 1] * 3, confidence=[P.candidate_confidence + 10] * 3)
    c.distance_steps = np.array([0.5 * P.auto_distance_steps, 1.8 * P.auto_distance_steps, np.nan])
    assert tiers(c, P).tolist() == ["auto", "candidate", "auto"]


def test_views_whose_inliers_lie_on_one_plane_are_left_to_a_person():
    # A flat picture copied elsewhere (a poster, a repeated wall texture) fits two views as
    # well as a revisit does; the revisit sees things at several depths.
    strong = P.auto_inliers * 3
    c = matches(a=[0, 30, 60], b=[100, 130, 160], score=[P.candidate_z + 1] * 3, inliers=[strong] * 3,
                ratio=[0.8] * 3, step=[strong // 2] * 3, confidence=[P.candidate_confidence + 10] * 3)
    c.plane_share = np.array([0.3, min(1.0, P.auto_plane_share + 0.2), np.nan])   # NaN: a pure rotation
    assert tiers(c, P).tolist() == ["auto", "candidate", "auto"]


def test_without_geometry_only_score_and_support_together_make_an_automatic_loop():
    c = matches(a=[0, 0, 0], b=[20, 40, 60], score=[P.auto_z + 1, P.auto_z + 1, P.candidate_z + 0.1],
                support=[P.auto_support + 1, 0.0, P.auto_support + 1], confidence=[20, 20, 20])
    assert tiers(c, P).tolist() == ["auto", "candidate", "candidate"]


def test_a_loop_whose_heading_does_not_close_the_cycle_goes_back_to_the_candidates():
    # The robot drives straight (headings 0) and returns on the same stretch the other way:
    # true loops there have yaw 180. One loop claims yaw 90: it cannot be the same place
    # seen with the heading the path says.
    headings = np.zeros(200)
    headings[100:] = 180.0
    c = matches(a=[10, 14, 18, 22], b=[190, 186, 182, 178], score=[8, 7, 6, 9],
                yaw=[180.0, 181.0, 178.0, 90.0], confidence=[8, 7, 6, 5])
    status = np.array(["auto"] * 4, dtype=object)
    out = consistency(c, status, headings, P)
    assert out.tolist() == ["auto", "auto", "auto", "candidate"]


def test_consistent_loops_far_apart_along_the_path_are_not_judged_against_each_other():
    headings = np.linspace(0, 3000, 5000)     # lots of turning, lots of drift between them
    c = matches(a=[10, 4000], b=[2000, 4900], score=[8, 7], yaw=[33.0, -120.0])
    status = np.array(["auto", "auto"], dtype=object)
    assert consistency(c, status, headings, P).tolist() == ["auto", "auto"]


def test_the_consistent_majority_wins_over_one_more_confident_outlier():
    headings = np.zeros(200)
    headings[100:] = 180.0
    c = matches(a=[10, 14, 18, 22], b=[190, 186, 182, 178], score=[5, 5, 5, 9],
                yaw=[180.0, 181.0, 178.0, 90.0], confidence=[5, 5, 5, 9])
    status = np.array(["auto"] * 4, dtype=object)
    assert consistency(c, status, headings, P).tolist() == ["auto", "auto", "auto", "candidate"]


def test_a_high_score_that_nothing_else_agrees_with_is_not_even_a_candidate():
    # The best of thousands of unrelated matches is a few standard deviations up by chance.
    c = matches(a=[0, 0], b=[20, 40], score=[P.candidate_z + 1] * 2, support=[0.0, 4.0],
                confidence=[P.candidate_z + 1, P.candidate_z + 5])
    assert tiers(c, P).tolist() == ["", "candidate"]


def test_a_loop_whose_path_runs_away_goes_back_to_the_candidates_and_one_that_returns_stays():
    from engine.loop_closure import closure

    def judged(track, a, b):
        c = matches(a=[a], b=[b], score=[8])
        c.closure = np.linalg.norm(track[c.b] - track[c.a], axis=1)
        return closure(c, np.array(["auto"], dtype=object), P).tolist()

    # Out 60 steps east and back: node 120 is where node 0 was.
    out_and_back = np.stack([60.0 - np.abs(60.0 - np.arange(121.0)), np.zeros(121)], axis=1)
    assert judged(out_and_back, 0, 120) == ["auto"]
    # One straight street: nodes 20 and 180 are 160 steps apart by the path's own account,
    # two places that look alike, whatever the views say.
    street = np.stack([np.arange(200.0), np.zeros(200)], axis=1)
    assert judged(street, 20, 180) == ["candidate"]


def test_a_candidate_whose_path_runs_away_is_not_put_to_a_person_and_one_that_returns_is():
    from engine.loop_closure import closure

    street = np.stack([np.arange(200.0), np.zeros(200)], axis=1)          # straight out
    out_and_back = np.stack([60.0 - np.abs(60.0 - np.arange(121.0)), np.zeros(121)], axis=1)
    for track, (a, b), kept in ((street, (20, 180), []), (out_and_back, (0, 120), ["candidate"])):
        c = matches(a=[a], b=[b], score=[P.candidate_z])
        c.closure = np.linalg.norm(track[c.b] - track[c.a], axis=1)
        assert [s for s in closure(c, np.array(["candidate"], dtype=object), P).tolist() if s] == kept
    # Where the path is unknown (no geometry), nothing is dropped.
    c = matches(a=[20], b=[180], score=[P.candidate_z])
    c.closure = np.array([np.nan])
    assert closure(c, np.array(["candidate"], dtype=object), P).tolist() == ["candidate"]


def _out_and_back(steps_out: int) -> np.ndarray:
    """Dead-reckoned track of a drive ``steps_out`` node steps east and straight back."""
    i = np.arange(2 * steps_out + 1.0)
    return np.stack([steps_out - np.abs(steps_out - i), np.zeros(i.size)], axis=1)


def test_a_node_joined_to_two_places_apart_on_the_other_pass_sends_both_loops_to_the_queue():
    from engine.loop_closure import lengths

    track = _out_and_back(100)      # node i and node 200 - i are one place
    # Three true loops along the return, and node 14 joined once more, to node 176: ten steps
    # away from node 186 on the same pass, so 14 cannot be both places. Which is wrong the path
    # cannot say, and confidence is no judge: the wrong loop is once less, once more confident.
    # The other true loops lie far enough along the path for its drift to explain ten steps.
    for conf_true, conf_wrong in ((8, 5), (8, 12)):
        c = matches(a=[40, 14, 60, 14], b=[160, 186, 140, 176], score=[8, conf_true, 8, conf_wrong],
                    confidence=[8, conf_true, 8, conf_wrong])
        status = np.array(["auto"] * 4, dtype=object)
        assert lengths(c, status, track, P).tolist() == ["auto", "candidate", "auto", "candidate"]
    # Without a track (no geometry) nothing is judged.
    assert lengths(c, status, None, P).tolist() == ["auto"] * 4


def test_a_place_passed_on_three_laps_keeps_both_of_its_loops():
    from engine.loop_closure import lengths

    # A square block, ten steps a side (40 steps a lap), driven three times.
    side = np.repeat(np.array([[1, 0], [0, 1], [-1, 0], [0, -1]], float), 10, axis=0)
    track = np.concatenate([[[0.0, 0.0]], np.cumsum(np.tile(side, (3, 1)), axis=0)])
    c = matches(a=[5, 5, 45, 22], b=[45, 85, 85, 62], score=[8, 7, 6, 6], confidence=[8, 7, 6, 6])
    status = np.array(["auto"] * 4, dtype=object)
    assert lengths(c, status, track, P).tolist() == ["auto"] * 4


def _out_and_back_headings(wrong_step=None) -> np.ndarray:
    """Headings of a drive 100 steps out and back (a half turn on the spot at step 100), as
    the path's geometry reads them: with a straight step read as a half turn at ``wrong_step``."""
    headings = np.zeros(201)
    headings[101:] = 180.0
    if wrong_step is not None:
        headings[wrong_step + 1:] += 180.0
    return headings


def test_a_straight_step_read_as_a_half_turn_is_overruled_by_the_loops_on_both_sides_of_it():
    from engine.loop_closure import half_turns

    # Node i and node 200 - i are one place; the return sees it turned by 180 degrees.
    c = matches(a=[10, 14, 20, 40, 50, 60], b=[190, 186, 180, 160, 150, 140], score=[8] * 6, yaw=[180.0] * 6)
    status = np.array(["auto"] * 6, dtype=object)
    read = _out_and_back_headings(wrong_step=30)
    assert consistency(c, status, read, P).tolist().count("candidate") >= 2     # the groups disagree
    headings, overruled = half_turns(c, status, read, P)
    assert overruled.tolist() == [30]                     # not the real turn on the spot at 100
    assert np.allclose(np.mod(headings - _out_and_back_headings(), 360.0), 0.0)
    assert consistency(c, status, headings, P).tolist() == ["auto"] * 6


def test_one_loop_cannot_turn_the_path_to_fit_itself():
    from engine.loop_closure import half_turns

    # One loop over the half-turn step, three beside it: one voice against one step.
    c = matches(a=[10, 40, 50, 60], b=[190, 160, 150, 140], score=[9, 8, 8, 8], yaw=[180.0] * 4)
    status = np.array(["auto"] * 4, dtype=object)
    read = _out_and_back_headings(wrong_step=30)
    headings, overruled = half_turns(c, status, read, P)
    assert overruled.size == 0 and np.array_equal(headings, read)


def test_a_path_without_a_half_turn_step_is_left_as_read():
    from engine.loop_closure import half_turns

    read = np.linspace(0.0, 90.0, 201)                   # a gentle curve, no step near 180 degrees
    c = matches(a=[10, 14, 40, 50], b=[190, 186, 160, 150], score=[8] * 4, yaw=[0.0, 0.0, 180.0, 180.0])
    status = np.array(["auto"] * 4, dtype=object)
    headings, overruled = half_turns(c, status, read, P)
    assert overruled.size == 0 and np.array_equal(headings, read)
    assert half_turns(c, status, None, P)[0] is None      # no geometry, no headings


def _straight_track(n: int) -> np.ndarray:
    return np.stack([np.arange(n + 1.0), np.zeros(n + 1)], axis=1)


def test_a_lone_loop_that_closes_only_through_a_doubtful_half_turn_goes_to_the_queue():
    from engine.loop_closure import lone_turns

    # A straight corridor of 200 steps whose step 100 was read as a half turn: dead reckoning
    # folds the path back, so nodes 60 and 140 (look-alike views 80 steps apart) seem to meet.
    folded = _out_and_back(100)
    c = matches(a=[60], b=[140], score=[8])
    c.closure = np.linalg.norm(folded[c.b] - folded[c.a], axis=1)
    status = np.array(["auto"], dtype=object)
    assert lone_turns(c, status, {100: _straight_track(200)}, P).tolist() == ["candidate"]
    # Without a half turn read (or without geometry) nothing is judged.
    assert lone_turns(c, status, {}, P).tolist() == ["auto"]


def test_a_real_u_turn_needed_by_the_loops_of_the_return_keeps_them_all():
    from engine.loop_closure import lone_turns

    # A reverse drive: out 100 steps, a half turn on the spot, back. Every loop of the return
    # closes through the turn and none without it: they confirm the turn together.
    track = _out_and_back(100)
    c = matches(a=[20, 50, 80], b=[180, 150, 120], score=[8] * 3)
    c.closure = np.linalg.norm(track[c.b] - track[c.a], axis=1)
    status = np.array(["auto"] * 3, dtype=object)
    assert lone_turns(c, status, {100: _straight_track(200)}, P).tolist() == ["auto"] * 3
    # A loop whose path does not run over the turn is not judged by it.
    c = matches(a=[10], b=[40], score=[8])
    c.closure = np.array([0.5])
    assert lone_turns(c, np.array(["auto"], dtype=object), {100: _straight_track(200)}, P).tolist() == ["auto"]


def test_a_loop_as_long_as_the_temporal_window_is_not_its_own_reference_of_the_path():
    # Node 6 comes back to node 0's spot (a tight turn); every other node sees a scene of
    # its own. The path's reference for the loop (what an end shares with the node just
    # outside the temporal window) must be a node other than the loop's other end: the
    # geometry beyond the path's own is the whole loop here, not nothing.
    from engine.features import FeatureTable, LocalFeatures
    from engine.loop_closure import geometry
    from engine.sphere import bearings, to_uv

    rng = np.random.default_rng(0)

    def view(scene, desc, at):
        return LocalFeatures((to_uv(scene - at) % 1).astype(np.float32), desc)

    def scene():
        points = bearings(np.stack([rng.random(200), rng.uniform(0.1, 0.9, 200)], 1)) * rng.uniform(2, 8, (200, 1))
        return points, rng.integers(0, 256, (200, 128)).astype(np.uint8)

    place = scene()
    views = [view(*scene(), np.zeros(3)) for _ in range(13)]
    views[0], views[6] = view(*place, np.zeros(3)), view(*place, np.array([0.3, 0.1, 0.0]))
    geo = geometry(FeatureTable.from_list(views), np.arange(13), np.array([0]), np.array([6]), gap=6, cache={})
    assert geo["inliers"][0] > 100
    assert geo["path_inliers"][0] < geo["inliers"][0] / 4


def _track_of(headings: np.ndarray) -> np.ndarray:
    """Dead reckoning of one unit step per node in the direction of the node's heading."""
    rad = np.radians(headings[:-1])
    steps = np.stack([np.cos(rad), np.sin(rad)], axis=1)
    return np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])


def _block_read_with_half_turns(*steps: int) -> np.ndarray:
    """Headings of a square block, ten steps a side, driven round twice (80 steps), with each
    of the straight ``steps`` read as a half turn."""
    read = np.append(np.repeat(np.arange(8) * 90.0, 10), 720.0)
    for k in steps:
        read[k + 1:] += 180.0
    return read


def _second_lap_read_with_a_half_turn(loop_yaw: float):
    """The block (``_block_read_with_half_turns``); node 5 is passed again at node 45, seen
    turned by ``loop_yaw``. The geometry read the straight step 22 as a half turn. Returns
    the loop, its status, the headings as read, and {(22,): the track with step 22 read
    straight}."""
    from engine.loop_closure import read_straight

    read = _block_read_with_half_turns(22)
    c = matches(a=[5], b=[45], score=[8], yaw=[loop_yaw])
    return c, np.array(["auto"], dtype=object), read, {(22,): _track_of(read_straight(read, 22))}


def test_a_crossing_whose_path_reads_a_straight_step_as_a_half_turn_reads_it_straight():
    from engine.loop_closure import read_straight, straight_for_a_loop

    # As read, the path does not come back; with step 22 straight it does, and the loop's
    # heading agrees.
    c, status, read, straightened = _second_lap_read_with_a_half_turn(loop_yaw=0.0)
    assert np.linalg.norm(_track_of(read)[45] - _track_of(read)[5]) > 10
    assert straight_for_a_loop(c, status, read, _track_of(read), straightened, P) == (22,)
    # A candidate is no voice, and without a half turn read there is nothing to read straight.
    assert straight_for_a_loop(c, np.array(["candidate"], dtype=object), read, _track_of(read), straightened, P) is None
    assert straight_for_a_loop(c, status, read_straight(read, 22), straightened[(22,)], {}, P) is None


def test_a_loop_turned_against_the_straightened_path_cannot_straighten_it():
    from engine.loop_closure import straight_for_a_loop

    # The same place by position, but its two views turned half round against the path read
    # straight: its two voices disagree, and the step stays as read.
    c, status, read, straightened = _second_lap_read_with_a_half_turn(loop_yaw=180.0)
    assert straight_for_a_loop(c, status, read, _track_of(read), straightened, P) is None


def test_a_real_turn_on_the_spot_stays_when_loops_across_it_need_it():
    from engine.loop_closure import straight_for_a_loop

    # A reverse drive: out 100 steps, a half turn on the spot, back; three loops of the return
    # come back only through the turn. A fourth loop, a look-alike, would come back with the
    # turn read straight (a track where its ends meet): the loops that need the turn keep it.
    headings = _out_and_back_headings()
    track = _out_and_back(100)
    straight = _straight_track(200)
    straight[110] = straight[30]
    c = matches(a=[20, 50, 80, 30], b=[180, 150, 120, 110], score=[8] * 4, yaw=[180.0, 180.0, 180.0, 0.0])
    status = np.array(["auto"] * 4, dtype=object)
    assert straight_for_a_loop(c, status, headings, track, {(100,): straight}, P) is None
    # Alone, the look-alike's two voices would read the turn straight: the others are the guard.
    c1 = matches(a=[30], b=[110], score=[8], yaw=[0.0])
    assert straight_for_a_loop(c1, np.array(["auto"], dtype=object), headings, track, {(100,): straight}, P) == (100,)


def test_two_straight_steps_read_as_half_turns_are_read_straight_together_for_the_loop_across_both():
    from engine.loop_closure import read_straight, straight_for_a_loop

    # The block's second lap with two straight steps read as half turns (22 and 35): the
    # headings undo each other, but the positions between them are folded and the path does
    # not come back. Read straight alone, either step turns the loop's heading half round;
    # only both together let it come back and agree.
    read = _block_read_with_half_turns(22, 35)
    c = matches(a=[5], b=[45], score=[8], yaw=[0.0])
    status = np.array(["auto"], dtype=object)
    options = {(22,): _track_of(read_straight(read, 22)), (35,): _track_of(read_straight(read, 35))}
    assert np.linalg.norm(_track_of(read)[45] - _track_of(read)[5]) > 10
    assert straight_for_a_loop(c, status, read, _track_of(read), options, P) is None
    options[(22, 35)] = _track_of(read_straight(read, 22, 35))
    assert straight_for_a_loop(c, status, read, _track_of(read), options, P) == (22, 35)
    # A loop across only the first step that comes back as read (nodes 20 and 26, on one spot
    # through the fold, views turned half round) does not come back with both read straight:
    # it needs the turns, and they stay.
    c2 = matches(a=[5, 20], b=[45, 26], score=[8, 8], yaw=[0.0, 180.0])
    assert straight_for_a_loop(c2, np.array(["auto"] * 2, dtype=object), read, _track_of(read), options, P) is None


def test_the_distance_between_two_visits_is_measured_in_node_steps_from_both_ends():
    # A reverse drive 0.5 m to the side of the first pass, nodes 1 m apart on both: nodes 0-2
    # go out, nodes 10-12 come back. No model knows a length; the loop (1, 11) measures half
    # a step from each end's own steps.
    from engine.loop_closure import _distance_steps

    room = np.random.default_rng(7).uniform([-4, -4, -1.2], [6, 4, 1.5], (200, 3))
    at = {0: (0, 0), 1: (1, 0), 2: (2, 0), 10: (2, 0.5), 11: (1, 0.5), 12: (0, 0.5)}
    at = {n: np.array([x, y, 0.0]) for n, (x, y) in at.items()}
    cache = {"two_view": {(a, b): fitted(room, at[a], at[b])
                          for a, b in ((1, 11), (0, 1), (1, 2), (10, 11), (11, 12))}}
    d = _distance_steps(None, np.arange(13), np.array([1]), np.array([11]), cache)
    assert abs(d[0] - 0.5) < 0.02
