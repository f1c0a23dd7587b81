"""engine.retrieval: nearest distant rows, backgrounds and diagonal support without n x n arrays."""

from __future__ import annotations

import numpy as np
import pytest

from engine import retrieval as R


def _unit(x: np.ndarray) -> np.ndarray:
    return (x / np.linalg.norm(x, axis=1, keepdims=True)).astype(np.float32)


def _random(n: int, d: int, seed: int = 0) -> np.ndarray:
    return _unit(np.random.default_rng(seed).standard_normal((n, d)))


def _brute(v: np.ndarray, k: int, exclude: int):
    """Independent reference: full matrix, loop per row, sorted by similarity."""
    n = v.shape[0]
    sims = v.astype(np.float64) @ v.T.astype(np.float64)
    idx = np.full((n, k), -1)
    for i in range(n):
        cand = [j for j in range(n) if abs(i - j) > exclude]
        cand.sort(key=lambda j: -sims[i, j])
        idx[i, :len(cand[:k])] = cand[:k]
    return idx


def _walk_with_revisits(n: int = 3000, d: int = 64, seed: int = 0):
    """A smooth walk; rows [2000, 2200) revisit rows [300, 500) forward and rows
    [2400, 2600) revisit rows [1000, 1200) in reverse, as noisy copies (cos ~0.9)."""
    from benchmarks.harness import random_walk_descriptors

    rng = np.random.default_rng(seed)
    x = random_walk_descriptors(n, d, seed, revisit_share=0.0)[0]
    fwd = np.arange(300, 500)
    rev = np.arange(1199, 999, -1)
    x[2000:2200] = _unit(x[fwd] + 0.45 * rng.standard_normal((200, d)) / np.sqrt(d))
    x[2400:2600] = _unit(x[rev] + 0.45 * rng.standard_normal((200, d)) / np.sqrt(d))
    origin = np.full(n, -1)
    origin[2000:2200] = fwd
    origin[2400:2600] = rev
    return x, origin


def test_exact_blocked_search_equals_brute_force():
    v = _random(300, 16, seed=3)
    got = R.nearest(v, 7, 4, method="exact", block_rows=37)
    want = _brute(v, 7, 4)
    np.testing.assert_array_equal(got.index, want)
    np.testing.assert_allclose(got.sim, np.take_along_axis(v @ v.T, want, axis=1), atol=1e-5)
    assert np.all(np.diff(got.sim, axis=1) <= 1e-7)   # best first


@pytest.mark.parametrize("block_rows", [1, 13, 64, 1000])
def test_block_size_does_not_change_the_result(block_rows):
    v = _random(200, 24, seed=1)
    ref = R.nearest(v, 5, 3, method="exact", block_rows=200)
    got = R.nearest(v, 5, 3, method="exact", block_rows=block_rows)
    np.testing.assert_array_equal(got.index, ref.index)
    np.testing.assert_allclose(got.sim, ref.sim, atol=1e-6)   # BLAS may round a 1-row block differently


@pytest.mark.parametrize("method", ["exact", "approximate"])
def test_temporal_neighbours_are_never_returned(method):
    v, _ = _walk_with_revisits()
    neigh = R.nearest(v, 10, 5, method=method)
    rows = np.arange(v.shape[0])[:, None]
    ok = neigh.index >= 0
    assert np.all(np.abs(neigh.index - rows)[ok] > 5)


def test_rows_with_too_few_distant_rows_are_padded():
    v = _random(12, 8)
    neigh = R.nearest(v, 10, 4, method="exact")
    # Row 6 has rows 0, 1 and 11 outside |i - j| <= 4: three found, seven padded.
    assert np.sum(neigh.index[6] >= 0) == 3
    assert np.all(neigh.index[6, 3:] == -1) and np.all(np.isnan(neigh.sim[6, 3:]))


def test_a_planted_revisit_is_among_the_neighbours():
    v = _random(2000, 128, seed=5)
    v[1500] = _unit(v[200:201] + 0.5 * np.random.default_rng(9).standard_normal((1, 128)) / np.sqrt(128))[0]
    for method in ("exact", "approximate"):
        neigh = R.nearest(v, 5, 5, method=method)
        assert 200 in neigh.index[1500]
        assert 1500 in neigh.index[200]


def test_approximate_search_finds_most_planted_revisits():
    # Bound 0.9: the inverted file probes NPROBE cells; a revisit (cos ~0.9) falls in a
    # cell next to its original almost always.
    v, origin = _walk_with_revisits()
    neigh = R.nearest(v, 10, 5, method="approximate")
    rows = np.flatnonzero(origin >= 0)
    found = np.mean([origin[i] in neigh.index[i] for i in rows])
    assert found >= 0.9


