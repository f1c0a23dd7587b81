"""Two-view geometry between equirectangular panoramas, on bearing vectors.

A place revisit is checked by fitting a camera motion to matched local features
(``engine.features``): an essential matrix (the camera moved) or a pure rotation (it
stood at the same spot and turned). The number of matches that agree with the best
model (its inliers) is the evidence; how many are enough is the caller's rule.

Conventions (all in one place):
- Bearings (``bearings``): the camera frame is x forward (the image's centre column),
  y left, z up (the robot body frame of ROS REP 103). Column fraction ``u`` is the
  longitude clockwise from forward, ``2*pi*(u - 0.5)``, because columns of an
  equirectangular image increase as one turns right; row fraction ``v`` is the
  elevation ``pi*(0.5 - v)`` (top row = up).
- ``TwoView.rotation`` R maps bearings of a to bearings of b: a far point seen at
  ``x`` in a is seen at ``R @ x`` in b; with the essential model ``X_b = R X_a + t``
  and ``x_b^T E x_a = 0`` for ``E = [t]x R``.
- ``TwoView.yaw_deg`` follows ``engine.shift.relative_yaw``: how far (degrees, positive
  towards increasing column) the content of a appears displaced in b, in (-180, 180].
  Content turns clockwise in the image when the camera turns anticlockwise, so it is
  also b's heading minus a's (anticlockwise positive): ``atan2(-R[1, 0], R[0, 0])``.
- Features are extracted from the panorama-SHIFTED frames; ``yaw_of_originals`` adds
  the shifts back (the arithmetic of ``engine.verify.pair_yaw``).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .features import FeatureTable, LocalFeatures

# Lowe's ratio test (Lowe 2004, fig. 11: 0.8 drops 90 % of false matches and < 5 % of true ones).
RATIO = 0.8
# Inlier threshold: angle (radians) between a bearing and the model's prediction (the
# rotated bearing, or the epipolar great circle). 0.015 rad = 0.86 degree, about one pixel
# of the image SIFT works on (engine.features: 256 columns, doubled inside SIFT): keypoints
# are located to a fraction of that; resampling and a rolling shutter add a little.
THRESHOLD = 0.015
# RANSAC: hypotheses are drawn and scored in batches (the first BATCH = 32, later 8 * BATCH:
# a clean pair stops after the first, and each batch costs a fixed ~0.2 ms of numpy calls);
# sampling stops when a fully clean sample of a model with w = max(best inliers so far,
# floor) / matches would have been drawn with CONFIDENCE (1 - (1 - w^s)^n), or at the cap.
# The floor is the fewest inliers that could change the result (MIN_INLIERS; for the
# rotation, which is fitted second, ROTATION_SHARE of the essential model's inliers), so a
# pair whose best model stays below it costs the draws that rule such a model out, not
# the cap. Caps: 2-point rotation 256 draws (a clean sample for w = 0.15 with 99.7 %); 8-point
# essential 1024 draws (w = 0.5 with 98 %, w = 0.4 with 49 %). Mutual matches that pass the
# ratio test are mostly right on real revisits (GoPro MAX steps of 1-9 m: 58-89 % inliers), so
# the cap is rarely reached there; a pair with 70 % wrong matches usually fails (that is weak
# evidence anyway); false pairs with 20-60 matches reach it (the worst case, ~5-7 ms).
# Costs per pair (CPU, one thread): benchmarks/bench_sphere.py, benchmarks/results/sphere.md.
CONFIDENCE = 0.99
BATCH = 32
ROTATION_DRAWS = 256
ESSENTIAL_DRAWS = 1024
REFINE_STEPS = 2
# Model choice: the essential model's test is one-dimensional (distance to a great circle)
# and a pure rotation is a degenerate case of it, so it always collects at least the
# rotation's inliers plus chance ones. A rotation is preferred when it explains at least
# ROTATION_SHARE of the essential model's inliers. Measured (rotation / essential inliers):
# a roll of tests/data/examplepano_1024.jpg 232/233; a real 1 m step (GoPro MAX 1 -> 2) 55/119;
# synthetic 1 m steps with scenery 2-10 m away 6/180 .. 10/170 (tests/test_sphere.py cases).
# The essential model is fitted first: on a moving camera (most pairs) the rotation's RANSAC
# then needs a handful of draws to rule out a rotation with ROTATION_SHARE of its inliers.
ROTATION_SHARE = 0.8
# Below this many inliers neither model is reported ("none"): an 8-point model always
# fits its own sample, so 8 inliers and 2 more say nothing. Not a loop threshold. A pair with
# fewer matches than this is "none" without any fitting (inliers 0).
MIN_INLIERS = 10
MODEL_CODES = {"none": 0, "rotation": 1, "essential": 2}


_blas = None


def _one_blas_thread():
    """A context with BLAS on one thread. The products here are tiny (9 columns, a few
    hundred rows); OpenBLAS splits them over its threads anyway, and on the shared 2-core
    machine that cost ~5 times the CPU of one thread (bench_sphere.py --pairs: 15 vs 3 ms
    per pair). ~10 us to enter (threadpoolctl); no limit when it is not installed."""
    global _blas
    if _blas is None:
        try:
            from threadpoolctl import ThreadpoolController
            _blas = ThreadpoolController()
        except ImportError:      # pragma: no cover - a declared dependency
            _blas = False
    return _blas.limit(limits=1, user_api="blas") if _blas else contextlib.nullcontext()


@dataclass
class TwoView:
    matches: int
    inliers: int
    inlier_ratio: float             # inliers / matches (0 without matches)
    model: str                      # 'essential' | 'rotation' | 'none'
    rotation: np.ndarray            # float64 (3, 3), bearings of a -> bearings of b (identity for 'none')
    yaw_deg: Optional[float]        # relative_yaw convention, None for 'none'
    uv_a: np.ndarray                # float32 (m, 2) matched features in a (engine.features uv)
    uv_b: np.ndarray                # float32 (m, 2) their matches in b
    inlier_mask: np.ndarray         # bool (m,) the matches the model explains
    translation: Optional[np.ndarray] = None   # unit (3,) direction of t for 'essential'


def bearings(uv: np.ndarray) -> np.ndarray:
    """Unit vectors (float64, (k, 3)) of equirectangular fractions ``uv`` (k, 2), see the module notes."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    lon = 2.0 * np.pi * (uv[:, 0] - 0.5)
    el = np.pi * (0.5 - uv[:, 1])
    c = np.cos(el)
    return np.stack([c * np.cos(lon), -c * np.sin(lon), np.sin(el)], axis=1)


