import numpy as np
import pytest

from engine.descriptors.vlad import kmeans_cosine, l2_normalize, vlad, vlad_many
from engine.errors import InputError


# Centres c0 = (1, 0), c1 = (0, 1). Features (unit):
#   f1 = (0.6, 0.8): dots 0.6 / 0.8 -> cluster 1, residual (0.6, -0.2)
#   f2 = (0.8, 0.6): dots 0.8 / 0.6 -> cluster 0, residual (-0.2, 0.6)
#   f3 = (1.0, 0.0): cluster 0, residual (0, 0)
# Cluster 0 sum (-0.2, 0.6), norm sqrt(0.4) -> (-1, 3) / sqrt(10)
# Cluster 1 sum ( 0.6,-0.2), norm sqrt(0.4) -> ( 3,-1) / sqrt(10)
# Concatenated norm is sqrt(2) -> (-1, 3, 3, -1) / sqrt(20).
CENTERS = np.array([[1.0, 0.0], [0.0, 1.0]], dtype=np.float32)
FEATURES = np.array([[0.6, 0.8], [0.8, 0.6], [1.0, 0.0]], dtype=np.float32)


def test_vlad_hand_example():
    v = vlad(FEATURES, CENTERS)
    assert v.dtype == np.float32 and v.shape == (4,)
    expected = np.array([-1.0, 3.0, 3.0, -1.0]) / np.sqrt(20.0)
    np.testing.assert_allclose(v, expected, atol=1e-6)


def test_vlad_empty_cluster_stays_zero():
    # Only f2 and f3 (both cluster 0): block 0 = (-1, 3)/sqrt(10), block 1 = 0; total norm 1.
    v = vlad(FEATURES[1:], CENTERS)
    expected = np.array([-1.0, 3.0, 0.0, 0.0]) / np.sqrt(10.0)
    np.testing.assert_allclose(v, expected, atol=1e-6)


def test_vlad_many_rows_match_single():
    sets = [FEATURES, FEATURES[1:], FEATURES[:1]]
    many = vlad_many(sets, CENTERS)
    assert many.shape == (3, 4)
    for row, f in zip(many, sets):
        np.testing.assert_allclose(row, vlad(f, CENTERS), atol=1e-7)
    # f1 alone: cluster 1 residual (0.6, -0.2) -> (3, -1)/sqrt(10), block 0 empty.
    np.testing.assert_allclose(many[2], np.array([0.0, 0.0, 3.0, -1.0]) / np.sqrt(10.0), atol=1e-6)


def test_vlad_rejects_mismatched_shapes():
    with pytest.raises(InputError):
        vlad(np.ones((3, 3), np.float32), CENTERS)


def test_l2_normalize():
    x = np.array([[3.0, 4.0], [0.0, 0.0]])
    y = l2_normalize(x)
    np.testing.assert_allclose(y, [[0.6, 0.8], [0.0, 0.0]])


def _clusters(rng, k=5, c=16, per=300, spread=0.05):
    true = l2_normalize(rng.normal(size=(k, c)))
    pts = np.repeat(true, per, axis=0) + spread * rng.normal(size=(k * per, c))
    return true, l2_normalize(pts).astype(np.float32)


def test_kmeans_recovers_separated_clusters():
    rng = np.random.default_rng(3)
    true, pts = _clusters(rng)
    centers = kmeans_cosine(pts, 5, seed=0)
    assert centers.shape == (5, 16) and centers.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(centers, axis=1), 1.0, atol=1e-5)
    # Each true centre has exactly one estimated centre very close to it.
    sims = true @ centers.T
    assert np.all(sims.max(axis=1) > 0.99)
    assert sorted(np.argmax(sims, axis=1).tolist()) == list(range(5))


def test_kmeans_deterministic_and_chunked(monkeypatch):
    import engine.descriptors.vlad as vlad_mod

    rng = np.random.default_rng(4)
    _, pts = _clusters(rng, k=4, c=8, per=200)
    a = kmeans_cosine(pts, 4, seed=7)
    b = kmeans_cosine(pts, 4, seed=7)
    np.testing.assert_array_equal(a, b)
    # Chunked processing gives the same centres as one chunk.
    monkeypatch.setattr(vlad_mod, "CHUNK", 37)
    c = kmeans_cosine(pts, 4, seed=7)
    np.testing.assert_allclose(a, c, atol=1e-5)


def test_kmeans_handles_duplicates_and_too_few():
    # Many identical rows: k-means must still return k unit centres (empty clusters re-seeded).
    pts = np.array([[1.0, 0.0]] * 50 + [[0.0, 1.0]] * 50 + [[0.7071, 0.7071]], dtype=np.float32)
    centers = kmeans_cosine(pts, 3, seed=1)
    assert centers.shape == (3, 2)
    assert np.all(np.isfinite(centers))
    with pytest.raises(InputError):
        kmeans_cosine(pts[:2], 3)
