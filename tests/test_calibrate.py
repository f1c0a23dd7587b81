"""Thresholds from the recording itself: z-scores, lag background, automatic thresholds."""

import warnings

import numpy as np
import pytest

from engine.calibrate import loop_threshold, node_threshold, paper_thresholds, zscores


def walk(n: int, d: int = 64, step: float = 0.35, seed: int = 0) -> np.ndarray:
    """Unit descriptors of a drive: each one a small random step from the previous."""
    rng = np.random.default_rng(seed)
    v = np.empty((n, d))
    v[0] = rng.normal(size=d)
    for i in range(1, n):
        v[i] = v[i - 1] + step * np.linalg.norm(v[i - 1]) / np.sqrt(d) * rng.normal(size=d) * 3
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def test_a_revisit_stands_out_and_others_do_not():
    v = walk(120)
    v[100] = v[20] + 0.05 * np.random.default_rng(1).normal(size=v.shape[1])
    v[100] /= np.linalg.norm(v[100])
    z = zscores(v @ v.T, exclude=5)
    far = np.abs(np.arange(120)[:, None] - np.arange(120)[None, :]) > 30
    others = z[far].copy()
    assert z[20, 100] > 5.0
    assert z[20, 100] > np.sort(others)[-3]   # the planted pair (both orders) is the top
    assert np.median(others) == pytest.approx(0.0, abs=0.5)


@pytest.mark.parametrize("gain,offset", [(0.5, 0.3), (0.2, 0.7)])
def test_zscores_do_not_depend_on_the_descriptor_scale(gain, offset):
    """A descriptor whose cosines are squeezed or lifted gives the same z-scores: thresholds transfer."""
    v = walk(80, seed=2)
    sims = v @ v.T
    np.testing.assert_allclose(zscores(gain * sims + offset, 5), zscores(sims, 5), atol=1e-3)


def test_nearby_nodes_are_judged_against_their_lag():
    """Nodes a few steps apart are always alike; that alone must not look like a revisit."""
    rng = np.random.default_rng(3)
    n = 100
    sims = rng.normal(0.2, 0.05, size=(n, n))
    sims = 0.5 * (sims + sims.T)
    idx = np.arange(n)
    lag = np.abs(idx[:, None] - idx[None, :])
    sims[(lag >= 1) & (lag <= 8)] += 0.4     # the same street, a few metres on
    np.fill_diagonal(sims, 1.0)
    z = zscores(sims, exclude=5)
    assert np.abs(z[lag == 7]).max() < 5.0
    # ...while a true revisit at the same lag still stands out against its lag.
    sims[10, 17] = sims[17, 10] = 0.95
    assert zscores(sims, exclude=5)[10, 17] > 5.0


def test_node_threshold_between_a_step_and_identity():
    v = walk(60)
    step = np.median(np.einsum("ij,ij->i", v[:-1], v[1:]))
    th = node_threshold(v)
    assert step < th < 1.0
    assert th == pytest.approx(0.5 * (step + 1.0), abs=1e-6)


def test_loop_threshold_is_above_the_background():
    v = walk(150, seed=4)
    sims = v @ v.T
    far = np.abs(np.arange(150)[:, None] - np.arange(150)[None, :]) > 5
    th = loop_threshold(v)
    assert np.median(sims[far]) < th < 1.0
    assert np.mean(sims[far] >= th) < 0.01
    assert set(paper_thresholds(v)) == {"node_sim_th", "loop_sim_th"}


def test_row_medians_with_gaps_match_numpy():
    from engine.robust import robust_stats

    rng = np.random.default_rng(3)
    for cols in (1, 2, 7, 8, 384):
        x = rng.normal(size=(40, cols)).astype(np.float32)
        x[rng.random(x.shape) < 0.3] = np.nan
        x[0] = np.nan                      # a row with no value at all
        mu, sd = robust_stats(x, axis=1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # numpy warns about the empty row
            ref = np.nanmedian(x, axis=1)
            ref_mad = np.nanmedian(np.abs(x - ref[:, None]), axis=1) * 1.4826
        np.testing.assert_allclose(mu, ref, equal_nan=True)
        ok = ~np.isnan(ref)
        np.testing.assert_allclose(sd[ok], np.maximum(ref_mad[ok], 1e-3), rtol=1e-6)