def to_uv(x: np.ndarray) -> np.ndarray:
    """Inverse of ``bearings``: unit vectors (k, 3) to fractions (k, 2) in [0, 1)."""
    x = np.asarray(x, np.float64).reshape(-1, 3)
    x = x / np.linalg.norm(x, axis=1, keepdims=True)
    u = (np.arctan2(-x[:, 1], x[:, 0]) / (2.0 * np.pi) + 0.5) % 1.0
    v = 0.5 - np.arcsin(np.clip(x[:, 2], -1.0, 1.0)) / np.pi
    return np.stack([u, v], axis=1)


def yaw_of_rotation(r: np.ndarray) -> float:
    """``relative_yaw``-convention yaw (degrees) of a rotation of bearings a -> b."""
    deg = float(np.degrees(np.arctan2(-r[1, 0], r[0, 0])))
    return 180.0 if deg <= -180.0 else deg


def yaw_of_originals(two_view_yaw_deg, shift_a, shift_b, frame_width: int):
    """Relative yaw of the ORIGINAL frames of a pair whose features come from the frames
    rolled left by ``shift_a``, ``shift_b`` columns (``Descriptors.shifts``) of
    ``frame_width`` columns. Scalars give a float, arrays an array (NaN stays NaN)."""
    from .verify import pair_yaw

    # pair_yaw adds the shifts to an alignment given in columns of some width: degrees
    # are columns of a 360-column image.
    out = pair_yaw(two_view_yaw_deg, 360, shift_a, shift_b, frame_width)
    return float(out) if np.ndim(out) == 0 else out


def match(fa: LocalFeatures, fb: LocalFeatures, ratio: float = RATIO) -> tuple[np.ndarray, np.ndarray]:
    """Mutual nearest neighbours that pass Lowe's ratio test: indices ``(ia, ib)``.

    Exact brute force in numpy: one float32 product ``a @ b.T`` gives both directions and
    the ratio test (squared distances |a|^2 + |b|^2 - 2 a.b). For a few hundred features per
    frame a k-d tree (FLANN) is neither faster nor exact, and it is randomised; OpenCV's
    ``BFMatcher.knnMatch`` and ``batchDistance(K=2)`` measured 3.4 and 2.5 ms per pair of
    ~325 features against 0.4 ms for this (one thread, benchmarks/results/sphere.md).
    """
    if len(fa) < 2 or len(fb) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    da = fa.desc.astype(np.float32)
    db = fb.desc.astype(np.float32)
    na2, nb2 = (da * da).sum(1), (db * db).sum(1)
    # Row minima need only |b|^2 - 2 a.b (|a|^2 is constant along a row): two passes find
    # the nearest and, with it masked, the second nearest (cheaper than a partition).
    s = db @ (-2.0 * da).T
    s += nb2[:, None]
    s = s.T                                                   # (len(a), len(b))
    ia = np.arange(da.shape[0])
    ib = np.argmin(s, axis=1)
    best = s[ia, ib]
    s[ia, ib] = np.inf
    second = s.min(axis=1)
    s[ia, ib] = best
    s += na2[:, None]                                         # full squared distances
    mutual = np.argmin(s, axis=0)[ib] == ia
    ok = (np.maximum(best + na2, 0.0) < (ratio * ratio) * np.maximum(second + na2, 0.0)) & mutual
    return ia[ok].astype(np.int64), ib[ok].astype(np.int64)


