"""Stages 1 and 2 of ``verified``: candidate pairs by retrieval, calibrated, with their support.

Stage 1 (``candidates``): each node's best ``retrieval_k`` descriptor matches beyond its
temporal neighbours in its own recording and ``retrieval_k_across`` in the others, shared
among them (``engine.retrieval``: in blocks, never an n x n array), each cosine calibrated
as standard deviations above the two nodes' own background (their similarity to unrelated
nodes of the other's recording), so that one threshold means the same for any descriptor,
scene and pair of recordings.

Stage 2 (``with_support``): the mean calibrated score along the stretch through each pair,
forwards (the same way again) and backwards (a reverse drive): the paper's window count,
generalised to both directions. A crossing shares one point and has no such run.
"""

from __future__ import annotations

import numpy as np

from .. import retrieval
from ..params import MapParams
from .pairs import Pairs


def _key(vectors: np.ndarray, recording: np.ndarray, *rest) -> tuple:
    return (vectors.shape, hash(vectors[:, :4].tobytes()), hash(recording.tobytes())) + rest


def background(vectors: np.ndarray, recording: np.ndarray, params: MapParams, cache: dict):
    """Each node's background similarity statistics against each recording, cached per node set."""
    key = ("background",) + _key(vectors, recording, params.neighbor_node_num)
    if key not in cache:
        cache[key] = retrieval.background(vectors, params.neighbor_node_num, segment=recording)
    return cache[key]


def scored(vectors: np.ndarray, stats, a: np.ndarray, b: np.ndarray) -> Pairs:
    """Pairs (a, b) with their cosine and calibrated score."""
    cos = retrieval.pair_similarities(vectors, a, b)
    return Pairs(a=a, b=b, cosine=cos, score=retrieval.zscores(cos, stats, a, b))


def candidates(vectors: np.ndarray, recording: np.ndarray, params: MapParams, cache: dict) -> Pairs:
    """Stage 1: unique pairs (a < b) of each node's best matches in its own recording and
    across the others (``recording``: one label per node), with cosine and score."""
    key = ("nearest",) + _key(vectors, recording, params.retrieval_k, params.retrieval_k_across,
                              params.neighbor_node_num)
    if key not in cache:
        cache[key] = retrieval.nearest(vectors, params.retrieval_k, params.neighbor_node_num, segment=recording,
                                       k_across=params.retrieval_k_across)
    neigh = cache[key]
    m, k = neigh.index.shape
    rows = np.repeat(np.arange(m, dtype=np.int64), k)
    cols = neigh.index.reshape(-1).astype(np.int64)
    ok = cols >= 0
    pair = retrieval.sorted_unique(np.minimum(rows[ok], cols[ok]) * m + np.maximum(rows[ok], cols[ok]))
    return scored(vectors, background(vectors, recording, params, cache), pair // m, pair % m)


def with_support(vectors: np.ndarray, recording: np.ndarray, pairs: Pairs, params: MapParams, cache: dict) -> Pairs:
    """Stage 2: ``pairs`` with ``support`` (the better of the forward and reverse mean
    calibrated score along the stretch; NaN where there is none) and its ``direction``.
    Each pair's two means are cached, so a re-map computes only pairs it has not seen."""
    stats = background(vectors, recording, params, cache)
    key = ("support",) + _key(vectors, recording, params.support_half, params.neighbor_node_num)
    m = vectors.shape[0]
    ids = pairs.a * m + pairs.b
    seen, means = cache.get(key, (np.zeros(0, np.int64), np.zeros((0, 2))))   # pair ids sorted, their means
    todo = np.setdiff1d(retrieval.sorted_unique(ids), seen, assume_unique=True)
    if todo.size:
        new = [retrieval.diagonal_support(vectors, stats, todo // m, todo % m, params.support_half, d)[0]
               for d in (+1, -1)]
        seen, means = np.concatenate([seen, todo]), np.concatenate([means, np.stack(new, axis=1)])
        order = np.argsort(seen)
        seen, means = cache[key] = seen[order], means[order]
    both = means[np.searchsorted(seen, ids)]
    fwd, rev = np.nan_to_num(both[:, 0], nan=-np.inf), np.nan_to_num(both[:, 1], nan=-np.inf)
    best = np.maximum(fwd, rev)
    pairs.support = np.where(np.isfinite(best), best, np.nan)
    pairs.direction = np.where(rev > fwd, -1, 1).astype(np.int64)
    return pairs


def descriptor_rank(pairs: Pairs) -> np.ndarray:
    """A pair's rank before geometry: calibrated score + positive support."""
    return pairs.score + np.maximum(np.nan_to_num(pairs.support, nan=0.0), 0.0)
