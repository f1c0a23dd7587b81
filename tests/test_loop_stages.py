"""Stages 3 and 5 of the verified method on plain arrays: one pair per place, tiers by the rule table."""

import numpy as np

from engine.loops.pairs import Pairs
from engine.loops.places import one_per_place
from engine.loops.tiers import AUTO_RULES
from engine.loops.tiers import tiers as _tiers
from engine.params import MapParams

P = MapParams()
GEOMETRY_MARGIN_Z = P.geometry_margin_z


def tiers(c, params):
    return _tiers(c, params)[0]


def matches(a, b, score, inliers=None, ratio=None, support=None, yaw=None, confidence=None, path=None, step=None):
    n = len(a)
    arr = lambda v, default, dt=np.float64: np.asarray(v if v is not None else [default] * n, dt)  # noqa: E731
    return Pairs(a=np.asarray(a, np.int64), b=np.asarray(b, np.int64), cosine=arr(None, 0.5, np.float32),
                   score=arr(score, 0.0), support=arr(support, 0.0), direction=np.ones(n, np.int64),
                   matches=arr(inliers, -1, np.int64) * 2, inliers=arr(inliers, -1, np.int64),
                   inlier_ratio=arr(ratio, np.nan), yaw=arr(yaw, np.nan), path_inliers=arr(path, -1, np.int64),
                   step_inliers=arr(step, -1, np.int64), plane_share=arr(None, np.nan),
                   distance_steps=arr(None, np.nan), confidence=arr(confidence if confidence is not None else score, 0.0))


def test_one_loop_per_place_keeps_the_most_confident_of_a_cluster_and_separate_places():
    c = matches(a=[10, 11, 12, 50], b=[80, 81, 82, 120], score=[4, 6, 5, 4])
    owner = one_per_place(c, radius=4)
    assert owner.tolist() == [1, 1, 1, 3]      # the set-aside pairs name the kept pair of their place


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


def test_a_revisit_in_a_bare_corridor_is_found_when_its_views_share_what_a_step_shares():
    # Indoors, on bare walls, a node step shares some 20-30 inliers: a revisit there cannot
    # show more than a step does. Sharing a step's worth it is one place; sharing half of what
    # its steps share it is the same corridor seen from elsewhere, left to a person.
    step = 24
    c = matches(a=[0, 30], b=[100, 130], score=[P.auto_geometry_z + 1] * 2, inliers=[step + 2, step + 2],
                ratio=[0.5, 0.5], step=[step, 2 * step], confidence=[P.candidate_confidence + 10] * 2)
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


def test_a_high_score_that_nothing_else_agrees_with_is_not_even_a_candidate():
    # The best of thousands of unrelated matches is a few standard deviations up by chance.
    c = matches(a=[0, 0], b=[20, 40], score=[P.candidate_z + 1] * 2, support=[0.0, 4.0],
                confidence=[P.candidate_z + 1, P.candidate_z + 5])
    assert tiers(c, P).tolist() == ["", "candidate"]


def test_every_automatic_loop_names_the_rule_that_made_it():
    strong = P.auto_inliers * 3
    c = matches(a=[0, 30], b=[100, 130], score=[P.auto_geometry_z + 1, 1.0], inliers=[strong, 2],
                ratio=[0.8, 0.1], step=[strong - 1, 50], confidence=[P.candidate_confidence + 10, 1.0])
    status, rule = _tiers(c, P)
    assert status.tolist() == ["auto", ""]
    assert rule[0] in [name for name, _needs, _score in AUTO_RULES] and rule[1] == ""


# ------------------------------------------------------------------ stage 7: the map as a measurement

class _Steps:
    """The geometry ``consistent`` asks for: a square walked twice, 10 straight steps per side."""

    def __init__(self, m):
        from engine.loops.pairs import Steps

        yaw = np.array([90.0 if (i + 1) % 10 == 0 else 0.0 for i in range(m - 1)])
        self._steps = Steps(yaw=yaw, motion=np.zeros(m - 1), still=np.zeros(m - 1, bool),
                            ambiguous=np.zeros(m - 1, bool))

    def steps(self, params):
        return self._steps


