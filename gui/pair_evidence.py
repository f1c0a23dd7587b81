"""The evidence behind a pair of nodes, computed from their frames (no Qt).

``pair_yaw``: the relative heading of a pair, for a loop the user adds by hand
(issue 14, defect 8: manual loops kept no yaw) and for a pair the pair view shows.
``PairMatches`` / ``match_segments``: the matched local features of a pair and where
the pair view draws them; ``evidence_lines``: the numbers behind a decision as text.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Optional

import numpy as np


def pair_yaw(doc, cache, key, matches_for=None) -> Optional[float]:
    """Yaw (degrees, ``engine.shift`` convention) of the pair at source frames ``key``, or None.

    The loop's own yaw when it has one, else one the pair view already estimated,
    else the two-view geometry's (``matches_for``, e.g. a ``MatchCache``) when it
    fitted a model, else estimated from the two frames' column signals
    (``estimate_yaw``); None when the frames cannot be read (recording not found).
    """
    attrs = doc.loop_attrs(key) if doc.has_map else None
    if attrs is not None and attrs.get("yaw") is not None and np.isfinite(attrs["yaw"]):
        return float(attrs["yaw"])
    if key in doc.estimated_yaws:
        return float(doc.estimated_yaws[key])
    m = matches_for(key) if matches_for is not None else None
    if m is not None and m.yaw is not None:
        return float(m.yaw)
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


@dataclass(frozen=True)
class PairMatches:
    """Matched local features of a pair, as the geometry module gives them.

    ``uv_a``, ``uv_b``: (m, 2) positions as fractions of the width and height of the
    panorama-SHIFTED frames; ``inlier_mask``: (m,) bool, True where the match fits the
    two-view model. ``yaw`` (degrees) is the model's relative heading when it has one.
    """

    uv_a: np.ndarray
    uv_b: np.ndarray
    inlier_mask: np.ndarray
    yaw: Optional[float] = None
    inlier_ratio: Optional[float] = None

    @property
    def inliers(self) -> int:
        return int(np.count_nonzero(self.inlier_mask))

    @property
    def matches(self) -> int:
        return int(len(self.inlier_mask))


def match_segments(m: PairMatches, width: int, height: int, shift_a: int, shift_b: int,
                   roll_b: int, offset_b: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Where to draw each match in the pair view: (inlier, outlier) arrays of (k, 2, 2) segments.

    The query is drawn as its original frame with its top-left corner at (0, 0); the
    candidate as its original frame rolled left by ``roll_b`` columns (aligned by the
    yaw) with its top-left corner at ``offset_b`` (below or beside the query). A feature at u in the shifted frame lies at column
    ``u * width + shift`` of the original (modulo the width), and the candidate's
    column moves left by ``roll_b`` more.
    """
    uv_a = np.asarray(m.uv_a, dtype=np.float64).reshape(-1, 2)
    uv_b = np.asarray(m.uv_b, dtype=np.float64).reshape(-1, 2)
    xa = np.mod(uv_a[:, 0] * width + shift_a, width)
    xb = np.mod(uv_b[:, 0] * width + shift_b - roll_b, width) + offset_b[0]
    ya = uv_a[:, 1] * height
    yb = uv_b[:, 1] * height + offset_b[1]
    seg = np.stack([np.stack([xa, ya], axis=1), np.stack([xb, yb], axis=1)], axis=1)
    mask = np.asarray(m.inlier_mask, dtype=bool).reshape(-1)
    return seg[mask], seg[~mask]


def evidence_lines(attrs: Optional[dict], matches: Optional[PairMatches], similarity: float) -> list[str]:
    """The numbers behind a loop decision, one short phrase each (for the pair view's text).

    From the loop arc's evidence attributes (``engine.graph.EVIDENCE_KEYS``: ``score`` and
    ``support`` in standard deviations above the recording's background, ``matches``,
    ``inliers``, ``inlier_ratio``, ``step_inliers``, ``distance_steps``, ``closure``,
    ``plane_share``, ``direction``, ``confidence``); the feature counts of ``matches``
    (computed for the view) take the place of the arc's when given.
    """
    attrs = attrs or {}

    def num(key):
        value = attrs.get(key)
        return float(value) if value is not None and np.isfinite(float(value)) else None

    out = []
    if np.isfinite(similarity):
        out.append(f"similarity {similarity:.3f}")
    if num("score") is not None:
        out.append(f"descriptor score {num('score'):.2f} σ")
    inl, total, ratio = num("inliers"), num("matches"), num("inlier_ratio")
    if matches is not None:
        inl, total, ratio = matches.inliers, matches.matches, matches.inlier_ratio
    if inl is not None:
        ratio_text = f" ({100 * ratio:.0f} %)" if ratio is not None and np.isfinite(ratio) else ""
        out.append(f"inliers {int(inl)}/{int(total)} matches{ratio_text}" if total is not None
                   else f"inliers {int(inl)}{ratio_text}")
    if num("step_inliers") is not None:
        out.append(f"one step along the path shares {int(num('step_inliers'))}")
    if num("distance_steps") is not None:
        out.append(f"the two views {num('distance_steps'):.2f} node steps apart")
    if num("closure") is not None:
        out.append(f"the path meets itself again within {num('closure'):.1f} node steps")
    if num("plane_share") is not None:
        out.append(f"{100 * num('plane_share'):.0f} % of the inliers on one plane")
    if num("support") is not None:
        out.append(f"sequence support {num('support'):.1f} σ")
    elif num("window_count"):
        out.append(f"window count {int(num('window_count'))}")
    if num("direction"):
        out.append("same way" if num("direction") > 0 else "reverse way")
    if num("confidence") is not None:
        out.append(f"confidence {num('confidence'):.2f}")
    return out


