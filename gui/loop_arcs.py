"""Where a loop arc is drawn: a curve that bulges away from the path, never a dot.

A true loop joins two nodes at (almost) the same ground-truth position, so a
straight line between them has no length and nothing shows (issue 14, defect 2).
Every loop is drawn as a cubic Bezier curve from node a to node b whose middle
stands off the chord by a height of at least ``MIN_HEIGHT_FRACTION`` of the map's
extent; a short chord becomes a teardrop loop, so a loop is a visible shape at any
chord length. Plain numpy: the graph view samples the curves once per redraw.
"""

from __future__ import annotations

import numpy as np

# Smallest bulge, as a fraction of the larger side of the map's bounding box: 7 %
# is about 30 px in a 450 px high graph view, big enough to see and click, small enough
# not to hide the path (chosen by looking at the demo routes' screenshots).
MIN_HEIGHT_FRACTION = 0.07
# Bulge of a long chord, as a fraction of its length: a flat arc that leaves the
# straight line so that a loop is never drawn on top of the path it joins.
HEIGHT_PER_LENGTH = 0.25
SAMPLES = 24


def loop_curves(x: np.ndarray, y: np.ndarray, pairs: np.ndarray, samples: int = SAMPLES) -> np.ndarray:
    """(len(pairs), samples, 2) points of the curve of each loop (a, b) over nodes at (x, y)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.size == 0 or len(x) == 0:
        return np.zeros((0, samples, 2))
    xy = np.stack([np.asarray(x, np.float64), np.asarray(y, np.float64)], axis=1)
    extent = float(max(np.ptp(xy[:, 0]), np.ptp(xy[:, 1]), 1e-9))
    min_h = MIN_HEIGHT_FRACTION * extent
    pa, pb = xy[pairs[:, 0]], xy[pairs[:, 1]]
    chord = pb - pa
    length = np.linalg.norm(chord, axis=1)
    tangent = _path_tangent(xy, pairs[:, 0])
    # Along: the chord's direction, or the path's where the chord is too short to have one.
    short = length < min_h
    along = np.where(short[:, None], tangent, chord / np.maximum(length, 1e-12)[:, None])
    normal = np.stack([-along[:, 1], along[:, 0]], axis=1)
    # Bulge away from the middle of the map: out of the drawing, not across the path.
    mid = (pa + pb) / 2
    outward = np.einsum("ij,ij->i", normal, mid - xy.mean(axis=0))
    normal *= np.where(outward < 0, -1.0, 1.0)[:, None]
    height = np.maximum(HEIGHT_PER_LENGTH * length, min_h)
    # Cubic Bezier with both inner controls pushed by c: the middle stands off by 0.75 c.
    push = normal * (height / 0.75)[:, None]
    # A short chord opens into a teardrop: the controls spread along the path.
    spread = along * (np.where(short, 0.8 * height, 0.0))[:, None]
    p1 = pa + push - spread
    p2 = pb + push + spread
    t = np.linspace(0.0, 1.0, samples)[None, :, None]
    s = 1.0 - t
    return (s ** 3) * pa[:, None] + 3 * s * s * t * p1[:, None] + 3 * s * t * t * p2[:, None] + (t ** 3) * pb[:, None]


def nan_joined(curves: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x, y of all curves in one line item, each curve ended by a NaN (connect='finite')."""
    if curves.shape[0] == 0:
        return np.zeros(0), np.zeros(0)
    n, s, _ = curves.shape
    out = np.full((n, s + 1, 2), np.nan)
    out[:, :s] = curves
    out = out.reshape(-1, 2)
    return out[:, 0], out[:, 1]


def distance_to_curves(curves: np.ndarray, qx: float, qy: float, sx: float = 1.0, sy: float = 1.0) -> np.ndarray:
    """Distance from (qx, qy) to each sampled curve, after scaling x by 1/sx and y by 1/sy (pixels)."""
    if curves.shape[0] == 0:
        return np.zeros(0)
    p = curves / np.array([sx, sy])
    q = np.array([qx / sx, qy / sy])
    a, b = p[:, :-1], p[:, 1:]
    d = b - a
    t = np.clip(np.einsum("nij,nij->ni", q - a, d) / np.maximum(np.einsum("nij,nij->ni", d, d), 1e-12), 0, 1)
    nearest = a + t[..., None] * d
    return np.linalg.norm(nearest - q, axis=2).min(axis=1)


def _path_tangent(xy: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Unit direction of the path at nodes ``k`` (from the node before to the node after)."""
    n = xy.shape[0]
    d = xy[np.minimum(k + 1, n - 1)] - xy[np.maximum(k - 1, 0)]
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    return np.where(norm > 1e-12, d / np.maximum(norm, 1e-12), np.array([[1.0, 0.0]]))
