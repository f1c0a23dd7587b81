"""Panorama shift (METHOD.md section 1) and circular alignment of panoramas.

A horizontal roll of an equirectangular image is a yaw rotation of the camera
that loses nothing. ``canonical_shift`` rolls a canonical column to the left
edge, so the same place seen from another heading gives (nearly) the same image.
The canonical column is the phase of the first circular harmonic of the per-column
colour of the horizon band: the paper's "column with the highest value", made
continuous (no jumps between two similar peaks) and insensitive to lighting. ``relative_yaw`` estimates the
heading between two panoramas by circular cross-correlation of column signatures.

Where the recording says which way the camera looked (a bag's odometry or IMU, a photo's
EXIF/XMP heading, a GoPro's orientation track), ``shift_from_heading`` / ``shift_from_yaw``
give a shift from that instead: every frame is turned to one direction of the world, so two
views of a place are aligned whatever the image content (the image-only shift aligns them
only as far as the horizon colours agree). Measured with ``python benchmarks/bench_shift.py
--mode stability`` (same-place pairs of the crossing and reverse routes agreeing within 20
degrees): image-only 0.84 (engine.synth) and 0.43 (engine.synth2), from the heading 1.00 and
1.00. Tying the image-only shift to the previous frame (each frame's first harmonic plus the
previous ones turned by ``relative_yaw``) steadies consecutive frames but lowers revisit
agreement on both families (0.64 / 0.36 with memory 0.7, 0.26 / 0.17 with full memory): a
place's canonical heading then depends on the way it was reached. So the image-only shift
stays per frame, and a recorded heading replaces it where there is one.

Conventions (all in one place):
- ``apply_shift(rgb, s)`` rolls the image LEFT by ``s`` columns: ``np.roll(rgb, -s, axis=1)``.
- ``relative_yaw(a, b)`` returns ``yaw_deg`` in (-180, 180]: how far (in degrees,
  positive = towards increasing column) the content of ``a`` appears displaced in ``b``.
  Hence ``apply_shift(b, yaw_to_columns(yaw_deg, W))`` aligns ``b`` with ``a``, and for
  ``b = np.roll(a, -k, axis=1)`` (``a`` rolled left by ``k``), ``yaw_deg == -k * 360 / W``.
- With canonical shifts ``s_a``, ``s_b`` of ``a``, ``b`` and the shifted images ``a'``, ``b'``:
  ``relative_yaw(a, b) == relative_yaw(a', b') + shift_to_yaw_deg(s_b - s_a, W)`` (mod 360).
- ``shift_from_heading(W, h)`` puts heading 0 at column 0 for a frame whose centre column
  looks towards compass heading ``h`` (columns grow clockwise); ``shift_from_yaw(W, a)`` is
  the same for a counter-clockwise yaw ``a`` in radians (``h = -a``).
"""

from __future__ import annotations

import cv2
import numpy as np

from .errors import InputError

# Width at which the heading signals are computed (the returned shift is full resolution).
PROFILE_WIDTH = 256
# Width at which column signatures are correlated for relative yaw (~0.7 deg per column).
YAW_WIDTH = 512
# Rows used for scoring: a band around the horizon. The poles are stretched by the
# projection and the bottom holds the robot's own body, which turns with the camera
# and would pin the canonical column to the robot.
BAND = (0.15, 0.75)
# Horizontal bands of the yaw signature.
YAW_BANDS = 8


def check_rgb(rgb: np.ndarray) -> None:
    """Raise InputError unless ``rgb`` is an H x W x 3 image."""
    if not isinstance(rgb, np.ndarray) or rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[1] < 2:
        shape = getattr(rgb, "shape", None)
        raise InputError(f"panorama shift needs an H x W x 3 image, got shape {shape}")


def downscale(rgb: np.ndarray, width: int) -> np.ndarray:
    """Float32 RGB at ``min(width, W)`` columns, keeping the 2:1-or-whatever aspect."""
    h, w = rgb.shape[:2]
    if w <= width:
        return rgb.astype(np.float32)
    new_h = max(2, int(round(h * width / w)))
    # INTER_AREA averages whole pixel blocks: no aliasing and no border effects that
    # would make the result depend on where the seam is.
    return cv2.resize(rgb, (width, new_h), interpolation=cv2.INTER_AREA).astype(np.float32)


def _band(img: np.ndarray) -> np.ndarray:
    h = img.shape[0]
    top, bottom = int(round(BAND[0] * h)), max(int(round(BAND[1] * h)), int(round(BAND[0] * h)) + 1)
    return img[top:bottom]


