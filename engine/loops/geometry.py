"""Stage 4 of ``verified``: two-view geometry on the sphere, behind one cache object.

``PairGeometry`` fits local features of two frames with a two-view model on the sphere
(``engine.sphere``: essential matrix, or a pure rotation at one spot) once per frame pair.
Inliers are physical evidence of the same scene; the rotation gives the loop's ``yaw``. The
same fit between each end and its next node (``step_inliers``: what one node step away
shares) and its path neighbour just outside the temporal window (``path_inliers``) gives
the recording's own reference; each end's points, triangulated by its step and seen from the
other view, say how far apart the views are (``distance_steps``, node steps). ``steps`` reads
every consecutive pair as a relative motion: the step factors of the pose graph (stage 7).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from .. import sphere
from ..params import MapParams
from ..shift import original_yaw, wrap_degrees
from .pairs import Pairs, Steps

# Columns of a fit row (``PairGeometry.fits``).
MATCHES, INLIERS, RATIO, YAW, MOTION, PLANE, PARALLAX = range(7)


class PairGeometry:
    """Two-view fits of node pairs, cached per frame pair in ``cache`` (kept across re-maps)."""

    def __init__(self, features, node_rows: np.ndarray, shifts: np.ndarray, frame_width: int,
                 columns=None, cache: Optional[dict] = None, recording: Optional[np.ndarray] = None):
        self.features, self.columns = features, columns
        self.node_rows = np.asarray(node_rows, np.int64)
        # each node's recording: a node's path neighbours are those of its own recording
        self.recording = np.zeros(self.node_rows.size, np.int64) if recording is None else np.asarray(recording)
        self.shifts = np.asarray(shifts, np.int64)
        self.frame_width = int(frame_width)
        self.cache = {} if cache is None else cache

    @property
    def known(self) -> bool:
        return self.features is not None

    def fits(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Rows (matches, inliers, inlier ratio, yaw, motion azimuth, plane share, parallax) of
        the shifted frames of node pairs (a, b); only pairs not fitted before are fitted."""
        store = self.cache.setdefault("geometry", {})
        keys = list(zip(self.node_rows[a].tolist(), self.node_rows[b].tolist()))
        todo = sorted({k for k in keys if k not in store})
        if todo:
            arr = np.asarray(todo, np.int64)
            res = sphere.verify_pairs(self.features, arr[:, 0], arr[:, 1])
            cols = ("matches", "inliers", "inlier_ratio", "yaw_deg", "motion_deg", "plane_share", "parallax_deg")
            for j, k in enumerate(todo):
                store[k] = tuple(float(res[c][j]) for c in cols)
        return np.asarray([store[k] for k in keys], np.float64).reshape(-1, 7)

    def two_view(self, row_a: int, row_b: int):
        """``engine.sphere.two_view`` of two frames, cached per frame pair."""
        store = self.cache.setdefault("two_view", {})
        key = (int(row_a), int(row_b))
        if key not in store:
            store[key] = sphere.two_view(self.features.of(key[0]), self.features.of(key[1]))
        return store[key]

    def neighbour_inliers(self, ends: np.ndarray, gap: int, partners: Optional[np.ndarray] = None) -> np.ndarray:
        """Inliers of each node in ``ends`` with the node ``gap`` before or after it, whichever
        shares more (0 where neither exists); never with its loop's other end (``partners``)."""
        m = self.node_rows.size
        best = np.zeros(ends.size, np.int64)
        for step in (-gap, gap):
            other = ends + step
            ok = (other >= 0) & (other < m)
            ok[ok] &= self.recording[other[ok]] == self.recording[ends[ok]]
            if partners is not None:
                ok &= other != partners
            if ok.any():
                lo, hi = np.minimum(ends[ok], other[ok]), np.maximum(ends[ok], other[ok])
                best[ok] = np.maximum(best[ok], self.fits(lo, hi)[:, INLIERS].astype(np.int64))
        return best

    def distance_steps(self, a: np.ndarray, b: np.ndarray, max_sigma: float) -> np.ndarray:
        """How far apart the two views of each pair are, in node steps: per end, the median of
        ``engine.sphere.resected_distance`` of the pair against the end's steps to its previous
        and next node (those known within ``max_sigma`` steps); the mean of the two ends (NaN
        unless both are known). Each end's own step is one node step long, and the points it
        triangulates give the scale two views lack (docs/method.md)."""
        store = self.cache.setdefault("distance_steps", {})
        rows, m, rec = self.node_rows, self.node_rows.size, self.recording
        out = np.full(a.size, np.nan)
        for k, (i, j) in enumerate(zip(a.tolist(), b.tolist())):
            near = [(end, side, o) for end, side in ((i, 0), (j, 1)) for o in (end - 1, end + 1)
                    if 0 <= o < m and rec[o] == rec[end] and o not in (i, j)]
            key = (int(rows[i]), int(rows[j]), float(max_sigma)) + tuple((side, int(rows[o])) for _, side, o in near)
            if key not in store:
                loop, found = self.two_view(rows[i], rows[j]), ([], [])
                for end, side, o in near:
                    step = self.two_view(rows[min(end, o)], rows[max(end, o)])
                    d, sigma = sphere.resected_distance(loop, side, step, 0 if end < o else 1)
                    if sigma <= max_sigma:   # NaN compares False
                        found[side].append(d)
                store[key] = float(np.mean([np.median(d) for d in found])) if all(found) else np.nan
            out[k] = store[key]
        return out

    def column_yaw(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Relative heading of original frames from column signatures, where geometry has none."""
        from ..verify import align_nodes, pair_yaw

        _, sh = align_nodes(self.columns, a, b)
        return pair_yaw(sh, self.columns.shape[1], self.shifts[a], self.shifts[b], self.frame_width)

    def measure(self, pairs: Pairs, params: MapParams) -> Pairs:
        """Stage 4: ``pairs`` with their geometry (the measured distance where a pair has
        ``auto_inliers``; it costs up to four more fits) and ``confidence``: calibrated score
        + positive support + inliers beyond the path's own / ``inliers_per_z``."""
        n = len(pairs)
        for name, fill in (("matches", -1), ("inliers", -1), ("path_inliers", -1), ("step_inliers", -1)):
            setattr(pairs, name, np.full(n, fill, np.int64))
        for name in ("inlier_ratio", "yaw", "plane_share", "distance_steps", "bearing"):
            setattr(pairs, name, np.full(n, np.nan))
        if self.known and n:
            a, b = pairs.a, pairs.b
            fit = self.fits(a, b)
            pairs.matches, pairs.inliers = fit[:, MATCHES].astype(np.int64), fit[:, INLIERS].astype(np.int64)
            pairs.inlier_ratio, pairs.plane_share = fit[:, RATIO], fit[:, PLANE]
            pairs.yaw = original_yaw(fit[:, YAW], self.shifts[a], self.shifts[b], self.frame_width)
            pairs.bearing = wrap_degrees(fit[:, MOTION] - (self.shifts[a] * 360.0 / self.frame_width
                                                           if self.frame_width > 0 else 0.0))
            gap = params.neighbor_node_num + 1
            pairs.path_inliers = np.maximum(self.neighbour_inliers(a, gap, partners=b),
                                            self.neighbour_inliers(b, gap, partners=a))
            pairs.step_inliers = np.minimum(self.neighbour_inliers(a, 1), self.neighbour_inliers(b, 1))
            near = np.flatnonzero(pairs.inliers >= max(int(params.auto_inliers), 1))
            pairs.distance_steps[near] = self.distance_steps(a[near], b[near], params.loop_sigma_steps)
        if self.columns is not None and n:
            unknown = ~np.isfinite(pairs.yaw)
            if unknown.any():
                pairs.yaw[unknown] = self.column_yaw(pairs.a[unknown], pairs.b[unknown])
        lift = np.where(pairs.inliers > 0, np.maximum(pairs.inliers - np.maximum(pairs.path_inliers, 0), 0), 0)
        sup = np.where(np.isfinite(pairs.support), np.maximum(pairs.support, 0.0), 0.0)
        pairs.confidence = pairs.score + sup + lift / params.inliers_per_z
        return pairs

    def steps(self, params: MapParams) -> Optional[Steps]:
        """Every consecutive node pair as a relative motion (None without features), cached.

        A step whose essential model turns the camera by more than ``ambiguous_turn_deg`` is
        read again as planar motion (``engine.sphere.planar_yaw``: every turn and direction,
        the one most matches agree with); where the two readings disagree by more than a
        quarter turn the step takes the planar yaw and its direction of motion is unknown. A
        step still turning more than ``ambiguous_turn_deg`` is ``ambiguous``: a scene that
        looks the same turned round (a symmetric corridor) fits a half turn as well as the
        straight step, so the pose graph lets the loops outvote it."""
        m = self.node_rows.size
        if not self.known or m < 2:
            return None
        key = ("steps", hash(self.node_rows.tobytes()), hash(self.shifts.tobytes()), params.ambiguous_turn_deg)
        if key not in self.cache:
            k = np.arange(m - 1)
            fit = self.fits(k, k + 1)
            yaw = original_yaw(fit[:, YAW], self.shifts[:-1], self.shifts[1:], self.frame_width)
            motion = fit[:, MOTION] - (self.shifts[:-1] * 360.0 / self.frame_width if self.frame_width > 0 else 0.0)
            planar = self.cache.setdefault("planar", {})
            for i in np.flatnonzero((np.abs(yaw) > params.ambiguous_turn_deg) & np.isfinite(fit[:, MOTION])):
                rows = (int(self.node_rows[i]), int(self.node_rows[i + 1]))
                if rows not in planar:
                    planar[rows] = sphere.planar_yaw(self.two_view(*rows))[0]
                other = float(original_yaw(planar[rows], self.shifts[i], self.shifts[i + 1], self.frame_width))
                if abs(wrap_degrees(other - yaw[i])) > 90.0:
                    yaw[i], motion[i] = other, np.nan
            ambiguous = np.abs(yaw) > params.ambiguous_turn_deg                # NaN: no
            still = fit[:, PARALLAX] < params.still_parallax_deg            # NaN (no model): moved
            self.cache[key] = Steps(yaw=yaw, motion=wrap_degrees(motion), still=still, ambiguous=ambiguous)
        return self.cache[key]
