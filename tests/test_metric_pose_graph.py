"""Stage 7 with metric factors (engine/metric.py): odometry steps, GPS positions, in metres;
and without them the image-only graph exactly as it was."""

from pathlib import Path

import numpy as np
import pytest

from engine.loops.pairs import Steps
from engine.loops.pose_graph import Loops, solve, step_factors
from engine.metric import Metric
from engine.params import MapParams

REFERENCE = Path(__file__).parent / "data" / "pose_graph_image_only.npz"
SIDE = 10
NO_LOOPS = Loops(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))


def _square(laps: int = 2, noise_deg: float = 0.0, seed: int = 0):
    """test_pose_graph's square: ``laps`` laps of 4 x SIDE unit steps, a left turn per corner."""
    rng = np.random.default_rng(seed)
    n = 4 * SIDE * laps
    yaw = np.zeros(n)
    yaw[SIDE - 1::SIDE] = 90.0
    yaw = yaw + rng.normal(0.0, noise_deg, n) if noise_deg else yaw
    return n + 1, Steps(yaw=yaw, motion=np.zeros(n), still=np.zeros(n, bool), ambiguous=np.abs(yaw) > 90.0)


def _reference_cases():
    """The graphs whose image-only solutions were stored (tests/data/pose_graph_image_only.npz)
    by the code before metric factors existed."""
    m, steps = _square(noise_deg=1.0)
    a = np.arange(0, 4 * SIDE, 5)
    yield "square", m, steps, Loops(a=np.append(a, 3), b=np.append(a + 4 * SIDE, 4 * SIDE + 2 * SIDE + 5),
                                    yaw=np.zeros(a.size + 1)), (0,)
    m, steps = _square(noise_deg=2.0, seed=3)
    bad = 4 * SIDE + SIDE // 2
    steps.yaw[bad] = 180.0
    steps.ambiguous[bad] = True
    steps.motion[7] = np.nan
    steps.yaw[11] = np.nan
    steps.still[20] = True
    a = np.arange(0, 4 * SIDE, 3)
    yield "ambiguous", m, steps, Loops(a=a, b=a + 4 * SIDE, yaw=np.where(a % 2 == 0, 0.0, np.nan)), (0,)
    m, steps = _square(laps=1)
    yield "path", m, steps, NO_LOOPS, (0, 20)


@pytest.mark.parametrize("metric", [None, Metric(), Metric(gps=np.full((81, 2), np.nan))])
def test_without_metric_data_the_image_only_solution_is_unchanged(metric):
    ref = np.load(REFERENCE)
    for name, m, steps, loops, starts in _reference_cases():
        given = metric if metric is None or metric.gps is None else Metric(gps=np.full((m, 2), np.nan))
        sol = solve(m, steps, loops, MapParams(), chain_starts=starts, extra_keys=[2, min(50, m - 1)], metric=given)
        np.testing.assert_allclose(sol.poses, ref[name + "_poses"], rtol=0, atol=1e-9, err_msg=name)
        assert np.array_equal(sol.kept, ref[name + "_kept"]) and sol.unit == 1.0
        assert np.array_equal(sol.outvoted_steps, ref[name + "_outvoted"])
        assert sol.hops(np.array([2]), np.array([min(50, m - 1)]))[0] == ref[name + "_hops"][0]
        f = step_factors(steps, starts, MapParams(), given)
        np.testing.assert_array_equal(np.array([f.dx, f.dy, f.dt, f.sigma_xy, f.sigma_t]), ref[name + "_steps"])


# --- a route with GPS: out along a street, back along another 30 m away, and on over the start


def _route(legs, step_m: float = 1.0, noise_deg: float = 1.0, seed: int = 0):
    """(m, image steps, true xy in metres, true heading in radians) of legs (steps, turn after in degrees), each step
    ``step_m`` long; the image steps read the turns with ``noise_deg`` of noise, one node step long."""
    rng = np.random.default_rng(seed)
    yaw = np.concatenate([[0.0] * (n - 1) + [t] for n, t in legs])
    heading = np.radians(np.concatenate([[0.0], np.cumsum(yaw)]))
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(step_m * np.stack([np.cos(heading[:-1]), np.sin(heading[:-1])], 1), 0)])
    n = yaw.size
    steps = Steps(yaw=yaw + rng.normal(0, noise_deg, n), motion=rng.normal(0, 3, n), still=np.zeros(n, bool),
                  ambiguous=np.zeros(n, bool))
    return n + 1, steps, xy, heading


STREETS = [(60, 90), (30, 90), (60, 90), (30, 90), (20, 0)]   # a 60 x 30 m block, then 20 m on over the start


def _gps(xy, sigma=2.0, seed=1):
    return xy + np.random.default_rng(seed).normal(0, sigma, xy.shape)