# -- minimal solvers and scores, vectorised over hypotheses (leading axis) -----------------

def _kabsch(a: np.ndarray, b: np.ndarray, w: Optional[np.ndarray] = None) -> np.ndarray:
    """Rotations (h, 3, 3) minimising sum |b - R a|^2 for point sets (h, k, 3)."""
    m = np.einsum("hki,hkj->hij", b if w is None else b * w[..., None], a)
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[:, :, 2] *= d[:, None]
    return u @ vt


def _triads(x: np.ndarray) -> np.ndarray:
    """Orthonormal frames (h, 3, 3), columns: the bisector of two bearings (h, 2, 3), the
    normal of their plane, and the third axis."""
    s = x[:, 0] + x[:, 1]
    n = _cross(x[:, 0], x[:, 1])
    s /= np.maximum(np.sqrt((s * s).sum(axis=1, keepdims=True)), 1e-12)
    n /= np.maximum(np.sqrt((n * n).sum(axis=1, keepdims=True)), 1e-12)
    return np.stack([s, n, _cross(s, n)], axis=2)


def _cross(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Cross products of (h, 3) rows (np.cross costs several times more on small arrays)."""
    return np.stack([x[:, 1] * y[:, 2] - x[:, 2] * y[:, 1], x[:, 2] * y[:, 0] - x[:, 0] * y[:, 2],
                     x[:, 0] * y[:, 1] - x[:, 1] * y[:, 0]], axis=1)


def _rotation_fit(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotations (h, 3, 3) of bearing sets (h, k, 3). Two points: the rotation that takes a's
    bisector and plane normal to b's, which is the least-squares (Kabsch) rotation of a pair
    in closed form (no SVD per hypothesis); more points: ``_kabsch``."""
    if a.shape[1] != 2:
        return _kabsch(a, b)
    return _triads(b) @ _triads(a).transpose(0, 2, 1)


_REFLECTOR_MASK = np.arange(9)[None, :] > np.arange(8)[:, None]   # below-diagonal part of a 9 x 8 QR
_REFLECTOR_ONES = np.eye(8, 9)


def _null_vectors(rows: np.ndarray) -> np.ndarray:
    """Unit null vectors (h, 9) of minimal systems of 8 rows (h, 8, 9).

    The last column of Q in a complete QR of the rows' transpose is orthogonal to all of
    them. LAPACK's raw Householder form (one batched call) is half the cost of forming Q;
    the 8 reflectors are applied to e_9 in numpy, vectorised over the hypotheses.
    """
    hh, tau = np.linalg.qr(rows.transpose(0, 2, 1), mode="raw")   # hh (h, 8, 9): reflector i in row i
    v = np.where(_REFLECTOR_MASK, hh, 0.0) + _REFLECTOR_ONES
    x = np.zeros((rows.shape[0], 9))
    x[:, 8] = 1.0
    for i in range(7, -1, -1):       # Q e_9 = H_0 H_1 ... H_7 e_9, H_i = I - tau_i v_i v_i^T
        vi = v[:, i]
        x -= (tau[:, i] * np.einsum("hj,hj->h", vi, x))[:, None] * vi   # (einsum: sum(axis=1) of short rows is slow)
    return x


def _nearest_essential(e: np.ndarray) -> np.ndarray:
    """The nearest matrices (h, 3, 3) with singular values (1, 1, 0): U diag(1, 1, 0) V^T of
    E = U S V^T, written as E V2 S2^-1 V2^T with V2, S2^2 the two largest eigenpairs of E^T E
    (one batched 3 x 3 ``eigh``: ~1.3 us per hypothesis against ~2 us for the SVD; the same
    matrices to rounding)."""
    w, v = np.linalg.eigh(e.transpose(0, 2, 1) @ e)                 # ascending eigenvalues
    v2 = v[:, :, 1:]
    s2 = np.sqrt(np.maximum(w[:, 1:], 1e-300))
    return (e @ v2 / s2[:, None, :]) @ v2.transpose(0, 2, 1)


def _essential_fit(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Essential matrices (h, 3, 3) by the linear 8-point method on (h, k, 3) bearings (k >= 8).

    Batched over all hypotheses, a few LAPACK calls per batch (not per hypothesis):
    ``_null_vectors`` for minimal samples (least squares, an SVD, for refinement on more
    points), then ``_nearest_essential``. Measured on one thread: ~3 us per hypothesis
    against ~8 us for the nine 8 x 8 minors and a 3 x 3 SVD it replaced.
    """
    rows = (b[..., :, None] * a[..., None, :]).reshape(a.shape[0], a.shape[1], 9)   # b^T E a = rows . vec(E)
    if rows.shape[1] == 8:
        e = _null_vectors(rows)
    else:
        e = np.linalg.svd(rows, full_matrices=False)[2][:, -1, :]   # (no k x k U for k inliers)
    return _nearest_essential(e.reshape(-1, 3, 3))


def _outer(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Rows vec(x y^T) (m, 9): ``x^T M y == _outer(x, y) @ vec(M)``, so one matrix product
    scores every hypothesis at once."""
    return (x[:, :, None] * y[:, None, :]).reshape(-1, 9)


def _rotation_inliers(r: np.ndarray, ba: np.ndarray, threshold: float) -> np.ndarray:
    """Inliers (h, m) of rotations: chord |R a - b| < threshold (~ the angle for small ones),
    i.e. b^T R a > 1 - threshold^2 / 2 (|R a - b|^2 = 2 - 2 b^T R a); ``ba`` = ``_outer(b, a)``."""
    return (ba @ r.reshape(-1, 9).T).T > 1.0 - 0.5 * threshold * threshold


def _epipolar_inliers(e: np.ndarray, ba: np.ndarray, aa: np.ndarray, bb: np.ndarray,
                      threshold: float) -> np.ndarray:
    """Inliers (h, m) of essential matrices: the sine of the larger angle of b from a's
    epipolar great circle and of a from b's, |b^T E a| / |E a| and |b^T E a| / |E^T b|, below
    ``threshold`` (compared squared: no root or division per match and hypothesis;
    ``ba``, ``aa``, ``bb``: ``_outer`` of the bearings)."""
    r = ba @ e.reshape(-1, 9).T                                      # (m, h)
    ea2 = aa @ np.matmul(e.transpose(0, 2, 1), e).reshape(-1, 9).T  # |E a|^2
    eb2 = bb @ np.matmul(e, e.transpose(0, 2, 1)).reshape(-1, 9).T  # |E^T b|^2
    return (r * r < (threshold * threshold) * np.maximum(np.minimum(ea2, eb2), 1e-24)).T


def _samples(rng: np.random.Generator, h: int, m: int, k: int) -> np.ndarray:
    """``h`` draws of ``k`` distinct indices of ``m`` (h, k), uniform over the k-subsets:
    Floyd's algorithm, vectorised over the draws (k steps; redrawing rows with a repeat
    looped often: 8 of 40 has a repeat in half the draws)."""
    out = np.empty((h, k), np.int64)
    for s, j in enumerate(range(m - k, m)):
        t = (rng.random(h) * (j + 1)).astype(np.int64)      # uniform in 0..j
        taken = (out[:, :s] == t[:, None]).any(axis=1)
        out[:, s] = np.where(taken, j, t)
    return out


def _ransac(a, b, rng, k, draws, fit, inliers, floor=0):
    """Best model of ``fit`` (minimal samples of ``k``), then refined on its inliers.
    ``inliers(models)`` gives the (h, m) inlier masks of all matches.

    Sampling stops once a model with ``max(best so far, floor)`` inliers would have been
    drawn cleanly with ``CONFIDENCE``: ``floor`` is the fewest inliers that could change
    the caller's decision (a model below it is as good as none), so a pair whose best model
    stays below it costs the draws that rule it out, not the cap.
    """
    m = a.shape[0]
    best_model, best_mask, best_count, done = None, np.zeros(m, bool), -1, 0

    def draws_needed(count):
        fail = 1.0 - (max(count, floor) / m) ** k
        if fail <= 0.0:
            return 1
        return int(min(draws, max(1.0, np.ceil(np.log(1.0 - CONFIDENCE) / np.log(fail)))))

    needed = draws_needed(0)
    while done < needed:
        # The first batch is small (clean pairs stop after it); later ones larger, as each
        # batch costs some fixed numpy overhead.
        h = min(BATCH if done == 0 else 8 * BATCH, needed - done)
        idx = _samples(rng, h, m, k)
        models = fit(a[idx], b[idx])
        inl = inliers(models)
        counts = inl.sum(axis=1)
        j = int(np.argmax(counts))
        if counts[j] > best_count:
            best_model, best_mask, best_count = models[j], inl[j], int(counts[j])
        done += h
        needed = draws_needed(best_count)
    for _ in range(REFINE_STEPS):   # least squares on all inliers usually gains a few
        if best_count < k:
            break
        model = fit(a[best_mask][None], b[best_mask][None])
        inl = inliers(model)[0]
        if inl.sum() < best_count:
            break
        best_model, best_mask, best_count = model[0], inl, int(inl.sum())
    return best_model, best_mask, best_count


def _decompose(e: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) of an essential matrix: the one of four that puts most points in front of both views.

    Only points whose two rays are at least ``PARALLAX_MIN`` apart vote (all of them where
    none are): a point nearly at infinity, or near the direction of motion, has no
    parallax to speak of, and the sign of its depth follows the fitted rotation's small
    error (half a degree will do) rather than the motion, the same way for all such points;
    outdoors (facades across a street, the horizon) they can outnumber the near ones and
    turn the direction of motion round. On the first synthetic family
    (seeds 0-4) 4-23 node steps of a recording read 180 degrees backwards outdoors when
    all points voted (dead reckoning going one step back instead of one forward), and
    none with this rule; indoor recordings did not change. The same threshold as
    ``ray_depths``, which gives such rays no depth; no new number."""
    u, _, vt = np.linalg.svd(e)
    if np.linalg.det(u) < 0:
        u = -u
    if np.linalg.det(vt) < 0:
        vt = -vt
    w = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    best, best_front = None, -1
    for r in (u @ w @ vt, u @ w.T @ vt):
        ra = a @ r.T
        seen_apart = 1.0 - np.einsum("ij,ij->i", ra, b) ** 2 > PARALLAX_MIN ** 2
        if not seen_apart.any():
            seen_apart = np.ones(len(a), bool)
        for t in (u[:, 2], -u[:, 2]):
            # lambda_b b = lambda_a R a + t, least squares per point (2 x 2 normal equations).
            p, q = ra, -b
            a11, a12, a22 = (p * p).sum(1), (p * q).sum(1), (q * q).sum(1)
            r1, r2 = -(p @ t), -(q @ t)
            det = a11 * a22 - a12 * a12
            ok = np.abs(det) > 1e-12
            la = np.where(ok, (a22 * r1 - a12 * r2) / np.where(ok, det, 1.0), -1.0)
            lb = np.where(ok, (a11 * r2 - a12 * r1) / np.where(ok, det, 1.0), -1.0)
            front = int(np.count_nonzero((la > 0) & (lb > 0) & seen_apart))
            if front > best_front:
                best, best_front = (r, t), front
    return best


def two_view(fa: LocalFeatures, fb: LocalFeatures, seed: int = 0) -> TwoView:
    """Match two frames' features and fit the better of an essential matrix and a pure rotation.

    Deterministic for a given ``seed``. See the module notes for the conventions and
    ``ROTATION_SHARE`` / ``MIN_INLIERS`` for the choice of model. BLAS runs on one thread
    meanwhile (``_one_blas_thread``).
    """
    with _one_blas_thread():
        return _two_view(fa, fb, seed)


def _two_view(fa: LocalFeatures, fb: LocalFeatures, seed: int) -> TwoView:
    ia, ib = match(fa, fb)
    m = int(ia.size)
    uv_a, uv_b = fa.uv[ia].astype(np.float32), fb.uv[ib].astype(np.float32)
    none = TwoView(m, 0, 0.0, "none", np.eye(3), None, uv_a, uv_b, np.zeros(m, bool))
    if m < MIN_INLIERS:   # no model could reach MIN_INLIERS: nothing to fit
        return none
    a, b = bearings(uv_a), bearings(uv_b)
    rng = np.random.default_rng(seed)
    ba, aa, bb = _outer(b, a), _outer(a, a), _outer(b, b)
    ess, ess_mask, ess_n = _ransac(a, b, rng, 8, ESSENTIAL_DRAWS, _essential_fit,
                                   lambda e: _epipolar_inliers(e, ba, aa, bb, THRESHOLD), floor=MIN_INLIERS)
    # The rotation is chosen only with at least ROTATION_SHARE of the essential model's
    # inliers (and MIN_INLIERS): its RANSAC need only rule out models of that size, which
    # for a moving camera (most pairs) takes one batch instead of all ROTATION_DRAWS.
    rot_floor = max(MIN_INLIERS, int(np.ceil(ROTATION_SHARE * ess_n)))   # <= m
    rot, rot_mask, rot_n = _ransac(a, b, rng, 2, ROTATION_DRAWS, _rotation_fit,
                                   lambda r: _rotation_inliers(r, ba, THRESHOLD), floor=rot_floor)
    if rot_n >= ROTATION_SHARE * ess_n:
        model, mask, r, t = "rotation", rot_mask, rot, None
    else:
        r, t = _decompose(ess, a[ess_mask], b[ess_mask])
        model, mask = "essential", ess_mask
    n = int(mask.sum())
    if n < MIN_INLIERS:
        return TwoView(m, n, n / m, "none", np.eye(3), None, uv_a, uv_b, mask)
    return TwoView(m, n, n / m, model, np.asarray(r, np.float64), yaw_of_rotation(r), uv_a, uv_b, mask,
                   None if t is None else np.asarray(t, np.float64))


# Planar motion (``planar_yaw``): the camera upright, turning about the vertical and moving
# in the horizontal plane. Searched exhaustively on a grid of PLANAR_STEP_DEG in both the
# turn and the direction of motion; a match agrees within PLANAR_BAND_THRESHOLDS times
# THRESHOLD, since the model leaves out the camera's tilt and roll of a few degrees and the
# grid's half step (2.6 degrees against 0.86).
PLANAR_STEP_DEG = 1.0
PLANAR_BAND_THRESHOLDS = 3.0


def planar_yaw(tv: TwoView) -> tuple[float, int]:
    """The turn (``yaw_deg`` convention, of the frames as stored) of the planar motion that
    the most of ``tv``'s matches agree with, and how many agree; (NaN, 0) without matches.

    RANSAC of a general essential model draws samples of eight matches, and where a third of
    the matches or fewer are right it finds the best model by luck, or a model of a scene that
    looks alike turned round (``engine.loops.geometry.PairGeometry.steps``). A camera on a robot stays
    about upright, so the motion between two nearby views has two degrees of freedom, few
    enough to try every turn and every direction at ``PLANAR_STEP_DEG``: no sampling at all.
    A match agrees when the sine of its distance to the epipolar great circle is within the
    band (``_epipolar_inliers``' test, both views)."""
    if tv.matches == 0:
        return float("nan"), 0
    a, b = bearings(tv.uv_a), bearings(tv.uv_b)
    turn = np.radians(np.arange(-180.0, 180.0, PLANAR_STEP_DEG))
    go = np.radians(np.arange(0.0, 180.0, PLANAR_STEP_DEG))     # t and -t: one great circle
    t = np.stack([np.cos(go), np.sin(go)])                       # (2, directions)
    band = (PLANAR_BAND_THRESHOLDS * THRESHOLD) ** 2
    tb2 = 1.0 - (b[:, :2] @ t) ** 2                              # |E^T b|^2 = |t x b|^2
    best, best_turn = -1, 0.0
    for th in turn:
        c, s = np.cos(th), np.sin(th)
        ra = np.stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1], a[:, 2]], axis=1)
        r = _cross(ra, b)[:, :2] @ t                             # b^T [t]x R a = t . (R a x b)
        ta2 = 1.0 - (ra[:, :2] @ t) ** 2                         # |E a|^2 = |t x R a|^2
        count = (r * r < band * np.minimum(ta2, tb2)).sum(axis=0).max()
        if count > best:
            best, best_turn = int(count), float(th)
    return float(np.degrees(-best_turn)), best                   # yaw_of_rotation(Rz(th)) = -th


