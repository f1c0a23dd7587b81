import os
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

import engine.descriptors as registry
from engine.descriptors.base import Descriptors
from engine.descriptors.cache import DescriptorCache, cache_key
from engine.descriptors.efficientnet import sector_vlad, sector_weights
from engine.errors import Cancelled, InputError
from engine.shift import apply_shift, canonical_shift

DATA = Path(__file__).parent / "data"
SMALL = dict(input_height=128, batch_size=4)   # 128 x 256 input: fast, 8 x 16 local features


# -- registry -----------------------------------------------------------------------
def test_registry_names_and_errors():
    names = registry.names()
    assert names[0] == registry.DEFAULT_DESCRIPTOR == "effnet-vlad"
    assert {"anyloc-vlad", "anyloc-gem"} <= set(names)
    with pytest.raises(InputError) as err:
        registry.get("no-such-model")
    assert "effnet-vlad" in str(err.value) and "anyloc-vlad" in str(err.value)
    with pytest.raises(InputError):
        registry.defaults_for("no-such-model")


def test_defaults_for_effnet():
    d = registry.defaults_for("effnet-vlad")
    assert 0.0 < d["loop_sim_th"] < d["node_sim_th"] < 1.0
    model = registry.get("effnet-vlad", **SMALL)
    assert model.name == "effnet-vlad" and model.defaults == d


def test_bad_options():
    with pytest.raises(InputError):
        registry.get("effnet-vlad", input_height=100)
    with pytest.raises(InputError):
        registry.get("effnet-vlad", not_an_option=1)
    with pytest.raises(InputError):
        registry.get("effnet-vlad", vocabulary=np.ones((4, 3)))
    with pytest.raises(InputError):
        registry.get("effnet-vlad", layout="grid")
    with pytest.raises(InputError):
        registry.get("effnet-vlad", layout="sectors", sectors=1)


def test_layout_is_part_of_the_settings():
    plain = registry.get("effnet-vlad", layout="global", **SMALL)
    sectors = registry.get("effnet-vlad", layout="sectors", **SMALL)
    three = registry.get("effnet-vlad", layout="sectors", sectors=3, **SMALL)
    assert len({str(m.settings()) for m in (plain, sectors, three)}) == 3
    assert plain.dimension == 32 * plain.channels
    assert sectors.dimension == 5 * 32 * sectors.channels and three.dimension == 4 * 32 * three.channels
    # Its own calibrated thresholds; the class (registry.defaults_for) keeps the default layout's.
    assert sectors.defaults["loop_sim_th"] < plain.defaults["loop_sim_th"]
    assert plain.defaults == registry.defaults_for("effnet-vlad")


