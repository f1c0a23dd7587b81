"""Second synthetic world family: determinism, geometry, routes and their revisits, licences."""

from __future__ import annotations

import numpy as np
import pytest

from engine.errors import InputError
from engine.synth.recording import Recording
from engine.synth2 import ROUTES, Camera, make_recording, poses_for, revisits_for
from engine.synth2.camera import apply_camera
from engine.synth2.paths import drive
from engine.synth2.render import render_view
from engine.synth2.routes import route_spec
from engine.synth2.textures import TEXTURE_DIR, TILE_H, TILE_W, build_atlas, load_crop
from engine.synth2.world import Things, World, build_world

W = 64


def _world(route: str, seed: int) -> World:
    spec = route_spec(route, seed)
    return build_world(spec, seed, drive(spec.waypoints, 0.8, 1.0))


def test_same_arguments_give_identical_frames_and_another_seed_differs():
    a = make_recording("junction", seed=3, width=W, max_frames=3)
    b = make_recording("junction", seed=3, width=W, max_frames=3)
    c = make_recording("junction", seed=5, width=W, max_frames=3)
    assert isinstance(a, Recording)
    assert a.frames.tobytes() == b.frames.tobytes()
    assert np.abs(a.frames.astype(int) - c.frames.astype(int)).mean() > 8
    assert a.meta["generator"] == "panotopo.synth2"