def verify_pairs(table: FeatureTable, a: np.ndarray, b: np.ndarray, seed: int = 0) -> dict:
    """``two_view`` of frames ``a[k]``, ``b[k]`` of ``table`` for every candidate pair k.

    Returns arrays of len(a): ``inliers``, ``matches`` (int64), ``inlier_ratio`` (float32),
    ``yaw_deg`` (float64, of the frames as stored: add the shifts back with
    ``yaw_of_originals``; NaN for model 'none'), ``model`` (int8, ``MODEL_CODES``),
    ``motion_deg`` (``motion_azimuth`` of the essential model; NaN for the other models),
    ``plane_share`` (``plane_share`` of the essential model's inliers; NaN otherwise) and
    ``parallax_deg`` (``parallax`` of the model's inliers; NaN for model 'none').
    """
    a, b = np.asarray(a, np.int64).ravel(), np.asarray(b, np.int64).ravel()
    n = a.size
    out = {"inliers": np.zeros(n, np.int64), "matches": np.zeros(n, np.int64),
           "inlier_ratio": np.zeros(n, np.float32), "yaw_deg": np.full(n, np.nan),
           "model": np.zeros(n, np.int8), "motion_deg": np.full(n, np.nan),
           "plane_share": np.full(n, np.nan), "parallax_deg": np.full(n, np.nan)}
    cache: dict[int, LocalFeatures] = {}

    def feats(i: int) -> LocalFeatures:
        if i not in cache:
            cache[i] = table.of(i)
        return cache[i]

    for k in range(n):
        tv = two_view(feats(int(a[k])), feats(int(b[k])), seed=seed)
        out["inliers"][k], out["matches"][k] = tv.inliers, tv.matches
        out["inlier_ratio"][k] = tv.inlier_ratio
        out["model"][k] = MODEL_CODES[tv.model]
        if tv.yaw_deg is not None:
            out["yaw_deg"][k] = tv.yaw_deg
            out["parallax_deg"][k] = parallax(tv)
        if tv.model == "essential" and tv.translation is not None:
            out["motion_deg"][k] = motion_azimuth(tv.rotation, tv.translation)
            m = tv.inlier_mask
            out["plane_share"][k] = plane_share(tv.rotation, tv.translation,
                                                bearings(tv.uv_a[m]), bearings(tv.uv_b[m]), seed)
    return out