def unit_rows(rng, n: int, c: int) -> np.ndarray:
    x = rng.normal(size=(n, c)).astype(np.float32)
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def test_sector_vlad_turns_with_the_feature_map():
    """Rolling the feature map by one sector (90 degrees) moves each sector's block to its
    neighbour and leaves the global part unchanged: the layout is heading-sensitive,
    exactly as a camera turn."""
    rng = np.random.default_rng(0)
    rows, width, k, c = 8, 16, 6, 10
    feats = unit_rows(rng, rows * width, c)
    centres = unit_rows(rng, k, c)
    v = sector_vlad(feats, centres, width, 4)
    rolled = np.roll(feats.reshape(rows, width, c), -width // 4, axis=1).reshape(-1, c)  # content moves left
    r = sector_vlad(rolled, centres, width, 4)
    assert v.shape == r.shape == (5 * k * c,)
    np.testing.assert_allclose(np.linalg.norm(v), 1.0, atol=1e-6)
    gv, gr = v[:k * c], r[:k * c]
    np.testing.assert_allclose(gv, gr, atol=1e-6)
    sv, sr = v[k * c:].reshape(4, -1), r[k * c:].reshape(4, -1)
    np.testing.assert_allclose(sr, np.roll(sv, -1, axis=0), atol=1e-6)   # new sector s = old s + 1
    assert not np.allclose(sv, sr, atol=1e-3)   # and so the rolled copy is another vector


def test_sector_windows_overlap_and_cover_every_column():
    w = sector_weights(16, 4)
    assert w.shape == (4, 16)
    assert np.all(w.sum(axis=0) > 0.5)            # no column is left out
    assert np.all((w > 0.05).sum(axis=0) >= 2)    # every column is shared by two sectors
    np.testing.assert_allclose(w[1], np.roll(w[0], 4), atol=1e-6)   # sectors are turned copies


# -- images ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def full() -> np.ndarray:
    return np.ascontiguousarray(cv2.imread(str(DATA / "examplepano_1024.jpg"))[:, :, ::-1])


def small(img: np.ndarray) -> np.ndarray:
    return cv2.resize(img, (256, 128), interpolation=cv2.INTER_AREA)


@pytest.fixture(scope="module")
def pano(full) -> np.ndarray:
    return small(full)


def degrade(img: np.ndarray, seed: int) -> np.ndarray:
    """Brighter and noisy at full resolution, then downscaled as a real frame would be."""
    rng = np.random.default_rng(seed)
    return small(np.clip(img * 0.8 + 20 + rng.normal(0, 4, img.shape), 0, 255).astype(np.uint8))


def zoomed(img: np.ndarray, zoom: float) -> np.ndarray:
    """Central crop resized back: a few steps forward, roughly."""
    h, w = img.shape[:2]
    ch, cw = int(h / zoom), int(w / zoom)
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    return cv2.resize(img[y0:y0 + ch, x0:x0 + cw], (w, h), interpolation=cv2.INTER_AREA)


def city(seed: int) -> np.ndarray:
    """An unrelated synthetic panorama: sky, road, coloured blocks with windows."""
    rng = np.random.default_rng(seed)
    img = np.zeros((128, 256, 3), np.float32)
    img[:60] = (120, 160, 230)
    img[60:] = (70, 70, 75)
    for _ in range(12):
        x0, bw, top = rng.integers(0, 256), rng.integers(8, 30), rng.integers(15, 50)
        cols = (x0 + np.arange(bw)) % 256
        img[top:80, cols] = rng.uniform(40, 220, 3)
        img[top:80:5, cols] *= 0.5
    return np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def scene(pano, full):
    """Same place: the panorama, a zoomed-in copy, a relit copy. Different: two city panoramas, the pano upside down."""
    return {
        "pano": pano,
        "zoom": zoomed(pano, 1.08),
        "relit": degrade(full, 1),
        "city1": city(1),
        "city2": city(2),
        "flipped": np.ascontiguousarray(pano[::-1]),
    }


@pytest.fixture(scope="module")
def described(scene):
    model = registry.get("effnet-vlad", **SMALL)
    calls = []
    vecs = model.describe(iter(scene.values()), len(scene), progress=lambda *a: calls.append(a))
    return model, dict(zip(scene, vecs)), vecs, calls


def test_effnet_rows_are_unit_float32(described):
    model, _, vecs, calls = described
    assert vecs.dtype == np.float32
    assert model.layout == "global"   # the default: plain VLAD of the whole panorama
    assert vecs.shape == (6, 32 * model.channels) == (6, model.dimension)
    np.testing.assert_allclose(np.linalg.norm(vecs, axis=1), 1.0, atol=1e-5)
    assert model.vocabulary.shape == (32, model.channels)
    # Progress per batch of 4: after 4, then after 6, stage "describe".
    assert all(stage == "describe" for _, _, stage in calls)
    assert calls[-1][:2] == (6, 6)
    assert (4, 6, "describe") in calls


def test_same_place_more_similar_than_different(described):
    _, v, _, _ = described
    same = [float(v["pano"] @ v[k]) for k in ("zoom", "relit")]
    different = [float(v["pano"] @ v[k]) for k in ("city1", "city2", "flipped")]
    assert min(same) > max(different) + 0.15


def test_effnet_deterministic(scene, described):
    _, _, first, _ = described
    again = registry.get("effnet-vlad", **SMALL).describe(iter(scene.values()), len(scene))
    np.testing.assert_allclose(again, first, atol=1e-5)


def test_reused_vocabulary(scene, described):
    model, _, first, _ = described
    reuse = registry.get("effnet-vlad", vocabulary=model.vocabulary, **SMALL)
    assert reuse.settings() != model.settings()
    # With the vocabulary given, one image alone is described as in the full run.
    alone = reuse.describe(iter([scene["zoom"]]), 1)
    np.testing.assert_allclose(alone[0], first[1], atol=1e-4)


def test_cancel_between_batches(scene):
    model = registry.get("effnet-vlad", input_height=128, batch_size=2)
    stop = threading.Event()
    calls = []

    def progress(done, total, stage):
        calls.append(done)
        if done >= 2:
            stop.set()

    with pytest.raises(Cancelled):
        model.describe(iter(scene.values()), len(scene), progress=progress, cancel=stop)
    assert max(calls) < len(scene)


def test_shift_raises_similarity_of_rotated_copy(pano, full):
    # The same place seen after a yaw turn, a little brighter and noisy.
    w = full.shape[1]
    turned = degrade(np.roll(full, -int(w * 0.37), axis=1), 7)
    images = [pano, turned, city(3), city(4), np.ascontiguousarray(pano[::-1])]
    shifted_images = [apply_shift(im, canonical_shift(im)) for im in images]
    gain = {}
    for layout in ("global", "sectors"):
        plain = registry.get("effnet-vlad", layout=layout, **SMALL).describe(iter(images), 5)
        shifted = registry.get("effnet-vlad", layout=layout, **SMALL).describe(iter(shifted_images), 5)
        gain[layout] = float(shifted[0] @ shifted[1]) - float(plain[0] @ plain[1])
        # After the shift the turned copy is far more similar than any other place.
        assert float(shifted[0] @ shifted[1]) > float(np.max(shifted[0] @ shifted[2:].T)) + 0.2
    # Plain VLAD pools away where things are, so the shift changes less for it (measured
    # +0.13, at input height 224 +0.03); the sector layout is heading-sensitive and the
    # shift matters (measured +0.34, at 224 +0.18).
    assert gain["sectors"] > 0.2
    assert gain["sectors"] > gain["global"] + 0.1


def test_phases_keep_a_real_panorama_under_a_half_stride_roll(full):
    # The network is not shift-invariant below its stride (16 input pixels); pooling the
    # features of rolls within one stride is. A half-stride roll of the real panorama moves
    # the pooled descriptor less than the plain one, with the same vocabulary.
    img = cv2.resize(full, (512, 256), interpolation=cv2.INTER_AREA)   # 2x the network input
    half_stride = 16                                                    # 8 input pixels
    moved = {}
    for phases in (1, 2):
        vocab = registry.get("effnet-vlad", phases=phases, **SMALL)
        vocab.describe(iter([img]), 1)
        fixed = registry.get("effnet-vlad", phases=phases, vocabulary=vocab.vocabulary, **SMALL)
        a, b = fixed.describe(iter([img, np.roll(img, half_stride, axis=1)]), 2)
        moved[phases] = 1.0 - float(a @ b)
    assert moved[2] < 0.5 * moved[1]
    two = registry.get("effnet-vlad", phases=2, **SMALL)
    assert two.dimension == registry.get("effnet-vlad", **SMALL).dimension
    assert two.settings()["phases"] == 2 and "phases" not in registry.get("effnet-vlad", **SMALL).settings()
    with pytest.raises(InputError, match="phases must be one of 1, 2, 4, 8, 16, got 3"):
        registry.get("effnet-vlad", phases=3)


def test_photometric_standardise_ignores_exposure_and_white_balance(full):
    # Another exposure and white balance of the same real panorama (a gain and an offset per
    # channel, kept inside 0-255 so nothing clips) is the same frame to the network once each
    # frame's channels are standardised; to the plain input it is not. The network's local
    # features say it directly; the pooled descriptor follows (less exactly: a one-frame
    # vocabulary of 32 words over 128 features amplifies small changes).
    img = cv2.resize(full, (256, 128), interpolation=cv2.INTER_AREA).astype(np.float32)
    relit = np.clip(img * np.array([0.55, 0.7, 0.45]) + np.array([90.0, 60.0, 110.0]), 0, 255)
    frames = [img.astype(np.uint8), relit.round().astype(np.uint8)]
    local, pooled = {}, {}
    for photometric in ("none", "standardise"):
        vocab = registry.get("effnet-vlad", photometric=photometric, **SMALL)
        f = vocab.local_features(frames)
        local[photometric] = float((f[0] * f[1]).sum(-1).median())
        vocab.describe(iter(frames[:1]), 1)
        fixed = registry.get("effnet-vlad", photometric=photometric, vocabulary=vocab.vocabulary, **SMALL)
        a, b = fixed.describe(iter(frames), 2)
        pooled[photometric] = float(a @ b)
    assert local["standardise"] > 0.99 > local["none"]
    assert pooled["standardise"] > pooled["none"]
    assert registry.get("effnet-vlad", photometric="standardise", **SMALL).settings()["photometric"] == "standardise"
    assert "photometric" not in registry.get("effnet-vlad", **SMALL).settings()   # old caches stay valid
    with pytest.raises(InputError, match="photometric must be one of none, standardise, got 'auto'"):
        registry.get("effnet-vlad", photometric="auto")


def test_empty_input():
    model = registry.get("effnet-vlad", **SMALL)
    out = model.describe(iter([]), 0)
    assert out.shape == (0, model.dimension)


def test_bad_image():
    model = registry.get("effnet-vlad", **SMALL)
    with pytest.raises(InputError):
        model.describe(iter([np.zeros((64, 128), np.uint8)]), 1)


# -- cache -----------------------------------------------------------------------------
def _descs(d: int, n: int = 3, seed: int = 0) -> Descriptors:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, d)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return Descriptors(
        stamps=np.arange(n, dtype=np.float64) * 1.5,
        frames=np.arange(n, dtype=np.int64) * 30,
        shifts=np.array([5, 0, 17][:n], np.int64),
        vectors=v,
        meta={"descriptor": "effnet-vlad", "shift": True},
    )


