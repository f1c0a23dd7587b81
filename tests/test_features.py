from pathlib import Path

import cv2
import numpy as np
import pytest

from engine.descriptors.base import Descriptors
from engine.errors import InputError
from engine.features import BAND, FEATURES_MAX, WORK_WIDTH, FeatureTable, LocalFeatures, extract
from engine.frames import Frame
from engine.pipeline import DescribeSettings, describe_frames
from engine.shift import apply_shift

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def pano():
    return cv2.cvtColor(cv2.imread(str(DATA / "examplepano_1024.jpg")), cv2.COLOR_BGR2RGB)


@pytest.fixture(scope="module")
def feats(pano):
    return extract(pano)


def test_features_of_a_real_panorama_lie_in_the_band_and_cover_the_seam(feats):
    assert feats.uv.dtype == np.float32 and feats.desc.dtype == np.uint8
    assert feats.desc.shape == (len(feats), 128)
    assert 100 < len(feats) <= FEATURES_MAX
    u, v = feats.uv[:, 0], feats.uv[:, 1]
    assert np.all((u >= 0) & (u < 1)) and np.all((v >= 0) & (v < 1))
    # Nothing from the poles (the nadir shows the camera's carrier); a pixel of slack.
    assert v.min() >= BAND[0] - 0.01 and v.max() <= BAND[1] + 0.01
    # The panorama wraps: the seam is not a border where keypoints are lost.
    assert np.count_nonzero((u < 0.02) | (u > 0.98)) > 0


def test_rolling_the_frame_rolls_the_features(pano, feats):
    k = 300
    rolled = extract(np.roll(pano, -k, axis=1))
    moved = (feats.uv[:, 0] - k / pano.shape[1]) % 1.0
    # Most keypoints come back at the rolled place (the downscaled grid is not rolled by a
    # whole number of its pixels, so a few weak ones change).
    d = np.abs(moved[:, None] - rolled.uv[None, :, 0])
    d = np.minimum(d, 1 - d) + np.abs(feats.uv[:, None, 1] - rolled.uv[None, :, 1])
    assert np.mean(d.min(axis=1) < 2 / WORK_WIDTH) > 0.7


def test_bad_image_gives_one_clear_line():
    with pytest.raises(InputError, match="H x W x 3"):
        extract(np.zeros((10, 20), np.uint8))


def test_a_flat_frame_has_no_features():
    f = extract(np.full((128, 256, 3), 90, np.uint8))
    assert len(f) == 0 and f.uv.shape == (0, 2) and f.desc.shape == (0, 128)


def _descs(n, features):
    return Descriptors(stamps=np.arange(n, dtype=np.float64), frames=np.arange(n), shifts=np.zeros(n, np.int64),
                       vectors=np.eye(n, 4, dtype=np.float32), meta={"descriptor": "x"}, features=features)


def test_feature_table_round_trips_through_a_descriptors_file(tmp_path, pano, feats):
    empty = LocalFeatures(np.zeros((0, 2), np.float32), np.zeros((0, 128), np.uint8))
    table = FeatureTable.from_list([feats, empty, extract(pano[:, ::-1])])
    path = tmp_path / "d.npz"
    _descs(3, table).save(path)
    back = Descriptors.load(path).features
    assert len(back) == 3 and len(back.of(1)) == 0
    for i in (0, 2):
        a, b = table.of(i), back.of(i)
        assert np.array_equal(a.desc, b.desc)
        assert np.abs(a.uv - b.uv).max() < 1e-3 and np.all(b.uv < 1.0)
    picked = back.subset([2, 0])       # e.g. the node rows of a map
    assert len(picked) == 2 and np.array_equal(picked.of(0).desc, back.of(2).desc)


def test_files_without_features_still_load(tmp_path):
    path = tmp_path / "old.npz"
    _descs(2, None).save(path)
    with np.load(path) as z:
        assert not any(k.startswith("feat_") for k in z.files)
    assert Descriptors.load(path).features is None


@pytest.mark.parametrize("change", ["drop_desc", "uv_shape", "offsets_short", "offsets_end"])
def test_malformed_features_give_one_clear_line(tmp_path, feats, change):
    arrays = FeatureTable.from_list([feats, feats]).to_arrays()
    if change == "drop_desc":
        del arrays["feat_desc"]
    elif change == "uv_shape":
        arrays["feat_uv"] = arrays["feat_uv"][:, :1]
    elif change == "offsets_short":
        arrays["feat_offsets"] = arrays["feat_offsets"][:2]
    else:
        arrays["feat_offsets"][-1] += 5
    path = tmp_path / "bad.npz"
    d = _descs(2, None)
    np.savez(path, stamps=d.stamps, frames=d.frames, shifts=d.shifts, descriptors=d.vectors,
             meta=np.array("{}"), **arrays)
    with pytest.raises(InputError) as err:
        Descriptors.load(path)
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg and "local feature" in msg


def test_describe_keeps_the_features_of_each_shifted_frame(pano):
    small = cv2.resize(pano, (512, 256), interpolation=cv2.INTER_AREA)
    frames = [Frame(i, float(i), np.roll(small, 97 * i, axis=1)) for i in range(3)]
    settings = DescribeSettings(options={"input_height": 128, "batch_size": 4})
    descs = describe_frames(frames, 3, settings)
    assert descs.features is not None and len(descs.features) == 3
    for i, f in enumerate(frames):
        want = extract(apply_shift(f.rgb, int(descs.shifts[i])))
        got = descs.features.of(i)
        assert np.array_equal(got.desc, want.desc) and np.abs(got.uv - want.uv).max() < 1e-3