# Plane share: inliers are triangulated with the essential model (midpoint of the two rays);
# rays nearly parallel (less than PARALLAX_MIN radians apart, 0.6 degree: under one pixel of
# the image SIFT works on) give no depth and are left out. A point is on a plane when it lies
# within PLANE_TOL of its own distance from it (depth from one-pixel parallax is that
# uncertain at a few metres); planes are drawn from PLANE_DRAWS random triples (the dominant
# plane of 400 points holding 30 % of them is missed by all 200 with probability 0.4 %).
PARALLAX_MIN = 0.01
PLANE_TOL = 0.05
PLANE_DRAWS = 200
PLANE_MIN_POINTS = 12


def ray_depths(r: np.ndarray, t: np.ndarray, a: np.ndarray, b: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depths of matched bearings (a in view a, b in view b, unit (n, 3)) triangulated with
    ``X_b = R X_a + t`` by the midpoint of the two rays: ``(s, u, ok)`` with the point at ``s a``
    in a's frame and ``u b`` in b's, both in units of ``|t|``; ``ok`` where the rays are at
    least ``PARALLAX_MIN`` apart and the point lies in front of both views."""
    r, t = np.asarray(r, np.float64), np.asarray(t, np.float64).ravel()
    p, q = np.asarray(a, np.float64) @ r.T, np.asarray(b, np.float64)   # rays of a in b's frame
    pq = np.einsum("ij,ij->i", p, q)
    det = 1.0 - pq * pq
    ok = det > PARALLAX_MIN ** 2
    # s p - u q = -t in least squares (p, q unit)
    safe = np.where(ok, det, 1.0)
    s = (-(p @ t) + pq * (q @ t)) / safe
    u = ((q @ t) - pq * (p @ t)) / safe
    return s, u, ok & (s > 0) & (u > 0)


def plane_share(r: np.ndarray, t: np.ndarray, a: np.ndarray, b: np.ndarray, seed: int = 0) -> float:
    """Share of matched bearings (a in view a, b in view b, unit (n, 3)) whose triangulated
    points lie on the one plane that holds the most of them, for ``X_b = R X_a + t``.

    Two views of a revisited place see things at several depths (walls on both sides, the
    floor, objects); two views of a flat picture copied elsewhere (a poster, a facade print,
    a repeated wall texture) see one plane, and a plane explains any two views of it with a
    relative pose of its own, so the geometry alone cannot tell that copy from the place.
    NaN where fewer than ``PLANE_MIN_POINTS`` points have a depth."""
    s, _, ok = ray_depths(r, t, a, b)
    x = s[ok, None] * np.asarray(a, np.float64)[ok]                  # points in a's frame
    n = x.shape[0]
    if n < PLANE_MIN_POINTS:
        return float("nan")
    tri = np.random.default_rng(seed).integers(0, n, size=(PLANE_DRAWS, 3))   # a repeated point
    normal = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])   # gives no plane
    length = np.linalg.norm(normal, axis=1)
    good = length > 1e-12
    if not good.any():
        return float("nan")
    normal = normal[good] / length[good, None]
    offset = np.einsum("ij,ij->i", normal, x[tri[good, 0]])
    dist = np.abs(x @ normal.T - offset[None, :])                      # (n, planes)
    on = dist <= PLANE_TOL * np.linalg.norm(x, axis=1)[:, None]
    return float(on.sum(axis=0).max() / n)


# Points the step must triangulate among the loop's inliers for a resection
# (``resected_distance``). Chosen for the depth-ratio estimate this replaced, on the first
# synthetic family (seeds 0-4, against true positions): from 20 or more points estimates were
# all within a factor 1.42 (95 % within 12 %); from 12-19, 5 % were off by more than 1.5x. The
# resection from 8-19 points put 48 of the first family's day pairs beyond 2 m within 1.1 steps
# (far content fitted as a pure rotation), none from 20 on (docs/method.md, stage 4).
COMMON_POINTS_MIN = 20
# Times the resection drops the matches its position misses and solves again (wrong matches
# move the first solution); the position returned is always solved from the matches kept.
RESECTION_DROPS = 3


def _depths_at(tv: TwoView, end: int) -> dict:
    """Depth (units of the model's |t|) of each triangulated inlier, keyed by its feature's
    position in view ``end`` (0: a, 1: b)."""
    m = tv.inlier_mask
    s, u, ok = ray_depths(tv.rotation, tv.translation, bearings(tv.uv_a[m]), bearings(tv.uv_b[m]))
    uv = (tv.uv_a if end == 0 else tv.uv_b)[m][ok]
    depth = (s if end == 0 else u)[ok]
    return dict(zip(map(tuple, uv.tolist()), depth.tolist()))


def resected_distance(loop: TwoView, loop_end: int, step: TwoView, step_end: int) -> tuple[float, float]:
    """How far apart the two views of ``loop`` are, in units of the baseline of ``step``, and
    the standard deviation of that: two models that share one frame (view ``loop_end`` of
    ``loop``, view ``step_end`` of ``step``; 0 is a, 1 is b).

    A model of two views knows the direction between them, not the distance. The step
    triangulates the shared frame's points in units of its own length; the loop's other view
    sees the same points along its bearings, turned by the loop's rotation. Its position is
    then the one that puts every point on its bearing: linear least squares in the position
    (a resection with known rotation, the three-view idea of structure from motion), each
    point's error taken as an angle (near points pin the position, far ones hardly). Matches
    missed by more than twice the models' inlier threshold (the step's depths carry their own
    error) are dropped and the position solved again. Unlike a ratio of the two models'
    depths it needs no depth from the loop, so it holds where the loop's views are at one spot
    (a pure rotation, no baseline to triangulate with) and where few points have parallax in
    both models. The deviation is the position's, from the angular noise ``THRESHOLD``: far
    content alone leaves it large. NaN, NaN where the step has no essential model, the loop
    no model, or fewer than ``COMMON_POINTS_MIN`` points are common."""
    nothing = (float("nan"), float("nan"))
    if loop.model == "none" or step.model != "essential":
        return nothing
    depth_of = _depths_at(step, step_end)
    m = loop.inlier_mask
    shared, other = (loop.uv_a[m], loop.uv_b[m]) if loop_end == 0 else (loop.uv_b[m], loop.uv_a[m])
    keys = list(map(tuple, shared.tolist()))
    seen = np.array([k in depth_of for k in keys], bool)
    if seen.sum() < COMMON_POINTS_MIN:
        return nothing
    depth = np.array([depth_of[k] for k, s in zip(keys, seen) if s])
    rotation = np.asarray(loop.rotation, np.float64)             # X_b = R X_a (+ t)
    if loop_end == 1:
        rotation = rotation.T
    points = (bearings(shared[seen]) * depth[:, None]) @ rotation.T   # in the other view's axes
    rays = bearings(other[seen])
    used = np.ones(depth.size, bool)
    for drops in range(RESECTION_DROPS + 1):
        # minimise sum |(I - f f^T)(P + t)|^2 / |P|^2: each point's distance from its ray, as an angle
        w2 = 1.0 / np.einsum("ij,ij->i", points[used], points[used])
        across = np.eye(3)[None] - rays[used, :, None] * rays[used, None, :]
        normal = np.einsum("k,kij->ij", w2, across)
        t = -np.linalg.solve(normal + 1e-12 * np.eye(3), np.einsum("k,kij,kj->i", w2, across, points[used]))
        if drops == RESECTION_DROPS:
            break          # the position solved from the last set kept
        moved = points + t
        miss = np.linalg.norm(moved - rays * np.einsum("ij,ij->i", moved, rays)[:, None], axis=1) \
            / np.linalg.norm(moved, axis=1)
        keep = miss < 2.0 * THRESHOLD
        if keep.sum() < COMMON_POINTS_MIN:
            return nothing
        if (keep == used).all():
            break
        used = keep
    distance = float(np.linalg.norm(t))
    along = t / distance if distance > 1e-12 else np.array([1.0, 0.0, 0.0])
    covariance = THRESHOLD ** 2 * np.linalg.pinv(normal)
    return distance, float(np.sqrt(max(along @ covariance @ along, 0.0)))


def parallax(tv: TwoView) -> float:
    """How far the nearer matched points moved across the two views beyond the turn: the 90th
    percentile (degrees) of the angle between each inlier's bearing in b and its bearing in a
    turned by the model's rotation; NaN for model 'none'.

    Turning alone moves every point by the rotation and leaves no parallax; a step moves
    near points (the ground below a panorama, walls beside it) by degrees and far ones
    hardly at all, so the upper tail says whether the camera moved, and the median (often
    the far scenery outdoors) cannot. The essential model's one-dimensional test leaves
    noise along the epipolar circle in its inliers, so a camera that did not move still
    shows a degree or two (``MapParams.still_parallax_deg``)."""
    if tv.model == "none":
        return float("nan")
    m = tv.inlier_mask
    turned = bearings(tv.uv_a[m]) @ np.asarray(tv.rotation, np.float64).T
    cos = np.clip(np.einsum("ij,ij->i", turned, bearings(tv.uv_b[m])), -1.0, 1.0)
    return float(np.degrees(np.percentile(np.arccos(cos), 90)))


def motion_azimuth(r: np.ndarray, t: np.ndarray) -> float:
    """Direction (degrees, anticlockwise from a's forward axis, in (-180, 180]) in which b's
    centre lies seen from a, for ``X_b = R X_a + t``: b's centre is ``-R^T t`` in a's frame."""
    c = -np.asarray(r, np.float64).T @ np.asarray(t, np.float64)
    return float(np.degrees(np.arctan2(c[1], c[0])))