def test_a_candidate_the_solved_map_closes_becomes_automatic_and_one_it_puts_apart_does_not():
    from engine.loops.verified import consistent

    m = 81                                 # node 40 + k is node k again (two laps of 40 steps)
    # an automatic loop closes the square; candidates: the same place a lap later (44, 84 - 40),
    # and a look-alike on the opposite side (15 -> 45 is 20 nodes round: 10 steps away)
    c = matches([0, 4, 15], [40, 44, 65], score=[6.0, 3.2, 3.2], inliers=[60, 30, 30], step=[40, 40, 40],
                yaw=[0.0, 0.0, 0.0])
    status = np.array(["auto", "candidate", "candidate"], dtype=object)
    out, reason, closure, poses, rule = consistent(c, status, _Steps(m), P, m, (0,))
    assert out[1] == "auto" and rule[1] == "the map closes it"
    assert out[2] != "auto" and closure[2] > 5.0
    assert closure[1] <= P.auto_distance_steps


def test_a_pair_under_the_review_score_the_solved_map_closes_becomes_automatic():
    """Stage 5 drops a pair whose descriptors score under ``candidate_z`` (a junction seen from
    another side); the map measures it all the same: closed where the map puts its ends together,
    still dropped where the map puts them apart."""
    from engine.loops.verified import consistent

    m = 81
    low = P.candidate_z - 0.5
    c = matches([0, 4, 15], [40, 44, 65], score=[6.0, low, low], inliers=[60, 30, 30], step=[40, 40, 40],
                yaw=[0.0, 0.0, 0.0])
    status = np.array(["auto", "", ""], dtype=object)      # "": dropped (Status.DROPPED)
    out, _, closure, _, rule = consistent(c, status, _Steps(m), P, m, (0,))
    assert out[1] == "auto" and rule[1] == "the map closes it" and closure[1] <= P.auto_distance_steps
    assert out[2] == ""


def test_a_crossing_whose_views_share_half_a_step_is_closed_by_the_map():
    """Two paths crossing at one spot see the place from two sides: the views share about half
    of what a step along either path shares, and cannot measure their distance. Where the map
    puts the ends together, that is enough."""
    from engine.loops.verified import consistent

    m = 81
    c = matches([0, 4], [40, 44], score=[6.0, 3.2], inliers=[60, 20], step=[40, 40], yaw=[0.0, 0.0])
    status = np.array(["auto", "candidate"], dtype=object)
    out, _, closure, _, rule = consistent(c, status, _Steps(m), P, m, (0,))
    assert out[1] == "auto" and rule[1] == "the map closes it" and closure[1] <= P.auto_distance_steps


def test_the_map_keeps_a_loop_where_the_two_views_measured_it():
    """A return driven a step beside the first pass: the automatic loop's views measured b one
    step to the left of a. The map keeps the second lap a step beside the first, so a pair
    further along the two laps is a step apart in it, not on top of each other (a loop factor
    of no translation would pull the laps onto one line)."""
    from engine.loops.verified import consistent

    m = 81
    # the second pair shares too little to be closed itself: only the map's reading of it is asked
    c = matches([0, 4], [40, 44], score=[6.0, 3.2], inliers=[60, 5], step=[40, 40], yaw=[0.0, 0.0])
    c.distance_steps = np.array([1.0, np.nan])
    c.bearing = np.array([90.0, np.nan])
    status = np.array(["auto", ""], dtype=object)
    beside = consistent(c, status, _Steps(m), P, m, (0,))[2][1]
    c.distance_steps[0] = np.nan                       # the same loop, its distance unmeasured
    on_top = consistent(c, status, _Steps(m), P, m, (0,))[2][1]
    assert on_top < 0.3 and 0.7 < beside < 1.3


def test_the_map_does_not_close_a_candidate_whose_views_share_too_little():
    from engine.loops.verified import consistent

    m = 81
    c = matches([0, 4], [40, 44], score=[6.0, 3.2], inliers=[60, 5], step=[40, 40], yaw=[0.0, 0.0])
    status = np.array(["auto", "candidate"], dtype=object)
    out, _, _, _, rule = consistent(c, status, _Steps(m), P, m, (0,))
    assert out[1] != "auto" and rule[1] == ""


