"""Stage 7, the robust pose graph, on paths whose answer is known: a driven square."""

import numpy as np

from engine.loops.pairs import Steps
from engine.loops.pose_graph import Loops, backwards, solve
from engine.params import MapParams

SIDE = 10   # node steps per side of the square


def _square(laps: int = 2, noise_deg: float = 0.0, seed: int = 0):
    """Steps of a square driven ``laps`` times (a left turn at each corner), camera facing
    forward: each step moves one unit straight ahead."""
    rng = np.random.default_rng(seed)
    n = 4 * SIDE * laps
    yaw = np.zeros(n)
    yaw[SIDE - 1::SIDE] = 90.0
    yaw = yaw + rng.normal(0.0, noise_deg, n) if noise_deg else yaw
    steps = Steps(yaw=yaw, motion=np.zeros(n), still=np.zeros(n, bool), ambiguous=np.abs(yaw) > 90.0)
    return n + 1, steps


def _true_xy(m: int) -> np.ndarray:
    xy, pos, heading = [], np.zeros(2), 0.0
    for k in range(m):
        xy.append(pos.copy())
        pos = pos + [np.cos(np.radians(heading)), np.sin(np.radians(heading))]
        if k % SIDE == SIDE - 1:
            heading += 90.0
    return np.array(xy)


def test_true_loops_of_a_second_lap_are_kept_and_close_the_square():
    m, steps = _square(noise_deg=1.0)
    a = np.arange(0, 4 * SIDE, 5)
    loops = Loops(a=a, b=a + 4 * SIDE, yaw=np.zeros(a.size))
    sol = solve(m, steps, loops, MapParams())
    assert sol.kept.all()
    xy = sol.poses[:, :2]
    assert np.max(np.linalg.norm(xy[a] - xy[a + 4 * SIDE], axis=1)) < 1.0
    assert np.max(np.linalg.norm(xy - _true_xy(m), axis=1)) < 3.0


def test_a_loop_to_a_look_alike_place_across_the_square_is_rejected_and_the_true_ones_kept():
    m, steps = _square(noise_deg=1.0)
    a = np.arange(0, 4 * SIDE, 5)
    false_a, false_b = 3, 4 * SIDE + 2 * SIDE + 5          # the far side of the square, ~10 steps away
    loops = Loops(a=np.append(a, false_a), b=np.append(a + 4 * SIDE, false_b), yaw=np.zeros(a.size + 1))
    sol = solve(m, steps, loops, MapParams())
    assert sol.kept[:-1].all()
    assert not sol.kept[-1]


def test_a_step_misread_as_a_half_turn_is_outvoted_by_the_loops_across_it():
    m, steps = _square()
    bad = 4 * SIDE + SIDE // 2                              # mid-side on the second lap
    steps.yaw[bad] = 180.0
    steps.ambiguous[bad] = True
    a = np.arange(0, 4 * SIDE, 3)
    loops = Loops(a=a, b=a + 4 * SIDE, yaw=np.zeros(a.size))
    sol = solve(m, steps, loops, MapParams())
    assert bad in sol.outvoted_steps.tolist()
    assert sol.kept.mean() > 0.9
    xy = sol.poses[:, :2]
    assert np.max(np.linalg.norm(xy - _true_xy(m), axis=1)) < 3.0


def test_a_true_half_turn_stands_where_no_loop_disagrees():
    m, steps = _square(laps=1)
    steps.yaw[5] = 180.0                                    # the robot turns round mid-side...
    steps.ambiguous[5] = True
    sol = solve(m, steps, Loops(np.zeros(0, int), np.zeros(0, int), np.zeros(0)), MapParams())
    assert sol.outvoted_steps.size == 0
    # ...and drives back over where it came from: node 7 is where node 5 was
    assert np.linalg.norm(sol.poses[7, :2] - sol.poses[5, :2]) < 0.5


def test_steps_read_backwards_on_a_straight_side_do_not_fold_the_path_back():
    """Two views fix the direction of motion only up to its sign; a run of steps read
    backwards mid-side must not put the side's far end back beside its middle."""
    m, steps = _square(laps=1)
    steps.motion[4:7] = 180.0                               # three steps read backwards, no turn
    sol = solve(m, steps, Loops(np.zeros(0, int), np.zeros(0, int), np.zeros(0)), MapParams())
    along = np.linalg.norm(sol.poses[SIDE - 1, :2] - sol.poses[3, :2])
    assert along > 0.7 * (SIDE - 4)                          # folded, it would be SIDE - 4 - 6


def test_in_a_corridor_of_far_points_only_the_misread_steps_are_read_backwards():
    m, steps = _square(laps=2)
    steps.motion[[13, 14]] = np.nan                         # no reading, then...
    flipped = [15, 18, 19, 23, 47, 60]                      # ...the first one after it misread
    steps.motion[flipped] = 180.0
    assert np.flatnonzero(backwards(steps, [0])).tolist() == flipped