def test_gps_rejects_a_loop_between_two_look_alike_places_30_m_apart_that_the_images_alone_keep():
    m, steps, xy, _ = _route(STREETS)
    a, b = 20, 130                                   # x = 20 m on the first street and on the second
    assert np.linalg.norm(xy[b] - xy[a]) == pytest.approx(30.0)
    wrong = Loops(np.array([a]), np.array([b]), np.array([np.nan]))
    assert solve(m, steps, wrong, MapParams()).kept.all()        # nothing in the images says otherwise
    sol = solve(m, steps, wrong, MapParams(), metric=Metric(gps=_gps(xy)))
    assert not sol.kept.any()
    assert sol.unit == pytest.approx(1.0, rel=0.05)              # metres per node step, from the GPS
    assert np.max(np.linalg.norm(sol.poses[:, :2] - xy, axis=1)) < 4.0   # in metres, in the GPS frame


@pytest.mark.parametrize("yaw", [180.0, np.nan])
def test_with_gps_the_true_revisit_is_kept_and_the_look_alike_rejected(yaw):
    m, steps, xy, _ = _route(STREETS)
    true_a, true_b = 10, 190                         # the start, driven over again at the end
    assert np.linalg.norm(xy[true_b] - xy[true_a]) < 1e-6
    loops = Loops(np.array([true_a, 20]), np.array([true_b, 130]), np.array([0.0, yaw]))
    sol = solve(m, steps, loops, MapParams(), metric=Metric(gps=_gps(xy)))
    assert sol.kept.tolist() == [True, False]
    assert np.linalg.norm(sol.poses[true_b, :2] - sol.poses[true_a, :2]) < 1.0


def test_the_image_steps_are_scaled_to_metres_and_the_map_turned_onto_the_gps():
    # 1.3 m per node step, the GPS frame turned 50 degrees from where the image path starts
    m, steps, xy, _ = _route(STREETS, step_m=1.3)
    turn = np.radians(50.0)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    world = xy @ rot.T + [100.0, -40.0]
    sol = solve(m, steps, NO_LOOPS, MapParams(), metric=Metric(gps=_gps(world)))
    assert sol.unit == pytest.approx(1.3, rel=0.05)
    assert np.max(np.linalg.norm(sol.poses[:, :2] - world, axis=1)) < 4.0
    heading = np.radians(sol.poses[1:59, 2])                  # along the first street
    assert np.degrees(np.abs(np.angle(np.mean(np.exp(1j * (heading - turn)))))) < 5.0


def test_a_gps_factor_is_position_only_the_heading_comes_from_the_path():
    # Two nodes one step apart with GPS fixes 10 m apart: the path gives no turn, so the
    # heading follows the fixes; a Pose2 prior with a free heading would pull it elsewhere.
    steps = Steps(yaw=np.zeros(1), motion=np.zeros(1), still=np.zeros(1, bool), ambiguous=np.zeros(1, bool))
    gps = np.array([[0.0, 0.0], [0.0, 10.0]])                  # due north
    sol = solve(2, steps, NO_LOOPS, MapParams(gps_sigma_m=0.01), metric=Metric(gps=gps))
    np.testing.assert_allclose(sol.poses[:, :2], gps, atol=0.05)
    assert sol.poses[0, 2] == pytest.approx(90.0, abs=1e-3)


def test_gps_precision_sets_the_factor_sigma():
    metric = Metric(gps=np.zeros((3, 2)), gps_dop=np.array([1.5, np.nan, 0.0]))
    np.testing.assert_allclose(metric.gps_sigma(3.0, 2.0), [3.0, 3.0, 3.0])
    metric = Metric(gps=np.zeros((3, 2)), gps_dop=np.array([4.0, np.nan, 1.0]))
    np.testing.assert_allclose(metric.gps_sigma(3.0, 2.0), [8.0, 3.0, 2.0])
    # a bad fix (DOP 10) barely pulls; with a good one the solution sits on it
    steps = Steps(yaw=np.zeros(1), motion=np.zeros(1), still=np.zeros(1, bool), ambiguous=np.zeros(1, bool))
    gps = np.array([[0.0, 0.0], [30.0, 0.0]])
    good = solve(2, steps, NO_LOOPS, MapParams(), metric=Metric(gps=gps, gps_dop=np.array([0.5, 0.5])))
    bad = solve(2, steps, NO_LOOPS, MapParams(), metric=Metric(gps=gps, gps_dop=np.array([0.5, 10.0])))
    assert good.poses[1, 0] - good.poses[0, 0] > bad.poses[1, 0] - bad.poses[0, 0]


