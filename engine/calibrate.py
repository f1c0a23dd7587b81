"""Thresholds that transfer: calibrate similarities from the recording itself.

Absolute cosine thresholds are tied to one descriptor and one kind of scene. Here each
similarity is instead measured against what "a different place" looks like in the same
recording: for every node, the similarities to temporally distant nodes are almost all
different places (revisits are a few per node at most), so their robust centre and
spread (median and MAD) define a per-node background. A pair's z-score

    z(i, j) = (S[i, j] - (mu_i + mu_j) / 2) / sqrt((sd_i^2 + sd_j^2) / 2)

says how many background spreads the pair stands out, which means the same for the
embedded descriptor, AnyLoc, indoor or outdoor. The same is done for verification
scores (``robust_stats`` on a sample of distant pairs).

Node threshold: consecutive samples of a moving robot are the reference for "one step
apart"; a frame is merged into the current node only when it is clearly more similar
than a typical step (half-way from the median step similarity to 1).
"""

from __future__ import annotations

import numpy as np

from .robust import robust_stats

# Columns sampled per row for the background statistics (enough for a stable median).
_SAMPLE = 384
def background(sims: np.ndarray, exclude: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Per-row (mu, sd) of similarities to nodes more than ``exclude`` apart in time.

    Uses a fixed random sample of at most ``_SAMPLE`` columns, so it stays cheap for
    thousands of nodes. Rows with no distant node get the global statistics.
    """
    m = sims.shape[0]
    rng = np.random.default_rng(seed)
    cols = np.arange(m) if m <= _SAMPLE else np.sort(rng.choice(m, _SAMPLE, replace=False))
    block = sims[:, cols].astype(np.float32, copy=True)
    near = np.abs(np.arange(m)[:, None] - cols[None, :]) <= exclude
    block[near] = np.nan
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mu, sd = robust_stats(block, axis=1)
    if np.all(np.isnan(mu)):
        return np.zeros(m, np.float32), np.ones(m, np.float32)
    g_mu, g_sd = robust_stats(block[~np.isnan(block)])
    mu = np.where(np.isnan(mu), g_mu, mu)
    sd = np.where(np.isnan(sd), g_sd, sd)
    return mu.astype(np.float32), sd.astype(np.float32)


def lag_background(sims: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """(mu, sd) of the similarities of nodes ``lag`` apart in time, for lag 0..max_lag.

    Nodes a few steps apart on the same street look alike without being the same
    place; their similarity is judged against other pairs at the same lag.
    """
    m = sims.shape[0]
    mu = np.full(max_lag + 1, np.inf, np.float32)
    sd = np.ones(max_lag + 1, np.float32)
    for lag in range(1, min(max_lag, m - 1) + 1):
        mu[lag], sd[lag] = robust_stats(np.diagonal(sims, lag).astype(np.float64))
    return mu, sd


def zscores(sims: np.ndarray, exclude: int, max_lag: int | None = None) -> np.ndarray:
    """(m, m) float32 z-scores of a similarity matrix against each node's background.

    For pairs at most ``max_lag`` (default 4 * exclude + 8) apart in time the z-score
    against the pairs at the same lag is used too, and the smaller of the two kept.
    """
    mu, sd = background(sims, exclude)
    half_mu = (0.5 * mu).astype(np.float32)
    half_var = (0.5 * sd.astype(np.float32) ** 2)
    # In place, in float32: a few (m, m) passes instead of several temporaries.
    z = np.asarray(sims, np.float32) - half_mu[:, None]
    z -= half_mu[None, :]
    spread = half_var[:, None] + half_var[None, :]
    np.sqrt(spread, out=spread)
    z /= spread
    m = sims.shape[0]
    max_lag = 4 * exclude + 8 if max_lag is None else int(max_lag)
    if m > 1 and max_lag > 0:
        lag_mu, lag_sd = lag_background(sims, max_lag)
        rows = np.arange(m)
        for lag in range(1, min(max_lag, m - 1) + 1):   # one diagonal at a time: O(m * max_lag)
            i, j = rows[:m - lag], rows[lag:]
            zl = (sims[i, j] - lag_mu[lag]) / lag_sd[lag]
            z[i, j] = np.minimum(z[i, j], zl)
            z[j, i] = np.minimum(z[j, i], zl)
    return z


def node_threshold(vectors: np.ndarray) -> float:
    """Automatic node_sim_th: half-way from the median consecutive-sample similarity to 1."""
    v = np.asarray(vectors, dtype=np.float32)
    if v.shape[0] < 2:
        return 0.9
    step = np.einsum("ij,ij->i", v[:-1], v[1:])
    return float(0.5 * (float(np.median(step)) + 1.0))


# Loop threshold of the paper's methods: this many background spreads above the median.
LOOP_Z = 3.5


def loop_threshold(vectors: np.ndarray, exclude: int = 5, k: float = LOOP_Z) -> float:
    """Automatic loop_sim_th for the paper's methods: median + k * spread of the
    similarities between temporally distant samples (almost all different places)."""
    v = np.asarray(vectors, dtype=np.float32)
    m = v.shape[0]
    if m <= exclude + 1:
        return 0.9
    from .retrieval import sample_columns, sampled_similarities

    # The (m, 384) sample one row block at a time; only the distant values are kept
    # (float32, 150 MB at 100k rows) and their median and MAD taken as before.
    far = np.concatenate([block[~np.isnan(block)] for _, _, block in
                          sampled_similarities(v, sample_columns(m, _SAMPLE, seed=0), exclude)])
    mu, sd = robust_stats(far.astype(np.float64))
    return float(min(mu + k * sd, 0.99))


def paper_thresholds(vectors: np.ndarray, exclude: int = 5) -> dict:
    """node_sim_th and loop_sim_th for simple / shift-simple / ours, from the recording."""
    return {"node_sim_th": node_threshold(vectors), "loop_sim_th": loop_threshold(vectors, exclude)}
