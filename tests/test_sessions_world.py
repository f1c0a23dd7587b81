"""The same world on another day (engine.synth.sessions, engine.synth2.sessions): properties of
the day pair, never exact counts. Renders are tiny (64x32 or a few frames)."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InputError
from engine.synth import make_recording
from engine.synth.sessions import DayTwo, close_pairs, day_pair, day_two_path, offset_path, poses_pair
import engine.synth2 as synth2
from engine.synth2 import sessions as sessions2
from engine.synth2.routes import route_spec


def _longest_stretch(p, mask) -> float:
    """Metres driven along the longest run of consecutive samples of ``p`` where ``mask``."""
    step = np.r_[0.0, np.hypot(np.diff(p.x), np.diff(p.y))]
    best = run = 0.0
    for k, m in enumerate(mask):
        run = run + step[k] if m and k and mask[k - 1] else 0.0
        best = max(best, run)
    return best


def _shared(p1, p2, same: bool):
    """Day-2 samples within 1 m of a day-1 sample heading the same way (``same``) or the
    opposite way."""
    d2 = (p2.x[:, None] - p1.x[None]) ** 2 + (p2.y[:, None] - p1.y[None]) ** 2
    cos = np.cos(p2.yaw[:, None] - p1.yaw[None])
    ok = (d2 <= 1.0) & ((cos > 0.7) if same else (cos < -0.7))
    return ok.any(axis=1)


FIRST = [(r, lk) for r in ("crossing", "reverse", "offset", "loop") for lk in ("indoor", "outdoor")]
SECOND = list(synth2.ROUTES)


@pytest.mark.parametrize("route,look", FIRST)
def test_first_family_days_share_stretches_both_ways_from_another_start(route, look):
    p1, p2 = poses_pair(route, 0, look)
    assert len(close_pairs(p1, p2, 1.0)) > 0
    # Driven both days along a stretch, in the same direction and (partly) the other way.
    assert _longest_stretch(p2, _shared(p1, p2, same=True)) >= 5.0
    assert _longest_stretch(p2, _shared(p1, p2, same=False)) >= 3.0
    assert np.hypot(p1.x[0] - p2.x[0], p1.y[0] - p2.y[0]) > 2.0          # another start


@pytest.mark.parametrize("route", SECOND)
@pytest.mark.parametrize("seed", [0, 1])
def test_second_family_days_share_stretches_both_ways_and_stay_in_free_space(route, seed):
    p1, p2 = sessions2.poses_pair(route, seed)
    assert _longest_stretch(p2, _shared(p1, p2, same=True)) >= 5.0
    assert _longest_stretch(p2, _shared(p1, p2, same=False)) >= 3.0
    assert np.hypot(p1.x[0] - p2.x[0], p1.y[0] - p2.y[0]) > 2.0
    plan = route_spec(route, seed).plan
    assert plan.free_at(np.stack([p2.x, p2.y], 1), 0.1).all()            # never in a wall


def _wall_distance(world, x, y) -> np.ndarray:
    a, b = world.seg_a, world.seg_b
    p = np.stack([x, y], 1)[:, None]
    d = b - a
    f = np.clip(((p - a) * d).sum(-1) / (d * d).sum(-1), 0, 1)
    return np.hypot(*(p - (a + f[..., None] * d)).transpose(2, 0, 1)).min(axis=1)


def test_first_family_day_two_keeps_clear_of_walls():
    from engine.synth.routes import make_route

    for route, look in FIRST:
        world = make_route(route, look, 0).world
        _, p2 = poses_pair(route, 0, look)
        assert _wall_distance(world, p2.x, p2.y).min() > 0.3


def test_second_day_is_darker_at_the_same_places_first_family():
    pair = day_pair("crossing", 0, "indoor", width=64, height=32)
    pairs = close_pairs(pair.poses1, pair.poses2, 0.5)
    assert len(pairs) > 5
    m1 = pair.day1.frames[pairs[:, 0]].astype(float).mean()
    m2 = pair.day2.frames[pairs[:, 1]].astype(float).mean()
    assert m2 < 0.85 * m1
    # White balance: warmer light, red relative to blue goes up.
    r1 = pair.day1.frames[pairs[:, 0], ..., 0].mean() / pair.day1.frames[pairs[:, 0], ..., 2].mean()
    r2 = pair.day2.frames[pairs[:, 1], ..., 0].mean() / pair.day2.frames[pairs[:, 1], ..., 2].mean()
    assert r2 > r1


def test_second_day_is_darker_at_the_same_places_second_family():
    pair = sessions2.day_pair("crossing", 0, width=64)
    pairs = close_pairs(pair.poses1, pair.poses2, 0.5)
    assert len(pairs) > 5
    m1 = pair.day1.frames[pairs[:, 0]].astype(float).mean()
    m2 = pair.day2.frames[pairs[:, 1]].astype(float).mean()
    assert m2 < 0.85 * m1


def test_same_world_first_family_day_two_without_changes_is_day_one():
    plain = DayTwo(exposure=1.0, white_balance=(1.0, 1.0, 1.0), sun_turn=0.0, people=0, start_frac=0.0,
                   back_frac=0.0, lane=0.0, speed=0.8)
    pair = day_pair("offset", 2, "outdoor", width=32, height=16, day2=plain, max_frames=12)
    assert pair.day1.frames.tobytes() == pair.day2.frames.tobytes()


def test_day_one_is_the_plain_recording_and_renders_are_deterministic():
    a = day_pair("loop", 3, "outdoor", width=32, height=16, people=2, max_frames=6)
    b = day_pair("loop", 3, "outdoor", width=32, height=16, people=2, max_frames=6)
    ref = make_recording("loop", "outdoor", 3, width=32, height=16, fps=1.0, people=2, max_frames=6)
    assert a.day1.frames.tobytes() == ref.frames.tobytes()
    assert a.day2.frames.tobytes() == b.day2.frames.tobytes()
    other = day_pair("loop", 4, "outdoor", width=32, height=16, people=2, max_frames=6)
    assert other.day2.frames.tobytes() != a.day2.frames.tobytes()


def test_second_family_day_one_is_the_plain_recording_and_renders_are_deterministic():
    a = sessions2.day_pair("junction", 1, width=32, max_frames=5)
    b = sessions2.day_pair("junction", 1, width=32, max_frames=5)
    ref = synth2.make_recording("junction", 1, width=32, max_frames=5)
    assert a.day1.frames.tobytes() == ref.frames.tobytes()
    assert a.day2.frames.tobytes() == b.day2.frames.tobytes()
    assert a.day2.meta["day"] == 2 and a.day2.meta["things"] > 0


def test_ground_truth_of_the_render_matches_the_unrendered_poses():
    pair = day_pair("reverse", 0, "indoor", width=32, height=16, max_frames=4)
    p1, p2 = poses_pair("reverse", 0, "indoor")
    assert np.allclose(pair.poses2.x, p2.x[:4]) and np.allclose(pair.poses2.y, p2.y[:4])
    assert np.allclose(pair.poses1.x, p1.x[:4])


def test_paths_keep_their_lane_and_refuse_bad_knobs():
    square = np.array([(0, 0), (10, 0), (10, 10)], float)
    moved = offset_path(square, 0.5)
    assert np.allclose(moved[0], (0, -0.5)) and np.allclose(moved[-1], (10.5, 10))
    path, back_at = day_two_path(np.array([(0, 0), (20, 0)], float), 0.25, 0.5, 0.25)
    assert np.allclose(path[0], (5, -0.25))                # a quarter along, right of travel
    assert 0 < back_at < len(path)
    assert path[back_at:, 1].max() > 0                     # the return leg keeps to its right
    with pytest.raises(InputError):
        day_pair("loop", 0, day2=DayTwo(exposure=0.0), max_frames=1)
    with pytest.raises(InputError):
        poses_pair("nowhere")
