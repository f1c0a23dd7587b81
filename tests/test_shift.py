from pathlib import Path

import cv2
import numpy as np
import pytest

from engine.errors import InputError
from engine.shift import (
    apply_shift,
    canonical_shift,
    heading_harmonic,
    heading_signals,
    relative_yaw,
    shift_to_yaw_deg,
    yaw_to_columns,
)

DATA = Path(__file__).parent / "data"
# Rotations in columns of a 1024-wide panorama: none is a multiple of the
# reduced profile width's block (4) or of anything convenient.
ROTATIONS = [37, 173, 401, 613, 889, 1001]


@pytest.fixture(scope="module")
def pano() -> np.ndarray:
    bgr = cv2.imread(str(DATA / "examplepano_1024.jpg"))
    assert bgr is not None and bgr.shape == (512, 1024, 3)
    return np.ascontiguousarray(bgr[:, :, ::-1])


def synthetic_pano(seed: int, w: int = 512) -> np.ndarray:
    """A 2:1 panorama: smooth colour gradients, sky/ground split and a few random 'buildings'."""
    rng = np.random.default_rng(seed)
    h = w // 2
    x = np.linspace(0, 2 * np.pi, w, endpoint=False)[None, :, None]
    y = np.linspace(0, 1, h)[:, None, None]
    phase = rng.uniform(0, 2 * np.pi, size=(1, 1, 3))
    img = 90 + 40 * np.sin(x + phase) + 60 * (y > 0.55) + 20 * np.cos(3 * x + 2 * phase) * y
    img = np.broadcast_to(img, (h, w, 3)).copy()
    for _ in range(rng.integers(5, 10)):
        x0 = rng.integers(0, w)
        bw = rng.integers(w // 60, w // 12)
        top = rng.integers(int(0.2 * h), int(0.5 * h))
        cols = (x0 + np.arange(bw)) % w
        img[top:int(0.6 * h), cols] = rng.uniform(0, 255, size=3)
        # windows: a little texture so the building has structure inside
        img[top:int(0.6 * h):6, cols] *= 0.6
    return np.clip(img, 0, 255).astype(np.uint8)


def circ_diff(a: int, b: int, w: int) -> int:
    return int((a - b + w // 2) % w - w // 2)


def degrade(img: np.ndarray, seed: int) -> np.ndarray:
    """Global brightness change (gain and offset) plus small noise."""
    rng = np.random.default_rng(seed)
    out = img.astype(np.float32) * 0.75 + 25 + rng.normal(0, 4, img.shape)
    return np.clip(out, 0, 255).astype(np.uint8)


def test_apply_shift_rolls_left(pano):
    out = apply_shift(pano, 10)
    np.testing.assert_array_equal(out[:, 0], pano[:, 10])
    np.testing.assert_array_equal(out[:, -10], pano[:, 0])


def test_heading_signals_are_brightness_invariant(pano):
    p = heading_signals(pano)
    assert p.shape == (3, 256)
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), 1.0, atol=1e-9)
    brighter = np.clip(pano.astype(np.float32) * 0.6 + 30, 0, 255).astype(np.uint8)
    # Same signals up to quantisation of the uint8 image, hence the same heading.
    assert min(np.corrcoef(a, b)[0, 1] for a, b in zip(p, heading_signals(brighter))) > 0.99
    assert abs(circ_diff(canonical_shift(brighter), canonical_shift(pano), pano.shape[1])) <= 2


def test_heading_harmonic_turns_with_the_camera(pano):
    """A roll by k of n columns multiplies the harmonic by exp(-2j pi k / n)."""
    c0 = heading_harmonic(pano)
    assert abs(c0) > 1.0
    for k in (64, 300):   # multiples of the reduction factor 4: an exact roll of the reduced image
        c = heading_harmonic(np.roll(pano, -k, axis=1))
        assert abs(abs(c) - abs(c0)) < 1e-6 * abs(c0)
        assert abs(c - c0 * np.exp(2j * np.pi * k / pano.shape[1])) < 1e-6 * abs(c0)


def test_canonical_heading_is_continuous_under_a_small_change():
    """Two equal peaks: the argmax would pick one of them and jump to the other after a
    small change of either; the first-harmonic phase moves by about as little as the change."""
    w, h = 512, 256
    x = np.arange(w)
    base = np.full((h, w, 3), 120.0)
    for centre in (100, 300):
        base[:, np.abs(x - centre) < 20] = (200, 60, 60)
    s_base = canonical_shift(base.astype(np.uint8))
    for bump in (-1, 1):
        img = base.copy()
        img[:, np.abs(x - 100) < 20] = (200 + 8 * bump, 60, 60)  # one peak a little stronger or weaker
        # A jump between the peaks would be 200 columns; a 10 % change of one peak moves it a few degrees.
        assert abs(circ_diff(canonical_shift(img.astype(np.uint8)), s_base, w)) <= 16


@pytest.mark.parametrize("k", ROTATIONS)
def test_rotated_copies_share_canonical_image(pano, k):
    w = pano.shape[1]
    s0 = canonical_shift(pano)
    canon0 = apply_shift(pano, s0)
    for variant in (np.roll(pano, -k, axis=1), degrade(np.roll(pano, -k, axis=1), k)):
        s = canonical_shift(variant)
        assert 0 <= s < w
        # Content at column c of pano is at c - k in the rotated copy.
        assert abs(circ_diff(s, s0 - k, w)) <= 3
        canon = apply_shift(variant, s)
        # The canonical images coincide up to those few columns.
        assert abs(circ_diff(yaw_to_columns(relative_yaw(canon0, canon)[0], w), 0, w)) <= 3


@pytest.mark.parametrize("k", ROTATIONS)
def test_relative_yaw_recovers_rotation(pano, k):
    w = pano.shape[1]
    expected = shift_to_yaw_deg(-k, w)
    for variant in (np.roll(pano, -k, axis=1), degrade(np.roll(pano, -k, axis=1), 100 + k)):
        yaw, score = relative_yaw(pano, variant)
        assert abs(shift_to_yaw_deg(yaw - expected, 360)) < 1.0
        assert score > 0.9
        # The documented convention: shifting b by the yaw aligns it with a.
        aligned = apply_shift(variant, yaw_to_columns(yaw, w))
        assert abs(circ_diff(canonical_shift(aligned), canonical_shift(pano), w)) <= 3


def test_relative_yaw_consistent_with_canonical_shifts(pano):
    w = pano.shape[1]
    b = np.roll(pano, -289, axis=1)
    sa, sb = canonical_shift(pano), canonical_shift(b)
    yaw_shifted, _ = relative_yaw(apply_shift(pano, sa), apply_shift(b, sb))
    total = yaw_shifted + shift_to_yaw_deg(sb - sa, w)
    assert abs(shift_to_yaw_deg(total - relative_yaw(pano, b)[0], 360)) < 1.0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_synthetic_panoramas(seed):
    img = synthetic_pano(seed)
    w = img.shape[1]
    s0 = canonical_shift(img)
    for k in (51, 200, 377):
        rolled = degrade(np.roll(img, -k, axis=1), seed * 10 + k)
        assert abs(circ_diff(canonical_shift(rolled), s0 - k, w)) <= 3
        yaw, score = relative_yaw(img, rolled)
        assert abs(shift_to_yaw_deg(yaw - shift_to_yaw_deg(-k, w), 360)) < 1.0
        assert score > 0.8


def test_unrelated_panoramas_score_lower(pano):
    a = synthetic_pano(5, w=1024)
    _, same = relative_yaw(pano, np.roll(pano, 300, axis=1))
    _, other = relative_yaw(pano, a)
    assert same > other + 0.3


def test_yaw_helpers():
    assert shift_to_yaw_deg(256, 1024) == 90.0
    assert shift_to_yaw_deg(-256, 1024) == -90.0
    assert shift_to_yaw_deg(768, 1024) == -90.0
    assert shift_to_yaw_deg(512, 1024) == 180.0
    assert yaw_to_columns(90.0, 1024) == 256
    assert yaw_to_columns(-90.0, 1024) == 768
    assert yaw_to_columns(shift_to_yaw_deg(-37, 1024), 1024) == 1024 - 37


def test_bad_input():
    with pytest.raises(InputError):
        canonical_shift(np.zeros((10, 20), np.uint8))
    with pytest.raises(InputError):
        relative_yaw(np.zeros((64, 128, 3), np.uint8), np.zeros((64, 64, 3), np.uint8))


def test_featureless_image_has_zero_shift():
    assert canonical_shift(np.full((64, 128, 3), 128, np.uint8)) == 0
