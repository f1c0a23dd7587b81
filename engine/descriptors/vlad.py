"""VLAD aggregation and spherical (cosine) k-means, in plain numpy.

Shared by every descriptor that pools local features into one vector
(the embedded EfficientNet model, AnyLoc/DINOv2). Layout of a VLAD vector is
cluster-major: block ``j`` (``C`` numbers) belongs to cluster ``j``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import InputError

# Rows processed at once when assigning features to centres: bounds memory to
# CHUNK x k floats whatever N is (N can be ~1e6 patch features).
CHUNK = 65536
# k-means++ seeding looks at most this many rows (a random subset): seeding cost
# is k passes over the rows, too slow on 1e6 x 1536 for no gain in quality.
SEED_SAMPLE = 20000


def l2_normalize(x: np.ndarray, axis: int = -1, eps: float = 1e-12) -> np.ndarray:
    """``x`` divided by its L2 norm along ``axis`` (zero vectors stay zero)."""
    x = np.asarray(x)
    norm = np.linalg.norm(x, axis=axis, keepdims=True)
    return x / np.maximum(norm, eps)


def _assign(features: np.ndarray, centers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the most similar centre (argmax dot) and that similarity, per row."""
    n = features.shape[0]
    labels = np.empty(n, dtype=np.int64)
    best = np.empty(n, dtype=centers.dtype)
    for start in range(0, n, CHUNK):
        sims = features[start:start + CHUNK].astype(centers.dtype) @ centers.T
        labels[start:start + CHUNK] = np.argmax(sims, axis=1)
        best[start:start + CHUNK] = sims[np.arange(sims.shape[0]), labels[start:start + CHUNK]]
    return labels, best


def _cluster_sums(features: np.ndarray, labels: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-cluster sum of rows (float64) and row count, in chunks (rows sorted by cluster, summed
    per run: O(N C), where a one-hot product costs O(N C k))."""
    counts = np.bincount(labels, minlength=k)
    sums = np.zeros((k, features.shape[1]), dtype=np.float64)
    for start in range(0, features.shape[0], CHUNK):
        part = labels[start:start + CHUNK]
        order = np.argsort(part, kind="stable")
        present = np.unique(part)
        runs = np.searchsorted(part[order], present)
        sums[present] += np.add.reduceat(features[start:start + CHUNK][order].astype(np.float64), runs, axis=0)
    return sums, counts


def _seed_plus_plus(sample: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """k-means++ seeding with cosine distance (1 - cos) on ``sample`` rows."""
    n = sample.shape[0]
    chosen = [int(rng.integers(n))]
    dist = 1.0 - sample @ sample[chosen[0]]
    for _ in range(1, k):
        weights = np.clip(dist, 0.0, None).astype(np.float64) ** 2
        total = weights.sum()
        if total <= 0:  # every row coincides with a centre: pick any unused row
            unused = np.setdiff1d(np.arange(n), chosen)
            idx = int(rng.choice(unused))
        else:
            idx = int(rng.choice(n, p=weights / total))
        chosen.append(idx)
        dist = np.minimum(dist, 1.0 - sample @ sample[idx])
    return sample[chosen].copy()


def kmeans_start(features: np.ndarray, k: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(unit rows float32 (N, C), k-means++ seed centres float64 (k, C)) of ``features``: the
    part of ``kmeans_cosine`` shared with its CUDA twin (``vlad_torch.kmeans_cosine_torch``).

    Rows are L2-normalised (norms in float64, rows stored as float32: a 100k x 1536 sample stays
    0.6 GB); the seeds are drawn on the host from ``seed``, so both twins start alike.
    """
    x = np.asarray(features)
    if x.ndim != 2:
        raise InputError(f"k-means needs a 2-D array of features, got shape {x.shape}")
    if k < 1:
        raise InputError(f"k-means needs at least one cluster, got k={k}")
    if x.shape[0] < k:
        raise InputError(f"k-means with {k} clusters needs at least {k} features, got {x.shape[0]}")
    x = np.asarray(x, dtype=np.float32)
    norms = np.sqrt(np.einsum("ij,ij->i", x, x, dtype=np.float64))
    x = x * (1.0 / np.maximum(norms, 1e-12)).astype(np.float32)[:, None]
    rng = np.random.default_rng(seed)
    if x.shape[0] > SEED_SAMPLE:
        sample = x[np.sort(rng.choice(x.shape[0], SEED_SAMPLE, replace=False))]
    else:
        sample = x
    return x, _seed_plus_plus(sample.astype(np.float64), k, rng)


def kmeans_cosine(features: np.ndarray, k: int, iters: int = 30, seed: int = 0) -> np.ndarray:
    """Spherical k-means: ``k`` unit centres (float32, (k, C)) of the rows of ``features``.

    Rows are L2-normalised first; assignment is by cosine (argmax dot), each centre
    is the normalised mean of its rows. Seeding is k-means++ on a random subset,
    deterministic from ``seed``. An empty cluster is re-seeded with the row that is
    worst represented by its current centre.

    Computed in float64: the result then depends only on the input rows and the seed, not on
    BLAS kernels, thread counts or a GPU's reduction order (a float32 run on CUDA gave other
    centres, issue 15). This is the CPU's version (58 s on the 2-core development machine for
    65,536 x 1536 random rows, 30 iterations); on CUDA ``vlad_torch.kmeans_cosine_torch`` runs
    the same steps on the GPU.
    """
    x, centers = kmeans_start(features, k, seed)
    labels = None
    for _ in range(iters):
        new_labels, best = _assign(x, centers)
        sums, counts = _cluster_sums(x, new_labels, k)
        empty = np.flatnonzero(counts == 0)
        if empty.size:
            # Worst-represented rows become the new centres of the empty clusters.
            worst = np.argsort(best, kind="stable")[: empty.size]
            sums[empty] = x[worst].astype(np.float64)
        centers = l2_normalize(sums)
        if labels is not None and empty.size == 0 and np.array_equal(labels, new_labels):
            break
        labels = new_labels
    return centers.astype(np.float32)


def vlad(features: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """VLAD vector (float32, k*C) of L2-normalised ``features`` (N, C) against ``centers`` (k, C).

    Hard assignment by cosine, residuals ``f - c`` summed per cluster,
    each C-block L2-normalised (empty clusters stay zero), then the whole vector
    L2-normalised.
    """
    f = np.asarray(features, dtype=np.float32)
    c = np.asarray(centers, dtype=np.float32)
    if f.ndim != 2 or c.ndim != 2 or f.shape[1] != c.shape[1]:
        raise InputError(f"VLAD: features {f.shape} and centres {c.shape} do not match")
    k = c.shape[0]
    if f.shape[0] == 0:
        return np.zeros(k * c.shape[1], dtype=np.float32)
    labels, _ = _assign(f, c)
    sums, counts = _cluster_sums(f, labels, k)
    residuals = sums - counts[:, None] * c.astype(np.float64)
    residuals = l2_normalize(residuals)          # intra-normalisation
    return l2_normalize(residuals.reshape(-1)).astype(np.float32)


def vlad_many(features_list: Sequence[np.ndarray], centers: np.ndarray) -> np.ndarray:
    """One VLAD row per feature set: float32 (n, k*C)."""
    c = np.asarray(centers, dtype=np.float32)
    out = np.zeros((len(features_list), c.shape[0] * c.shape[1]), dtype=np.float32)
    for i, f in enumerate(features_list):
        out[i] = vlad(f, c)
    return out
