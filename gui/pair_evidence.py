"""The evidence behind a pair of nodes, computed from their frames (no Qt).

``pair_yaw``: the relative heading of a pair, for a loop the user adds by hand
(issue 14, defect 8: manual loops kept no yaw) and for a pair the pair view shows.
"""

from __future__ import annotations

from typing import Optional

import numpy as np


def pair_yaw(doc, cache, key) -> Optional[float]:
    """Yaw (degrees, ``engine.shift`` convention) of the pair at source frames ``key``, or None.

    The loop's own yaw when it has one, else one the pair view already estimated,
    else estimated now from the two frames (``estimate_yaw``); None when the
    frames cannot be read (recording not found).
    """
    attrs = doc.loop_attrs(key) if doc.has_map else None
    if attrs is not None and attrs.get("yaw") is not None and np.isfinite(attrs["yaw"]):
        return float(attrs["yaw"])
    if key in doc.estimated_yaws:
        return float(doc.estimated_yaws[key])
    a, b = cache.get(key[0]), cache.get(key[1])
    if a is None or b is None:
        return None
    return estimate_yaw(a.rgb, b.rgb)


def estimate_yaw(rgb_a: np.ndarray, rgb_b: np.ndarray) -> Optional[float]:
    """Heading of panorama ``b`` relative to ``a`` in degrees, or None for frames of different shapes."""
    if rgb_a.shape != rgb_b.shape:
        return None
    from engine.shift import relative_yaw

    return float(relative_yaw(rgb_a, rgb_b)[0])
