"""Synthetic worlds and recordings: determinism, panorama geometry, routes, writers."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from engine.errors import InputError
from engine.synth import LOOKS, ROUTES, Recording, make_recording, make_route, render, write_recording

W, H = 128, 64


def _best_roll_error(a: np.ndarray, b: np.ndarray) -> tuple[int, float]:
    """The circular column shift k minimising mean |roll(a, k) - b|, and that error."""
    a16, b16 = a.astype(np.int16), b.astype(np.int16)
    errs = [np.abs(np.roll(a16, k, axis=1) - b16).mean() for k in range(a.shape[1])]
    k = int(np.argmin(errs))
    return k, float(errs[k])


@pytest.fixture(scope="module")
def worlds():
    return {look: make_route("crossing", look, seed=3) for look in LOOKS}


def test_same_seed_gives_identical_frames_and_other_seed_differs():
    kw = dict(width=W, height=H, people=2, lighting_drift=0.5, noise=0.02, max_frames=6)
    a = make_recording("demo", "indoor", seed=5, **kw)
    b = make_recording("demo", "indoor", seed=5, **kw)
    c = make_recording("demo", "indoor", seed=6, **kw)
    assert isinstance(a, Recording)
    assert a.frames.tobytes() == b.frames.tobytes()
    assert np.array_equal(a.stamps, b.stamps)
    # Another seed: another world (textures), so the images differ clearly.
    assert np.abs(a.frames.astype(int) - c.frames.astype(int)).mean() > 10


@pytest.mark.parametrize("look", LOOKS)
def test_frames_are_2to1_uint8_with_real_content(worlds, look):
    r = worlds[look]
    tr = r.trajectory
    img = render(r.world, tr.x[10], tr.y[10], tr.yaw[10], tr.t[10], W, H)
    assert img.dtype == np.uint8 and img.shape == (H, W, 3)
    assert img.std() > 25
    # Structure in both directions (walls have features, not one flat colour per column).
    assert np.abs(np.diff(img.astype(int), axis=1)).mean() > 3
    assert np.abs(np.diff(img.astype(int), axis=0)).mean() > 3
    # Top rows: ceiling (indoor, grey-white) or sky (outdoor, blue) - never the floor.
    top = img[:3].reshape(-1, 3).mean(0)
    if look == "outdoor":
        assert top[2] > top[0] + 20
    else:
        assert top.mean() > 150


@pytest.mark.parametrize("look", LOOKS)
@pytest.mark.parametrize("quarter_turns", [1, 2, 3])
def test_yaw_rotation_is_an_exact_circular_shift(worlds, look, quarter_turns):
    r = worlds[look]
    x, y, yaw = 1.3, -0.4, 0.37
    a = render(r.world, x, y, yaw, 0.0, W, H)
    b = render(r.world, x, y, yaw + quarter_turns * np.pi / 2, 0.0, W, H)
    assert np.array_equal(np.roll(a, quarter_turns * W // 4, axis=1), b)
    assert not np.array_equal(a, b)


def test_centre_column_is_the_heading_and_columns_turn_clockwise():
    # One standing person 3 m east of the robot: seen at the centre column when heading east,
    # at three quarters (to the right) when heading north, at one quarter when heading south.
    from engine.synth.world import make_people

    r = make_route("crossing", "indoor", seed=0)
    person = make_people([(0.0, 0.0, 1.0, 0.0, 0.0)], 1, seed=0)
    person.p0[:] = [[3.0, 0.0]]
    person.p1[:] = [[3.0, 0.0]]
    person.colours[:] = [1.0, 0.0, 1.0]                    # magenta: nowhere else in the world
    r.world.people = person
    for yaw, expected in ((0.0, W // 2), (np.pi / 2, 3 * W // 4), (-np.pi / 2, W // 4)):
        img = render(r.world, 0.0, 0.0, yaw, 0.0, W, H).astype(int)
        magenta = (img[..., 0] > 150) & (img[..., 2] > 150) & (img[..., 1] < 60)
        cols = np.flatnonzero(magenta.any(axis=0))
        assert cols.size, yaw
        assert abs(cols.mean() - expected) <= 1.0, (yaw, cols)
        rows = np.flatnonzero(magenta.any(axis=1))
        assert rows.max() > H // 2 > rows.min()   # taller than the camera, standing on the floor


@pytest.mark.parametrize("look", LOOKS)
def test_same_place_other_heading_is_a_circular_shift(worlds, look):
    r = worlds[look]
    x, y = 0.2, 0.1
    a = render(r.world, x, y, 0.0, 0.0, W, H)
    # An arbitrary heading (not a whole number of columns): equal up to interpolation.
    b = render(r.world, x, y, np.radians(73.0), 0.0, W, H)
    k, err = _best_roll_error(a, b)
    assert abs(k - 73.0 / 360.0 * W) <= 1.0
    assert err < 6.0
    # A different place is clearly not a shift of it.
    c = render(r.world, x + 6.0, y, 0.0, 0.0, W, H)
    assert _best_roll_error(a, c)[1] > 3 * err + 5


@pytest.mark.parametrize("name", ["crossing", "reverse", "offset", "loop", "demo"])
def test_routes_revisit_their_places(name):
    r = make_route(name, "indoor", seed=0, fps=2.0)
    tr = r.trajectory
    assert np.all(np.diff(tr.t) > 0)
    step = np.hypot(np.diff(tr.x), np.diff(tr.y))
    assert step.max() <= 0.8 / 2.0 + 1e-9              # speed 0.8 m/s, never a jump
    assert np.abs(np.diff(tr.yaw)).max() < np.radians(60)   # smooth heading
    pos = np.stack([tr.x, tr.y], 1)
    far_apart = np.abs(np.subtract.outer(tr.t, tr.t)) > 20.0
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    assert dist[far_apart].min() < 1.0
    # Every listed revisit place is passed at least twice, at least 10 s apart.
    assert r.revisits
    for px, py in r.revisits:
        near = np.flatnonzero(np.hypot(tr.x - px, tr.y - py) < 1.0)
        assert near.size and tr.t[near].max() - tr.t[near].min() > 10.0, (name, px, py)


def test_crossing_is_passed_perpendicular_and_reverse_backwards():
    for name, angle in (("crossing", 90.0), ("reverse", 180.0)):
        tr = make_route(name, "indoor", seed=0).trajectory
        px, py = make_route(name, "indoor", seed=0).revisits[0 if name == "crossing" else 2]
        near = np.flatnonzero(np.hypot(tr.x - px, tr.y - py) < 0.5)
        first, last = near[0], near[-1]
        diff = np.degrees(np.angle(np.exp(1j * (tr.yaw[last] - tr.yaw[first]))))
        assert abs(abs(diff) - angle) < 15.0, (name, diff)


def test_people_move_between_frames():
    r = make_route("demo", "indoor", seed=1, people=6)
    p0, p1 = r.world.people.positions(0.0), r.world.people.positions(1.0)
    moved = np.hypot(*(p1 - p0).T)
    assert np.all(moved > 0.01) and np.median(moved) > 0.5
    # And they are visible: at the crossing (view along all four arms) the same pose at two
    # times renders differently with people, identically without.
    quiet = make_route("demo", "indoor", seed=1, people=0)
    frames = [render(w, 0.0, 0.0, 0.3, t, W, H) for w in (r.world, quiet.world) for t in (0.0, 3.0)]
    assert not np.array_equal(frames[0], frames[1])
    assert np.array_equal(frames[2], frames[3])


def test_lighting_drift_and_noise_change_pixels_only_slightly():
    base = make_recording("loop", "outdoor", seed=2, width=W, height=H, max_frames=1)
    drift = make_recording("loop", "outdoor", seed=2, width=W, height=H, max_frames=1,
                           lighting_drift=1.0, noise=0.03)
    d = np.abs(base.frames.astype(int) - drift.frames.astype(int)).mean()
    assert 1.0 < d < 60.0


def test_bad_arguments_raise_input_error():
    with pytest.raises(InputError):
        make_recording("demo", "indoor", width=100, height=64)
    with pytest.raises(InputError):
        make_recording("nowhere", "indoor")
    with pytest.raises(InputError):
        make_recording("demo", "underwater")
    r = make_route("demo", "indoor")
    with pytest.raises(InputError):
        render(r.world, 0, 0, 0, 0, 100, 100)


def test_routes_and_looks_are_complete():
    assert set(ROUTES) == {"crossing", "reverse", "offset", "loop", "demo"}
    assert set(LOOKS) == {"indoor", "outdoor"}
    for look in LOOKS:
        length = make_route("demo", look).length
        assert 60.0 <= length <= 100.0


def test_write_recording_writes_every_format(tmp_path):
    import cv2

    rec = make_recording("crossing", "indoor", seed=0, width=W, height=H, max_frames=5)
    written = write_recording(rec, tmp_path)
    assert set(written) == {"video", "ros1", "ros2-sqlite3", "ros2-mcap", "folder", "poses"}
    for fmt, path in written.items():
        assert path.exists(), fmt
    assert written["video"].name == "crossing.mp4" and written["ros1"].name == "crossing.bag"
    cap = cv2.VideoCapture(str(written["video"]))
    count = 0
    while cap.read()[0]:
        count += 1
    cap.release()
    assert count == 5
    assert len(list(written["folder"].glob("*.png"))) == 5
    with open(written["poses"]) as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 5 and float(rows[-1]["x"]) == pytest.approx(rec.poses.x[-1])
    assert any(written["ros2-mcap"].glob("*.mcap")) and any(written["ros2-sqlite3"].glob("*.db3"))
    with pytest.raises(InputError):
        write_recording(rec, tmp_path, formats=("tape",))