def test_cache_round_trip(tmp_path):
    cache = DescriptorCache(tmp_path / "cache")
    src = tmp_path / "video.mp4"
    src.write_bytes(b"x" * 100)
    key = cache_key(src, {"interval": 1.0, "topic": None}, {"shift": True, "name": "effnet-vlad"})
    assert len(key) == 40 and cache.load(key) is None
    d = _descs(64)
    cache.store(key, d)
    back = cache.load(key)
    np.testing.assert_array_equal(back.vectors, d.vectors)
    np.testing.assert_array_equal(back.shifts, d.shifts)
    np.testing.assert_array_equal(back.stamps, d.stamps)
    assert back.meta == d.meta
    cache.clear()
    assert cache.load(key) is None


def test_cache_key_changes(tmp_path):
    src = tmp_path / "video.mp4"
    src.write_bytes(b"x" * 100)
    sampling = {"interval": 1.0, "topic": None}
    settings = {"shift": True, "name": "effnet-vlad", "input_height": 224}
    key = cache_key(src, sampling, settings)
    assert cache_key(src, sampling, settings) == key
    assert cache_key(src, {"interval": 0.5, "topic": None}, settings) != key
    assert cache_key(src, sampling, {**settings, "shift": False}) != key
    assert cache_key(src, sampling, {**settings, "input_height": 256}) != key
    st = src.stat()
    os.utime(src, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    assert cache_key(src, sampling, settings) != key
    touched = cache_key(src, sampling, settings)
    src.write_bytes(b"y" * 101)
    os.utime(src, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    assert cache_key(src, sampling, settings) != touched
    # A folder input changes key when a file inside it changes.
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "a.jpg").write_bytes(b"1")
    k1 = cache_key(folder, sampling, settings)
    (folder / "b.jpg").write_bytes(b"2")
    assert cache_key(folder, sampling, settings) != k1


def test_corrupt_cache_file_is_ignored(tmp_path):
    cache = DescriptorCache(tmp_path)
    key = "0" * 40
    cache.store(key, _descs(8))
    path = cache.path_for(key)
    path.write_bytes(b"not a zip file at all")
    assert cache.load(key) is None
    assert not path.exists()


def test_long_vectors_stored_as_float16(tmp_path):
    cache = DescriptorCache(tmp_path)
    d = _descs(16384, n=2)
    path = cache.store("a" * 40, d)
    with np.load(path) as z:
        assert z["descriptors"].dtype == np.float16
    back = cache.load("a" * 40)
    assert back.vectors.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(back.vectors, axis=1), 1.0, atol=1e-5)
    assert np.all(np.sum(back.vectors * d.vectors, axis=1) > 0.999)


def test_default_root_from_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("PANOTOPO_CACHE", str(tmp_path / "elsewhere"))
    assert DescriptorCache().root == tmp_path / "elsewhere"