def test_two_recordings_no_loop_joins_are_not_closed_by_their_arbitrary_placement():
    from engine.loops.verified import consistent

    m = 82                                 # two recordings of 41 nodes, both start at the origin
    c = matches([2], [43], score=[3.2], inliers=[30], step=[40], yaw=[0.0])
    out, _, _, _, rule = consistent(c, np.array(["candidate"], dtype=object), _Steps(m), P, m, (0, 41))
    assert out[0] != "auto"


def test_a_distance_the_two_views_measured_outranks_the_map():
    """An offset return 1.5 steps to the side: the loops pull the map's ends together, the two
    views measured them apart; the measurement stands."""
    from engine.loops.verified import consistent

    m = 81
    c = matches([0, 4], [40, 44], score=[6.0, 3.2], inliers=[60, 30], step=[40, 40], yaw=[0.0, 0.0])
    c.distance_steps = np.array([np.nan, 1.5])
    status = np.array(["auto", "candidate"], dtype=object)
    out, _, _, _, rule = consistent(c, status, _Steps(m), P, m, (0,))
    assert out[1] != "auto" and rule[1] == ""


def test_the_map_closes_a_pair_its_views_measure_close_and_not_one_they_measure_apart():
    """Two measurements of one pair: the views' and the map's. Where both say one place the
    pair is closed, whatever its descriptor score (a place seen under another light); where the
    views measured the ends further apart than the map does, the views' own distance stands."""
    from engine.loops.verified import consistent

    m = 81
    low = P.candidate_z - 0.5
    c = matches([0, 4, 8], [40, 44, 48], score=[6.0, low, low], inliers=[60, 35, 35], step=[40, 40, 40],
                yaw=[0.0, 0.0, 0.0])
    c.distance_steps = np.array([np.nan, 0.5 * P.auto_distance_steps, 4.0 * P.auto_distance_steps])
    c.bearing = np.array([np.nan, 0.0, 0.0])
    status = np.array(["auto", "", ""], dtype=object)
    out, _, closure, _, rule = consistent(c, status, _Steps(m), P, m, (0,))
    assert closure[2] <= P.auto_distance_steps   # the map outvotes the far reading, and would close it
    assert out[1] == "auto" and rule[1] == "the map closes it"
    assert out[2] != "auto" and rule[2] == ""


class _TwoStraightDrives:
    """Two recordings (nodes 0-20 and 21-41), each 20 straight steps."""

    def steps(self, params):
        from engine.loops.pairs import Steps

        n = 41
        return Steps(yaw=np.zeros(n), motion=np.zeros(n), still=np.zeros(n, bool), ambiguous=np.zeros(n, bool))


def test_pairs_measured_apart_keep_the_map_from_joining_two_legs_beside_each_other():
    """Two drives leave one spot (an automatic loop with no turn measured) and part, the second
    turned 11 degrees: ten steps on, their views measured them two steps apart. That pair is no
    loop, but it is a measurement of the map: a pair further on, whose views share a step's
    points but could not measure their distance, is three steps apart, and the map must not
    close it as one place."""
    from engine.loops.verified import consistent

    m, starts = 42, (0, 21)
    turn = np.radians(11.3)
    ahead = lambda k: k * np.array([np.cos(turn), np.sin(turn)]) - np.array([k, 0.0])   # noqa: E731
    c = matches([0, 10, 15], [21, 31, 36], score=[6.0, 3.2, 3.2], inliers=[60, 60, 40], step=[40, 40, 40],
                yaw=[np.nan, 11.3, 11.3])
    apart = ahead(10)
    c.distance_steps = np.array([np.nan, np.hypot(*apart), np.nan])
    c.bearing = np.array([np.nan, np.degrees(np.arctan2(apart[1], apart[0])), np.nan])
    status = np.array(["auto", "", "candidate"], dtype=object)
    out, _, closure, _, rule = consistent(c, status, _TwoStraightDrives(), P, m, starts)
    assert out[0] == "auto" and out[1] != "auto"
    assert out[2] != "auto" and rule[2] == ""
    assert closure[2] > 2.0                         # the two drives are 2.9 steps apart there
