"""The horizon-band colour histogram: yaw invariant, lighting tolerant, parallax tolerant."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from engine.colour import BINS, colour_histogram
from engine.errors import InputError
from engine.synth.recording import make_recording

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def pano() -> np.ndarray:
    bgr = cv2.imread(str(DATA / "examplepano_1024.jpg"))
    return np.ascontiguousarray(cv2.resize(bgr, (256, 128), interpolation=cv2.INTER_AREA)[:, :, ::-1])


@pytest.fixture(scope="module")
def offset_route():
    return make_recording("offset", "indoor", seed=0, width=256, height=128, fps=1.0)


def test_unit_vector_of_all_bins(pano):
    h = colour_histogram(pano)
    assert h.shape == (BINS ** 3,) and h.dtype == np.float32
    assert np.isclose(np.linalg.norm(h), 1.0, atol=1e-5) and (h >= 0).all()


def test_a_yaw_rotation_does_not_change_it(pano):
    np.testing.assert_allclose(colour_histogram(np.roll(pano, 77, axis=1)), colour_histogram(pano), atol=1e-6)


def test_a_colour_cast_barely_changes_it_a_different_scene_does(pano, offset_route):
    cast = np.clip(pano.astype(np.float32) * np.array([0.75, 0.9, 1.15]), 0, 255).astype(np.uint8)
    h = colour_histogram(pano)
    assert float(colour_histogram(cast) @ h) > 0.9
    assert float(colour_histogram(offset_route.frames[10]) @ h) < 0.7


def test_a_place_seen_from_the_parallel_return_matches_better_than_elsewhere(offset_route):
    """Out along a corridor, back 0.8 m to the side: the nearest view of the return is
    more alike in colour than views of the same corridor 5 m or more away."""
    x, y = offset_route.poses.x, offset_route.poses.y
    hist = np.stack([colour_histogram(f) for f in offset_route.frames])
    out_leg = np.flatnonzero(y < 0)
    back_leg = np.flatnonzero(y > 0)
    wins = 0
    probes = out_leg[5:-5:6]
    for i in probes:
        d = np.hypot(x[back_leg] - x[i], y[back_leg] - y[i])
        near = back_leg[np.argmin(d)]
        far = back_leg[d > 5.0]
        wins += float(hist[i] @ hist[near]) > np.percentile(hist[far] @ hist[i], 90)
    assert wins >= 0.7 * len(probes)


def test_not_an_image_is_an_input_error():
    with pytest.raises(InputError):
        colour_histogram(np.zeros((10, 10)))
