"""A colour histogram of the horizon band: a place signal that survives a sideways move.

After a lateral offset of under a metre, near walls are magnified and far walls
shrink, so the global descriptor and the column signatures of a panorama change a
lot (benchmarks/results/offset_analysis.md). The *colours* of the doors, posters and
facades around the robot stay the same, only their share of the image changes a
little. ``colour_histogram`` counts them, ignoring where they are: invariant to yaw,
tolerant to parallax, and grey-world normalised so a global lighting change does not
move it. The ``verified`` method adds it to the descriptor's evidence when it looks
for long runs of matching nodes (``engine.loops_verified``).
"""

from __future__ import annotations

import cv2
import numpy as np

from .shift import check_rgb, downscale

# Bump when colour_histogram changes, so cached descriptors are recomputed.
COLOURS_VERSION = 1
BINS = 8                    # per Lab channel: 512 bins
_WIDTH = 256                # computed at this width: the count of colours, not detail
_ROWS = (1 / 3, 2 / 3)      # the horizon band: walls and facades, not floor and sky


def colour_histogram(rgb: np.ndarray) -> np.ndarray:
    """float32 (BINS**3,) unit vector: square-rooted Lab histogram of the horizon band.

    The square root (Hellinger) keeps one dominant colour (a long wall) from drowning
    the small distinctive ones; the dot product of two histograms is their similarity.
    """
    check_rgb(rgb)
    small = downscale(rgb, _WIDTH)
    h = small.shape[0]
    band = small[int(h * _ROWS[0]):max(int(h * _ROWS[1]), int(h * _ROWS[0]) + 1)]
    # Grey world: divide each channel by its mean, so a colour cast or gain cancels.
    means = np.maximum(band.reshape(-1, 3).mean(axis=0), 1.0)
    balanced = np.clip(band / means * 128.0, 0, 255).astype(np.uint8)
    lab = cv2.cvtColor(balanced, cv2.COLOR_RGB2LAB)
    hist = cv2.calcHist([lab], [0, 1, 2], None, [BINS] * 3, [0, 256] * 3).ravel()
    hist = np.sqrt(hist / max(float(hist.sum()), 1.0))
    norm = float(np.linalg.norm(hist))
    return (hist / norm if norm > 0 else hist).astype(np.float32)