def test_diagonal_support_is_high_along_planted_stretches_and_low_elsewhere():
    v, origin = _walk_with_revisits()
    stats = R.background(v, 5)
    a = np.array([400, 1100])       # middle of the forward and of the reverse stretch
    b = np.array([2100, 2499])
    fwd, n_fwd = R.diagonal_support(v, stats, a[:1], b[:1], half=10, direction=1)
    rev, n_rev = R.diagonal_support(v, stats, a[1:], b[1:], half=10, direction=-1)
    assert n_fwd[0] == 20 and n_rev[0] == 20
    assert fwd[0] > 3.0 and rev[0] > 3.0
    # The wrong direction along the same pairs is not supported.
    wrong, _ = R.diagonal_support(v, stats, a[:1], b[:1], half=10, direction=-1)
    assert wrong[0] < fwd[0] - 2.0
    rng = np.random.default_rng(2)
    ra, rb = rng.integers(0, 1900, 200), rng.integers(2700, 3000, 200)
    rand, _ = R.diagonal_support(v, stats, ra, rb, half=10, direction=1)
    assert np.median(rand) < 1.0


def test_diagonal_support_is_the_same_scored_in_blocks(monkeypatch):
    """Large sites score their stretches a block of pairs at a time; a pair's support is its own
    stretch's, whichever block it falls in."""
    v, _ = _walk_with_revisits()
    stats = R.background(v, 5)
    rng = np.random.default_rng(4)
    a, b = rng.integers(0, 1500, 50), rng.integers(1600, 3000, 50)
    whole = R.diagonal_support(v, stats, a, b, half=6, direction=1)
    monkeypatch.setattr(R, "SUPPORT_BLOCK", 7)
    blocks = R.diagonal_support(v, stats, a, b, half=6, direction=1)
    np.testing.assert_array_equal(whole[1], blocks[1])
    np.testing.assert_allclose(whole[0], blocks[0], rtol=1e-6)
    empty = R.diagonal_support(v, stats, a[:0], b[:0], half=6, direction=1)
    assert empty[0].size == 0 and empty[1].size == 0


def test_diagonal_support_skips_pairs_outside_and_near_in_time():
    v = _random(50, 8)
    stats = R.background(v, 3)
    _, count = R.diagonal_support(v, stats, np.array([0, 20]), np.array([49, 24]), half=5, direction=1)
    assert count[0] == 0      # (0 + t, 49 + t) stays inside only for t < 0, and then a + t < 0
    # (20 + t, 24 + t) are always 4 apart (> 3): all ten pairs count.
    assert count[1] == 10


def test_calibrated_scores_are_symmetric_and_a_revisit_stands_out():
    v, origin = _walk_with_revisits()
    stats = R.background(v, 5)
    assert stats.mean.shape == (v.shape[0], 1) and np.all(stats.std > 0)
    a, b = np.array([2100, 50]), np.array([origin[2100], 2900])
    np.testing.assert_allclose(R.pair_z(v, stats, a, b), R.pair_z(v, stats, b, a), rtol=1e-5)
    neigh = R.nearest(v, 3, 5, method="exact")
    z = R.calibrated(neigh, stats)
    assert z[2100, 0] > 4.0        # the revisit, many background spreads above a different place
    assert np.nanmedian(z[100:300, 0]) < z[2100, 0]


def test_pair_similarities_are_row_cosines():
    v = _random(40, 6)
    a, b = np.array([0, 5, 39]), np.array([1, 30, 2])
    np.testing.assert_allclose(R.pair_similarities(v, a, b), np.sum(v[a] * v[b], axis=1), atol=1e-6)


def test_block_rows_keep_a_block_under_the_element_budget():
    for n in (1, 10, 5000, 100_000, 10_000_000):
        rows = R.block_rows_for(n)
        assert rows >= 1
        assert rows * n <= max(R.BLOCK_ELEMENTS, n)   # one row always fits
    assert R.BLOCK_ELEMENTS * 12 <= 400e6               # float32 sims + int64 argpartition: < 400 MB


def test_auto_is_exact_when_small_and_approximate_when_large():
    assert R.choose_method(5000, 1024) == "exact"
    assert R.choose_method(100_000, 1024) == "approximate"
    with pytest.raises(ValueError):
        R.nearest(_random(10, 4), 2, 1, method="fast")


# ------------------------------------------------------------------ several recordings

def _two_days(n: int = 1500, d: int = 64, seed: int = 3):
    """Day 2 drives day 1's route again under other light: every row a noisy copy of day 1's
    row (cosine about 0.55, as rendered days measure), so that every similarity across the
    days is damped alike, while day 1's rows keep their full spread among themselves."""
    from benchmarks.harness import random_walk_descriptors

    rng = np.random.default_rng(seed)
    day1 = random_walk_descriptors(n, d, seed, revisit_share=0.0)[0]
    day2 = _unit(day1 + 1.5 * rng.standard_normal((n, d)) / np.sqrt(d))
    return np.vstack([day1, day2]).astype(np.float32), np.repeat([0, 1], n)


