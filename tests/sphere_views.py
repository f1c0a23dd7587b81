"""Two-view models made from known camera centres, for tests of what is measured from them."""

from __future__ import annotations

import numpy as np

from engine.sphere import TwoView, to_uv


def fitted(points: np.ndarray, centre_a: np.ndarray, centre_b: np.ndarray, model: str = "essential") -> TwoView:
    """The two-view model of cameras at ``centre_a``, ``centre_b`` (no rotation) seeing ``points``,
    as ``engine.sphere.two_view`` would fit it from perfect matches."""
    uv_a = to_uv(points - centre_a).astype(np.float32)
    uv_b = to_uv(points - centre_b).astype(np.float32)
    t = centre_a - centre_b                           # X_b = X_a + (centre_a - centre_b)
    n = len(points)
    return TwoView(n, n, 1.0, model, np.eye(3), 0.0, uv_a, uv_b, np.ones(n, bool),
                   t / np.linalg.norm(t) if model == "essential" else None)