def _gradient_magnitude(grey: np.ndarray) -> np.ndarray:
    """Central differences, circular in x (the panorama wraps), clamped in y."""
    gx = 0.5 * (np.roll(grey, -1, axis=1) - np.roll(grey, 1, axis=1))
    gy = np.gradient(grey, axis=0)
    return np.sqrt(gx * gx + gy * gy)


def _peak_subsample(values: np.ndarray, i: int) -> float:
    """Sub-sample position of the peak at ``i`` by a parabola through its neighbours (circular)."""
    n = values.size
    left, mid, right = values[(i - 1) % n], values[i], values[(i + 1) % n]
    denom = left - 2.0 * mid + right
    if denom >= 0:  # flat or not a maximum
        return float(i)
    return float(i) + float(np.clip(0.5 * (left - right) / denom, -0.5, 0.5))


def heading_signals(rgb: np.ndarray, width: int = PROFILE_WIDTH) -> np.ndarray:
    """Per-column mean colour (float64, (3, ``min(width, W)``)) in the horizon band.

    Each channel is normalised to zero mean and unit norm over the columns, so a
    brightness gain or offset per channel leaves it unchanged; a flat channel is zero.
    """
    check_rgb(rgb)
    sig = _band(downscale(rgb, width)).mean(axis=0).T.astype(np.float64)
    sig -= sig.mean(axis=1, keepdims=True)
    norm = np.linalg.norm(sig, axis=1, keepdims=True)
    return np.where(norm > 1e-6, sig / np.maximum(norm, 1e-12), 0.0)


def heading_harmonic(rgb: np.ndarray) -> complex:
    """Sum over the heading signals of their first Fourier coefficient.

    A roll of the panorama by ``k`` of ``n`` columns multiplies it by ``exp(-2j*pi*k/n)``:
    its phase turns with the camera and its magnitude does not, so the phase is a
    heading that belongs to the place. Unlike the argmax of a profile it is continuous:
    it does not jump between two similar peaks, and a person or a moved object only
    nudges it. (Measured on the synthetic routes, benchmarks/bench_shift.py: it agrees
    within 20 degrees for more same-place pairs than the argmax of a smoothed
    gradient-energy profile, whatever the smoothing.)
    """
    return complex(np.fft.rfft(heading_signals(rgb), axis=1)[:, 1].sum())


def canonical_shift(rgb: np.ndarray) -> int:
    """Columns ``s`` in [0, W) to roll LEFT so the canonical heading becomes column 0.

    The canonical heading is the phase of ``heading_harmonic``: where the colour of the
    horizon band is, to first order, "most like itself" (for ``x = cos(2*pi*(c - c0)/n)``
    it is ``c0``). A panorama without colour structure has no canonical column (0).
    """
    c1 = heading_harmonic(rgb)
    w = rgb.shape[1]
    n = min(PROFILE_WIDTH, w)
    if abs(c1) < 1e-6:
        return 0
    centre = (-np.angle(c1) * n / (2.0 * np.pi)) % n        # in reduced columns
    # Reduced column i spans full columns [i*r, (i+1)*r): its centre is i*r + (r-1)/2.
    r = w / n
    return int(round(centre * r + (r - 1.0) / 2.0)) % w


def shift_from_heading(width: int, heading_deg: float) -> int:
    """Columns in [0, ``width``) to roll LEFT so that heading 0 comes to column 0.

    ``heading_deg``: the compass heading of the image centre (column ``width / 2``) in
    degrees clockwise from north, as EXIF GPSImgDirection and XMP GPano PoseHeadingDegrees
    give it; columns grow clockwise (towards the right of the viewer), as in every
    equirectangular panorama. Any fixed reference instead of north works the same: the
    shift only needs the same direction of the world at column 0 in every frame.
    """
    w = int(width)
    if w < 1:
        raise InputError(f"shift needs a positive width, got {width}")
    h = float(heading_deg)
    if not np.isfinite(h):
        raise InputError(f"heading must be a finite number of degrees, got {heading_deg}")
    return int(round(w / 2.0 - h * w / 360.0)) % w


def shift_from_yaw(width: int, yaw_rad: float) -> int:
    """``shift_from_heading`` for a yaw in radians counter-clockwise (ROS REP 103: odometry,
    IMU, ``engine.poses``), the camera mounted facing the robot's yaw 0 at the image centre.

    A yaw turns the other way than a compass heading (``heading = -yaw``), and where the
    camera is mounted with another column forward the shift is off by that constant only,
    which the shift does not mind (the same for every frame).
    """
    return shift_from_heading(width, -np.degrees(float(yaw_rad)))