def test_a_long_recording_gets_gps_factors_every_few_metres_not_on_every_node():
    from engine.metric_factors import gps_nodes as _gps_nodes

    m, steps, xy, _ = _route([(400, 90), (400, 90), (400, 0)], step_m=1.0)
    metric = Metric(gps=_gps(xy))
    dx = np.ones(m - 1)
    nodes = _gps_nodes(metric, dx, np.zeros(m - 1), np.array([0]), MapParams(gps_spacing_m=5.0), m)
    assert len(nodes) == pytest.approx((m - 1) / 5.0, abs=2)
    assert np.all(np.diff(nodes) == 5)
    # a long one: no more than the budget (the graph's other key nodes), evenly spread
    nodes = _gps_nodes(metric, dx, np.zeros(m - 1), np.array([0]), MapParams(gps_spacing_m=5.0), m, budget=100)
    assert len(nodes) == pytest.approx(100, abs=2) and np.all(np.diff(nodes) == 12)


# --- odometry


def _odometry(xy, heading_rad, origin=(5.0, -3.0, np.radians(30.0))):
    """Poses in an odometry frame placed at ``origin`` (x, y, yaw) of the world."""
    c, s = np.cos(origin[2]), np.sin(origin[2])
    x = origin[0] + c * xy[:, 0] - s * xy[:, 1]
    y = origin[1] + s * xy[:, 0] + c * xy[:, 1]
    return np.stack([x, y, heading_rad + origin[2]], axis=1)


def test_odometry_gives_the_steps_and_the_frame():
    m, steps, xy, heading = _route(STREETS, step_m=0.8, noise_deg=5.0)
    odom = _odometry(xy, heading)
    sol = solve(m, steps, NO_LOOPS, MapParams(), metric=Metric(odometry=odom))
    np.testing.assert_allclose(sol.poses[:, :2], odom[:, :2], atol=1e-6)
    turn = (sol.poses[:, 2] - np.degrees(odom[:, 2]) + 180) % 360 - 180
    assert np.abs(turn).max() < 1e-6
    assert sol.unit == pytest.approx(0.8)
    f = step_factors(steps, (0,), MapParams(), Metric(odometry=odom))
    assert np.allclose(np.hypot(f.dx, f.dy), 0.8) and np.allclose(f.sigma_xy, 0.05 * 0.8)


def test_odometry_that_drifts_is_corrected_by_a_true_loop_and_a_false_one_rejected():
    m, steps, xy, true_heading = _route(STREETS)
    drift = np.cumsum(np.random.default_rng(4).normal(0, 0.01, m))   # heading drift, radians
    heading = true_heading + drift
    odo_xy = np.concatenate([[[0, 0]], np.cumsum(np.stack([np.cos(heading[:-1]), np.sin(heading[:-1])], 1), 0)])
    odom = np.column_stack([odo_xy, heading])
    loops = Loops(np.array([10, 20]), np.array([190, 130]), np.array([0.0, 180.0]))
    sol = solve(m, steps, loops, MapParams(), metric=Metric(odometry=odom))
    assert sol.kept.tolist() == [True, False]
    assert np.linalg.norm(sol.poses[190, :2] - sol.poses[10, :2]) < 1.0


# --- through stage 7 of verified


class _Geometry:
    """What ``verified.consistent`` asks of the two-view geometry: the steps."""

    def __init__(self, steps):
        self._steps = steps

    def steps(self, params):
        return self._steps


def _auto_pairs(a, b, yaw):
    from engine.loops.pairs import Pairs, Status

    n = len(a)
    pairs = Pairs(a=np.asarray(a, np.int64), b=np.asarray(b, np.int64), cosine=np.full(n, 0.9, np.float32),
                  score=np.full(n, 9.0), yaw=np.asarray(yaw, np.float64))
    return pairs, np.full(n, Status.AUTO.value, dtype=object)


def test_stage_seven_sends_the_loop_gps_rejects_to_the_queue_and_measures_closure_in_node_steps():
    from engine.loops.verified import consistent

    m, steps, xy, _ = _route(STREETS, step_m=2.0)
    pairs, status = _auto_pairs([10, 20], [190, 130], [0.0, np.nan])
    out, reason, closure, poses, _ = consistent(pairs, status, _Geometry(steps), MapParams(), m, (0,),
                                                Metric(gps=_gps(xy)))
    assert out.tolist() == ["auto", "candidate"] and "rejects" in reason[1]
    assert closure[0] < 0.5 and closure[1] == pytest.approx(30.0, abs=2.0)   # 60 m at 2 m per node step
    assert np.max(np.linalg.norm(poses[:, :2] - xy, axis=1)) < 4.0          # the map in metres
    image_only = consistent(pairs, status, _Geometry(steps), MapParams(), m, (0,))
    assert image_only[0][1] == "auto"        # the images alone keep the look-alike (and here drop the true one)
