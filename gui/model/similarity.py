"""The similarity matrix of a map's nodes, with a picture-sized preview (plain numpy).

At 20,000 nodes the matrix is 1.6 GB of float32: computing it, sorting it for a colour
scale or turning it into an image each take seconds, so all of it happens in a worker
thread. The preview keeps the strongest similarity of each block (a revisit is a thin
bright line that averaging would wash out) and is at most ``PREVIEW_SIDE`` pixels a side,
more than a screen shows; the colour floor is the 2nd percentile of a fixed sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PREVIEW_SIDE = 2048          # pixels a side at most: wider than any screen panel
FLOOR_PERCENTILE = 2.0       # the colour scale starts here: the background, not the outliers
FLOOR_SAMPLE = 1_000_000     # entries sampled for it (the percentile of 4e8 entries takes seconds)


@dataclass
class Similarity:
    matrix: np.ndarray       # (m, m) float32 cosine similarities
    preview: np.ndarray      # (k, k) block maxima, k <= PREVIEW_SIDE (the matrix itself when small)
    floor: float             # the colour scale's low end


def compute(vectors: np.ndarray) -> Similarity:
    from engine.loops import similarity_matrix

    matrix = similarity_matrix(vectors)
    return Similarity(matrix, preview_of(matrix), floor_of(matrix))


def preview_of(matrix: np.ndarray, side: int = PREVIEW_SIDE) -> np.ndarray:
    """Block maxima of ``matrix`` so that the result is at most ``side`` a side."""
    m = matrix.shape[0]
    if m <= side:
        return matrix
    block = -(-m // side)
    k = -(-m // block)
    padded = np.full((k * block, k * block), -1.0, np.float32)
    padded[:m, :m] = matrix
    return padded.reshape(k, block, k, block).max(axis=(1, 3))


def floor_of(matrix: np.ndarray) -> float:
    values = matrix.reshape(-1)
    if values.size > FLOOR_SAMPLE:
        values = values[np.random.default_rng(0).integers(0, values.size, FLOOR_SAMPLE)]
    return float(np.percentile(values, FLOOR_PERCENTILE)) if values.size else 0.0