@pytest.mark.parametrize("method", ["exact", "approximate"])
def test_every_row_gets_its_best_matches_in_each_recording(method):
    v, seg = _two_days()
    n = v.shape[0] // 2
    neigh = R.nearest(v, 5, 5, method=method, segment=seg)
    assert neigh.index.shape == (2 * n, 10)
    own, other = neigh.index[:, :5], neigh.index[:, 5:]   # its own recording first, then the other
    assert np.all(seg[np.maximum(own, 0)][own >= 0] == np.repeat(seg[:, None], 5, axis=1)[own >= 0])
    assert np.all(seg[np.maximum(other, 0)][other >= 0] == np.repeat(1 - seg[:, None], 5, axis=1)[other >= 0])
    # the same place on the other day (its copy, or a row beside it) is among the matches there
    found = np.mean([np.any(np.abs(other[i] - (i + n)) <= 3) for i in range(n)])
    assert found > 0.95


def _days(count: int, n: int = 600, d: int = 64, seed: int = 3):
    """``count`` recordings of one route, each a noisy copy of the first (other light)."""
    from benchmarks.harness import random_walk_descriptors

    rng = np.random.default_rng(seed)
    day1 = random_walk_descriptors(n, d, seed, revisit_share=0.0)[0]
    days = [day1] + [_unit(day1 + 1.5 * rng.standard_normal((n, d)) / np.sqrt(d)) for _ in range(count - 1)]
    return np.vstack(days).astype(np.float32), np.repeat(np.arange(count), n)


@pytest.mark.parametrize("method", ["exact", "approximate"])
def test_matches_in_the_other_recordings_share_one_budget_and_each_recording_gets_its_part(method):
    v, seg = _days(4)
    n = v.shape[0] // 4
    neigh = R.nearest(v, 6, 5, method=method, segment=seg, k_across=6)
    w = R.per_other_recording(6, 4)
    assert w == 2 and neigh.index.shape == (4 * n, 6 + 3 * w)
    for i in (0, n + 17, 2 * n + 300, 4 * n - 1):
        own, rest = neigh.index[i, :6], neigh.index[i, 6:].reshape(3, w)
        assert set(seg[own[own >= 0]]) == {seg[i]}
        others = [s for s in range(4) if s != seg[i]]
        for s, cols in zip(others, rest):
            assert set(seg[cols[cols >= 0]]) == {s}
    # every stretch of 5 rows (a place driven past) is still matched on every other day
    place = np.arange(4 * n) % n
    rest = neigh.index[:, 6:]
    hit = (np.abs(place[np.maximum(rest, 0)] - place[:, None]) <= 3) & (rest >= 0)
    per_row = hit.reshape(4 * n, 3, w).any(axis=2)
    per_stretch = per_row[: 4 * n // 5 * 5].reshape(-1, 5, 3).any(axis=1)
    assert per_stretch.mean() > 0.97


def test_with_two_recordings_the_budget_across_is_the_other_recording_s_k():
    v, seg = _two_days(n=400)
    plain = R.nearest(v, 5, 5, method="exact", segment=seg)
    shared = R.nearest(v, 5, 5, method="exact", segment=seg, k_across=5)
    assert np.array_equal(plain.index, shared.index)


def test_the_temporal_window_does_not_cross_from_one_recording_into_the_next():
    v = _random(40, 8)
    seg = np.repeat([0, 1], 20)
    neigh = R.nearest(v, 40, 5, method="exact", segment=seg)
    assert 20 in neigh.index[19]            # last of one recording, first of the next: no neighbours in time
    assert 14 not in neigh.index[19]        # within a recording the window holds
    stats = R.background(v, 5, segment=seg)
    _, count = R.diagonal_support(v, stats, np.array([19]), np.array([20]), half=3, direction=1)
    assert count[0] == 0                    # (19 + t, 20 + t) leaves one recording or the other for every t


def test_a_match_across_two_days_is_judged_against_the_background_between_those_days():
    v, seg = _two_days()
    n = v.shape[0] // 2
    rows = np.arange(0, n, 7)
    pooled = R.pair_z(v, R.background(v, 5), rows, rows + n)
    per_pair = R.pair_z(v, R.background(v, 5, segment=seg), rows, rows + n)
    assert np.median(per_pair) > np.median(pooled) + 0.3
    # and a different place on the other day still scores as a different place
    other = (rows + n // 2) % n + n
    assert np.median(R.pair_z(v, R.background(v, 5, segment=seg), rows, other)) < 1.0


def test_segments_must_be_contiguous_recordings():
    with pytest.raises(ValueError, match="contiguous"):
        R.nearest(_random(6, 4), 2, 1, segment=np.array([0, 1, 0, 1, 0, 1]))