class MatchCache:
    """The matched features of a pair, from the two-view geometry, computed once per pair.

    Features come from the descriptors of the run (``Descriptors.features``: the local
    features of each panorama-shifted frame) when it kept them, else are extracted now
    from the two frames (``engine.features.extract``, ~40 ms a frame). ``engine.sphere``
    matches them and fits the model; without those modules (an older engine) there are
    no matches and the pair view shows the aligned pair alone. ``clear`` when the map or
    the recording changes. Computing one pair takes ~0.2-0.8 s (SIFT on two frames and
    RANSAC, measured on this project's shared 2-core machine), so the pair view calls it
    from a worker thread and shows the pair at once, the matches when they are ready.
    """

    def __init__(self, doc, cache, capacity: int = 64) -> None:
        self.doc, self.cache, self.capacity = doc, cache, capacity
        self._pairs: dict = {}
        self.errors: dict = {}           # why a pair could not be matched, by key
        self._lock = threading.Lock()   # filled by a worker thread, read by the UI

    def clear(self) -> None:
        with self._lock:
            self._pairs = {}
            self.errors = {}

    def has(self, key) -> bool:
        with self._lock:
            return tuple(int(k) for k in key) in self._pairs

    def peek(self, key) -> Optional[PairMatches]:
        """The matches of ``key`` if computed already, else None (never computes)."""
        with self._lock:
            return self._pairs.get(tuple(int(k) for k in key))

    def __call__(self, key) -> Optional[PairMatches]:
        """The matches of ``key``, computed now if needed (slow: call it off the UI thread)."""
        key = tuple(int(k) for k in key)
        with self._lock:
            if key in self._pairs:
                return self._pairs[key]
        try:
            found = self._compute(key)
        except Exception as exc:  # noqa: BLE001 - a pair that cannot be matched shows without matches
            found = None          # (stored: never retried in a loop), the reason kept for the view
            self.errors[key] = f"{type(exc).__name__}: {exc}"
        with self._lock:
            if len(self._pairs) >= self.capacity:
                self._pairs.pop(next(iter(self._pairs)))
            self._pairs[key] = found
        return found

    def _compute(self, key) -> Optional[PairMatches]:
        try:
            from engine import sphere
        except ImportError:
            return None
        fa, fb = self._features(key[0]), self._features(key[1])
        if fa is None or fb is None:
            return None
        tv = sphere.two_view(fa[0], fb[0])
        yaw = None
        if tv.yaw_deg is not None:   # the model's yaw is of the shifted frames: back to the originals
            yaw = float(sphere.yaw_of_originals(tv.yaw_deg, fa[1], fb[1], fa[2]))
        return PairMatches(uv_a=tv.uv_a, uv_b=tv.uv_b, inlier_mask=tv.inlier_mask, yaw=yaw,
                           inlier_ratio=float(tv.inlier_ratio))

    def _features(self, frame: int):
        """(LocalFeatures of the shifted frame, its shift, the frame width), or None."""
        item = self.cache.get(frame)
        if item is None:
            return None
        width = int(item.rgb.shape[1])
        descs = self.doc.descs
        table = getattr(descs, "features", None) if descs is not None else None
        if table is not None:
            row = self.doc.descriptor_row(frame)   # a site: the row of that recording's frame
            if row is not None and row < len(table):
                shift = int(descs.shifts[row])
                counted = int(descs.meta.get("frame_width", 0) or 0) if self.doc.site is not None else 0
                if counted and counted != width:   # a site's shifts count in its first recording's width
                    shift = int(round(shift * width / counted)) % width
                return table.of(row), shift, width
        from engine.features import extract
        from engine.shift import apply_shift

        return extract(apply_shift(item.rgb, item.shift)), int(item.shift), width