def test_a_camera_mounted_sideways_moves_sideways_and_is_not_read_backwards():
    m, steps = _square(laps=1)
    steps.motion[:] = 90.0                                  # the camera faces the vehicle's left
    assert not backwards(steps, [0]).any()


def test_a_camera_that_keeps_its_heading_round_a_square_is_not_read_backwards():
    m, steps = _square(laps=1)
    steps.yaw[:] = 0.0                                      # a gimbal, or a 360 camera's direction lock:
    steps.motion[:] = 90.0 * (np.arange(steps.motion.size) // SIDE)   # it sees the vehicle move every way
    assert not backwards(steps, [0]).any()


def test_a_turn_read_in_steps_is_not_taken_for_backwards_motion():
    m, steps = _square(laps=1)
    steps.yaw[:] = 20.0                                     # a steady left curve...
    steps.motion[:] = 10.0                                  # ...moving along its chord
    assert not backwards(steps, [0]).any()


def test_two_recordings_are_two_chains_joined_only_by_loops():
    m1, s1 = _square(laps=1)
    # the second recording drives the same square starting 5 nodes into the first's lap
    steps = Steps(yaw=np.concatenate([s1.yaw, [0.0], np.roll(s1.yaw, -5)]), motion=np.zeros(2 * (m1 - 1) + 1),
                  still=np.zeros(2 * (m1 - 1) + 1, bool), ambiguous=np.zeros(2 * (m1 - 1) + 1, bool))
    a = np.arange(5, 4 * SIDE, 4)
    b = m1 + (a - 5)
    sol = solve(2 * m1, steps, Loops(a=a, b=b, yaw=np.zeros(a.size)), MapParams(), chain_starts=[0, m1])
    assert sol.kept.all()
    assert np.linalg.norm(sol.poses[m1, :2] - sol.poses[5, :2]) < 1.0
    assert np.isfinite(sol.poses).all()


def test_recordings_that_start_elsewhere_facing_elsewhere_are_joined_by_all_their_loops():
    """Three recordings of one square: the second starts a side and a half in (facing a
    quarter turn round), the third two and a half sides in (a half turn round), each
    dead-reckoned from the origin facing 0. The loops are kept and close the square."""
    m1, s1 = _square(laps=1, noise_deg=2.0)
    n1 = m1 - 1
    yaw = np.concatenate([s1.yaw, [0.0], np.roll(s1.yaw, -15), [0.0], np.roll(s1.yaw, -25)])
    steps = Steps(yaw=yaw, motion=np.zeros(yaw.size), still=np.zeros(yaw.size, bool),
                  ambiguous=np.zeros(yaw.size, bool))
    a2, a3 = np.arange(15, n1, 3), np.arange(25, n1, 3)
    loops = Loops(a=np.concatenate([a2, a3]), b=np.concatenate([m1 + a2 - 15, 2 * m1 + a3 - 25]),
                  yaw=np.zeros(a2.size + a3.size))
    sol = solve(3 * m1, steps, loops, MapParams(), chain_starts=[0, m1, 2 * m1])
    assert sol.kept.all()
    xy = sol.poses[:, :2]
    assert np.max(np.linalg.norm(xy[loops.a] - xy[loops.b], axis=1)) < 1.0


def test_the_solver_starts_each_recording_where_most_of_its_loops_put_it():
    from engine.loops.pose_graph import _aligned
    from engine.planar import dead_reckoning

    m1, s1 = _square(laps=1)
    yaw = np.concatenate([s1.yaw, [0.0], np.roll(s1.yaw, -15), [0.0], s1.yaw])
    n = yaw.size + 1
    dx, dy = np.ones(yaw.size), np.zeros(yaw.size)
    starts = np.array([0, m1, 2 * m1])
    dr = dead_reckoning(dx, dy, np.radians(yaw), n, starts)
    a = np.arange(15, m1 - 1, 2)
    b = m1 + a - 15
    wrong = np.zeros(a.size)
    wrong[:3] = 120.0                              # a few loops read a wrong heading
    start = _aligned(dr, starts, n, Loops(a=a, b=b, yaw=wrong), np.zeros(3, bool), np.radians(30.0))
    ok = slice(3, None)
    assert np.max(np.linalg.norm(start[a[ok], :2] - start[b[ok], :2], axis=1)) < 1e-6
    assert np.allclose(np.angle(np.exp(1j * (start[b[ok], 2] - start[a[ok], 2]))), 0.0, atol=1e-6)
    assert np.array_equal(start[:m1], dr[:m1])     # the first recording fixes the map
    assert np.array_equal(start[2 * m1:], dr[2 * m1:])   # a recording no loop joins stays put


def test_hops_follow_the_path_and_the_kept_loops():
    m, steps = _square()
    loops = Loops(a=np.array([0]), b=np.array([4 * SIDE]), yaw=np.zeros(1))
    sol = solve(m, steps, loops, MapParams(), extra_keys=[1, 4 * SIDE + 1])
    assert sol.hops(np.array([1]), np.array([4 * SIDE + 1]))[0] <= 3
