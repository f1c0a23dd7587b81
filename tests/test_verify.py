"""Yaw-aligned verification: column signatures, circular alignment, yaw convention, .npz key."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from engine.descriptors.base import Descriptors
from engine.errors import InputError
from engine.shift import apply_shift, canonical_shift, relative_yaw
from engine.verify import COLUMN_WIDTH, align, column_features, pair_yaw

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def pano() -> np.ndarray:
    bgr = cv2.imread(str(DATA / "examplepano_1024.jpg"))
    small = cv2.resize(bgr, (512, 256), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(small[:, :, ::-1])


def test_column_features_shape_and_normalisation(pano):
    c = column_features(pano)
    assert c.dtype == np.float16 and c.shape[0] == COLUMN_WIDTH and c.ndim == 2
    signals = c.astype(np.float64).T
    active = np.linalg.norm(signals, axis=1) > 0.5
    assert active.sum() >= signals.shape[0] // 2
    np.testing.assert_allclose(signals[active].mean(axis=1), 0.0, atol=1e-2)
    np.testing.assert_allclose(np.linalg.norm(signals[active], axis=1), 1.0, atol=1e-2)


@pytest.mark.parametrize("roll_cols", [0, 44, 200, 333])
def test_align_recovers_a_roll(pano, roll_cols):
    w = pano.shape[1]
    a = column_features(pano)
    b = column_features(np.roll(pano, roll_cols, axis=1))   # content moves right by roll_cols
    score, shift, margin = align(a[None], b[None])
    expected = roll_cols * COLUMN_WIDTH / w
    d = (shift[0] - expected + COLUMN_WIDTH / 2) % COLUMN_WIDTH - COLUMN_WIDTH / 2
    assert abs(d) <= 1.0
    assert score[0] > 0.9
    assert margin[0] > 0.05


def test_unrelated_panorama_scores_lower(pano):
    rng = np.random.default_rng(1)
    other = cv2.GaussianBlur(rng.integers(0, 255, pano.shape, dtype=np.uint8), (0, 0), 4)
    a = column_features(pano)
    same, _, _ = align(a[None], column_features(np.roll(pano, 100, axis=1))[None])
    diff, _, _ = align(a[None], column_features(other)[None])
    assert same[0] > diff[0] + 0.3


@pytest.mark.parametrize("k", [37, 150, 401])
def test_pair_yaw_follows_the_shift_module_convention(pano, k):
    """Yaw from shifted frames plus panorama shifts equals relative_yaw of the originals."""
    w = pano.shape[1]
    a, b = pano, np.roll(pano, -k, axis=1)
    sa, sb = canonical_shift(a), canonical_shift(b)
    ca = column_features(apply_shift(a, sa))
    cb = column_features(apply_shift(b, sb))
    _, shift, _ = align(ca[None], cb[None])
    yaw = pair_yaw(shift, COLUMN_WIDTH, np.array([sa]), np.array([sb]), w)[0]
    truth, _ = relative_yaw(a, b)
    err = (yaw - truth + 180.0) % 360.0 - 180.0
    assert abs(err) <= 2 * 360.0 / COLUMN_WIDTH
    assert -180.0 < yaw <= 180.0


def test_align_rejects_mismatched_shapes():
    with pytest.raises(InputError):
        align(np.zeros((2, 128, 32)), np.zeros((2, 64, 32)))


def test_npz_columns_key_is_optional(tmp_path, pano):
    n = 3
    base = dict(stamps=np.arange(n, dtype=float), frames=np.arange(n), shifts=np.zeros(n, np.int64),
                vectors=np.eye(n, 4, dtype=np.float32))
    cols = np.stack([column_features(np.roll(pano, 10 * i, axis=1)) for i in range(n)])
    with_cols = Descriptors(**base, meta={"descriptor": "x"}, columns=cols)
    with_cols.save(tmp_path / "a.npz")
    back = Descriptors.load(tmp_path / "a.npz")
    assert back.columns is not None and back.columns.dtype == np.float16
    np.testing.assert_array_equal(back.columns, cols)
    # A file written before the key existed (only the contract's keys) still loads.
    np.savez(tmp_path / "old.npz", stamps=base["stamps"], frames=base["frames"], shifts=base["shifts"],
             descriptors=base["vectors"], meta=np.array("{}"))
    old = Descriptors.load(tmp_path / "old.npz")
    assert old.columns is None and len(old) == n
    # Wrong shape is a clear input error.
    np.savez(tmp_path / "bad.npz", stamps=base["stamps"], frames=base["frames"], shifts=base["shifts"],
             descriptors=base["vectors"], meta=np.array("{}"), columns=np.zeros((n + 1, 4, 2), np.float16))
    with pytest.raises(InputError):
        Descriptors.load(tmp_path / "bad.npz")


def _warped(pano: np.ndarray, amplitude_cols: float, roll_px: int = 0) -> np.ndarray:
    """pano with content moved right by amplitude * sin(angle) signature columns (as a
    step forwards moves the side walls backwards), then rolled by roll_px pixels."""
    h, w = pano.shape[:2]
    x = np.arange(w, dtype=np.float32)
    moved = amplitude_cols * w / COLUMN_WIDTH * np.sin(2 * np.pi * x / w)
    map_x = np.tile((x - moved) % w, (h, 1)).astype(np.float32)
    map_y = np.repeat(np.arange(h, dtype=np.float32)[:, None], w, axis=1)
    out = cv2.remap(pano, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    return np.roll(out, roll_px, axis=1)


@pytest.mark.parametrize("amplitude", [0.0, 2.0, 4.0])
def test_local_shifts_measure_how_far_each_part_moved_beyond_the_roll(pano, amplitude):
    from engine.verify import LOCAL_STEP, align_nodes, displacement, local_shifts

    cols = np.stack([column_features(pano), column_features(_warped(pano, amplitude, roll_px=92))])
    _, shift = align_nodes(cols, np.array([0]), np.array([1]))
    local = local_shifts(cols, np.array([0]), np.array([1]), shift)[0]
    centres = np.arange(0, COLUMN_WIDTH, LOCAL_STEP)
    expected = amplitude * np.sin(2 * np.pi * centres / COLUMN_WIDTH)
    # The global shift absorbs the mean; the rest is where each window moved.
    assert np.median(np.abs(local - local.mean() - expected)) < 0.75
    assert displacement(local[None])[0] == pytest.approx(amplitude, abs=0.75)