@pytest.mark.parametrize("route", ROUTES)
def test_frames_are_2to1_uint8_photographic_and_poses_match(route):
    rec = make_recording(route, seed=1, width=W, max_frames=2)
    assert rec.frames.dtype == np.uint8 and rec.frames.shape[1:] == (W // 2, W, 3)
    img = rec.frames[1].astype(int)
    assert img.std() > 20
    assert np.abs(np.diff(img, axis=1)).mean() > 3 and np.abs(np.diff(img, axis=0)).mean() > 3
    full = poses_for(route, seed=1)
    assert np.array_equal(rec.poses.x, full.x[:2]) and np.array_equal(rec.poses.yaw, full.yaw[:2])
    assert 0.5 <= rec.meta["camera_height"] <= 1.8


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("route", ROUTES)
def test_routes_are_smooth_clear_of_walls_and_pass_their_revisits_twice(route, seed):
    p = poses_for(route, seed)
    assert 150 <= len(p) <= 400          # 1 frame per 0.8 m
    step = np.hypot(np.diff(p.x), np.diff(p.y))
    assert step.max() <= 0.8 + 1e-9
    assert np.abs(np.diff(p.yaw)).max() <= np.radians(46)
    # The robot keeps 0.3 m from every wall (it drives through doors, not walls) ...
    plan = route_spec(route, seed).plan
    assert plan.free_at(np.stack([p.x, p.y], 1), clearance=0.3).all()
    for px, py in revisits_for(route, seed):
        near = np.flatnonzero(np.hypot(p.x - px, p.y - py) < 1.0)
        assert near.size and p.t[near].max() - p.t[near].min() > 10.0, (route, px, py)
    assert bool(revisits_for(route, seed)) == (route != "lookalike")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lookalike_route_never_returns(seed):
    p = poses_for("lookalike", seed)
    pos = np.stack([p.x, p.y], 1)
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    apart = np.abs(np.subtract.outer(np.arange(len(p)), np.arange(len(p)))) > 3
    assert dist[apart].min() > 1.0


def test_lookalike_places_look_alike_and_differ_from_elsewhere():
    spec = route_spec("lookalike", 0)
    world = _world("lookalike", 0)
    world.things.pos[:] = np.nan
    (a, b), = spec.twins
    # Walls above the horizon (the floor is not copied), looking at the sides of the street
    # (ahead and behind, the streets beyond the copied building differ).
    band = (slice(W // 8, W // 2), np.r_[W // 8:3 * W // 8, 5 * W // 8:7 * W // 8])
    va = render_view(world, *a, 0.0, 0, W, 1.2)[band[0]][:, band[1]]
    vb = render_view(world, *b, 0.0, 0, W, 1.2)[band[0]][:, band[1]]
    vc = render_view(world, a[0] + 10.0, a[1], 0.0, 0, W, 1.2)[band[0]][:, band[1]]
    assert np.abs(va - vb).mean() * 3 < np.abs(va - vc).mean()
    assert abs(b[0] - a[0]) > 20.0


def test_crossing_angle_reverse_and_zero_net_turning_of_the_figure_eight():
    for seed in (0, 1, 2):
        p = poses_for("crossing", seed)
        near = np.flatnonzero(np.hypot(p.x, p.y) < 0.5)
        diff = np.degrees(abs(np.angle(np.exp(1j * (p.yaw[near[-1]] - p.yaw[near[0]])))))
        assert 60.0 - 1 <= diff <= 120.0 + 1 or 60.0 - 1 <= 180 - diff <= 120.0 + 1, diff
        p = poses_for("figure_eight", seed)
        sx, sy = revisits_for("figure_eight", seed)[1]
        near = np.flatnonzero(np.hypot(p.x - sx, p.y - sy) < 0.5)
        assert abs(np.degrees(p.yaw[near[-1]] - p.yaw[near[0]])) < 10.0
        p = poses_for("reverse", seed)
        cx, cy = revisits_for("reverse", seed)[0]
        near = np.flatnonzero(np.hypot(p.x - cx, p.y - cy) < 0.5)
        diff = np.degrees(abs(np.angle(np.exp(1j * (p.yaw[near[-1]] - p.yaw[near[0]])))))
        assert diff > 170.0


def test_junction_is_entered_from_different_arms():
    for seed in (0, 1):
        p = poses_for("junction", seed)
        inside = np.hypot(p.x, p.y) < 1.0
        starts = np.flatnonzero(inside & ~np.r_[False, inside[:-1]])
        assert starts.size >= 2
        headings = np.exp(1j * p.yaw[starts])
        assert np.abs(headings[1] - headings[0]) > 0.5      # not the same way twice


def _marker_world() -> World:
    """A 20 m square room with one magenta wall piece 3 m east of the origin."""
    grey = np.full((TILE_H, TILE_W, 3), 120, np.uint8)
    grey[::16] = 90
    magenta = np.zeros_like(grey)
    magenta[..., 0] = magenta[..., 2] = 255
    sky = np.zeros_like(grey)
    sky[..., 2] = 200
    atlas = build_atlas([grey, magenta, grey, grey, sky], ["grey", "magenta", "floor", "ceiling", "sky"])
    room = np.array([[-10, -10, 10, -10], [10, -10, 10, 10], [10, 10, -10, 10], [-10, 10, -10, -10]], float)
    marker = np.array([[3.0, -0.15, 3.0, 0.15]])
    segs = np.concatenate([room, marker])
    n = len(segs)
    things = Things(np.zeros((1, 0, 2)), np.zeros(0), np.zeros(0), np.zeros(0, int), np.zeros(0, bool), np.zeros(0))
    return World("marker", True, segs, np.arange(n, dtype=np.int64), np.zeros((n, 2)), np.array([0]),
                 3.0, 2.5, 2.5, 2, 3.0, 3, 4, atlas, things, np.array([1.0, 0.0]),
                 seg_tile=np.array([-1, -1, -1, -1, 1]))


def test_centre_column_is_the_heading_and_columns_increase_clockwise():
    world = _marker_world()
    for yaw, expected in ((0.0, W / 2), (np.pi / 2, 3 * W / 4), (-np.pi / 2, W / 4), (np.pi, 0.0)):
        img = apply_camera(Camera.plain(), render_view(world, 0.0, 0.0, yaw, 0, W, 1.2), 0.0, 0, 0.0, 0)
        img = img.astype(int)
        magenta = (img[..., 0] > 150) & (img[..., 2] > 150) & (img[..., 1] < 60)
        cols = np.flatnonzero(magenta.any(axis=0))
        assert cols.size, yaw
        centre = np.angle(np.exp(2j * np.pi * (cols + 0.5) / W).mean()) / (2 * np.pi) * W % W
        err = (centre - expected + W / 2) % W - W / 2
        assert abs(err) <= 1.0, (yaw, cols)


def test_turning_the_robot_rolls_the_panorama():
    world = _world("crossing", 2)
    x, y = poses_for("crossing", 2).x[20], poses_for("crossing", 2).y[20]
    a = render_view(world, x, y, 0.4, 0, W, 1.0)
    for quarter in (1, 2, 3):
        b = render_view(world, x, y, 0.4 + quarter * np.pi / 2, 0, W, 1.0)
        rolled = np.roll(a, quarter * W // 4, axis=1)
        assert np.abs(rolled - b).mean() < 0.5
        assert np.abs(a - b).mean() > 5


def test_things_move_between_laps_and_stay_within_a_lap():
    world = _world("block_laps", 0)
    th = world.things
    assert th.size.size > 0
    # ... and nothing stands on its path.
    p = poses_for("block_laps", 0)
    placed = th.pos[~np.isnan(th.pos[..., 0])]
    gap = np.hypot(placed[:, None, 0] - p.x[None], placed[:, None, 1] - p.y[None]).min()
    assert gap >= 0.7 - 1e-9
    moved = ~np.all(np.isclose(th.pos[0], th.pos[1], equal_nan=True), axis=1)
    assert moved.any()
    k = int(np.flatnonzero(moved)[0])
    p = th.pos[0, k] if not np.isnan(th.pos[0, k, 0]) else th.pos[1, k]
    q = p + np.array([1.2, 0.0])
    yaw = float(np.arctan2(*(p - q)[::-1]))
    v0 = render_view(world, *q, yaw, 0, W, 1.0)
    assert np.array_equal(v0, render_view(world, *q, yaw, 0, W, 1.0))
    assert not np.array_equal(v0, render_view(world, *q, yaw, 1, W, 1.0))


def test_camera_effects_change_pixels_but_keep_the_scene():
    world = _world("reverse", 0)
    p = poses_for("reverse", 0)
    view = render_view(world, p.x[10], p.y[10], p.yaw[10], 0, W, 1.0)
    plain = apply_camera(Camera.plain(), view, 10.0, 0, 0.0, 0).astype(int)
    cam = Camera.draw(np.random.default_rng(0), 2, True)
    real = apply_camera(cam, view, 10.0, 1, 0.5, 0).astype(int)
    d = np.abs(plain - real).mean()
    assert 1.0 < d < 60.0
    # The seam: a brightness step at a column fixed in the camera.
    seam = int(round(cam.seam_col * W))
    cam_seam = Camera(seam_col=cam.seam_col, seam_gain=(0.8, 0.8, 0.8))
    s = apply_camera(cam_seam, view, 10.0, 0, 0.0, 0).astype(float)
    ratio = s[:, seam:seam + W // 2].mean() / plain[:, seam:seam + W // 2].mean()
    assert abs(ratio - 0.8) < 0.05


def test_shipped_textures_have_their_licences():
    readme = (TEXTURE_DIR / "README.md").read_text()
    jpgs = sorted(TEXTURE_DIR.glob("*.jpg"))
    assert jpgs
    for f in jpgs:
        assert f"`{f.name}`" in readme, f.name
        assert load_crop(f.stem).ndim == 3
    assert "Permission is hereby granted" in (TEXTURE_DIR / "LICENSE-MIT-panoramax.txt").read_text()
    assert "by-sa/3.0" in (TEXTURE_DIR / "LICENSE-CC-BY-SA-3.0-examplepano.txt").read_text()
    assert sum(f.stat().st_size for f in TEXTURE_DIR.iterdir()) < 1_500_000


def test_bad_arguments_raise_input_error():
    with pytest.raises(InputError):
        make_recording("nowhere")
    with pytest.raises(InputError):
        make_recording("junction", width=63)
    with pytest.raises(InputError):
        poses_for("junction", fps=0.0)


def test_recordings_are_written_by_the_first_familys_writers(tmp_path):
    import csv

    import cv2

    from engine.synth import write_recording

    rec = make_recording("reverse", seed=0, width=W, max_frames=3)
    out = write_recording(rec, tmp_path, formats=("folder", "poses"))
    images = sorted(p for p in out["folder"].iterdir() if p.suffix in (".png", ".jpg"))
    assert len(images) == 3
    assert cv2.imread(str(images[0])).shape == (W // 2, W, 3)
    with open(out["poses"]) as f:
        assert len(list(csv.reader(f))) >= 3