def apply_shift(rgb: np.ndarray, s: int) -> np.ndarray:
    """``rgb`` rolled left by ``s`` columns."""
    return np.roll(rgb, -int(s), axis=1)


def shift_to_yaw_deg(columns: float, width: int) -> float:
    """Columns of displacement to degrees, wrapped into (-180, 180]."""
    deg = float(columns) * 360.0 / float(width)
    deg = (deg + 180.0) % 360.0 - 180.0
    return 180.0 if deg == -180.0 else deg


def wrap_degrees(deg):
    """Angles in degrees wrapped to [-180, 180) (arrays too)."""
    return (np.asarray(deg, np.float64) + 180.0) % 360.0 - 180.0


def original_yaw(yaw_shifted, shift_a, shift_b, frame_width: int) -> np.ndarray:
    """The convention above for arrays: the relative heading of the original frames from that
    of the panorama-shifted ones (``frame_width`` 0: not shifted)."""
    if frame_width <= 0:
        return np.asarray(yaw_shifted, np.float64)
    return wrap_degrees(np.asarray(yaw_shifted, np.float64)
                        + (np.asarray(shift_b) - np.asarray(shift_a)) * 360.0 / frame_width)


def yaw_to_columns(yaw_deg: float, width: int) -> int:
    """Degrees to the nearest whole column shift in [0, width)."""
    return int(round(float(yaw_deg) * width / 360.0)) % int(width)


def column_signature(rgb: np.ndarray, width: int = YAW_WIDTH) -> np.ndarray:
    """Per-column signals (float64, (S, width')) for circular alignment.

    For each of ``YAW_BANDS`` horizontal bands in the horizon band: the mean of each
    colour channel and the mean gradient magnitude per column. Every signal is
    normalised to zero mean and unit norm over the columns (flat signals become zero),
    so brightness gain/offset does not matter and correlations are Pearson-like.
    """
    check_rgb(rgb)
    small = _band(downscale(rgb, width))
    grey = small.mean(axis=2)
    grad = _gradient_magnitude(grey)
    h, n = grey.shape
    bands = min(YAW_BANDS, h)
    edges = np.linspace(0, h, bands + 1).round().astype(int)
    rows = []
    for top, bottom in zip(edges[:-1], edges[1:]):  # a handful of bands, not pixels
        rows.append(small[top:bottom].mean(axis=0).T)          # 3 x n colour
        rows.append(grad[top:bottom].mean(axis=0)[None, :])    # 1 x n structure
    sig = np.concatenate(rows, axis=0).astype(np.float64)
    sig -= sig.mean(axis=1, keepdims=True)
    norm = np.linalg.norm(sig, axis=1, keepdims=True)
    return np.where(norm > 1e-9 * n, sig / np.maximum(norm, 1e-12), 0.0)


def relative_yaw(rgb_a: np.ndarray, rgb_b: np.ndarray) -> tuple[float, float]:
    """Heading of ``b`` relative to ``a``: ``(yaw_deg, score)``.

    ``yaw_deg`` in (-180, 180] follows the module convention (``apply_shift(b,
    yaw_to_columns(yaw_deg, W))`` aligns ``b`` with ``a``). ``score`` in [-1, 1] is the
    mean Pearson correlation of the column signals at the best circular shift
    (1 = identical up to a roll, ~0 = unrelated).
    """
    sa = column_signature(rgb_a)
    sb = column_signature(rgb_b)
    if sa.shape != sb.shape:
        raise InputError(f"relative yaw needs panoramas of the same aspect, got {rgb_a.shape} and {rgb_b.shape}")
    active = np.count_nonzero(np.any(sa != 0, axis=1) & np.any(sb != 0, axis=1))
    if active == 0:
        return 0.0, 0.0
    n = sa.shape[1]
    # corr[d] = sum_j a[j] * b[j + d]: content of a at j appears at j + d in b.
    corr = np.fft.irfft(np.conj(np.fft.rfft(sa, axis=1)) * np.fft.rfft(sb, axis=1), n=n, axis=1).sum(axis=0)
    corr /= active
    best = int(np.argmax(corr))
    d = _peak_subsample(corr, best)
    return shift_to_yaw_deg(d, n), float(np.clip(corr[best], -1.0, 1.0))
