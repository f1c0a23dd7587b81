"""Local features (SIFT keypoints + descriptors) of equirectangular panoramas.

Loop closures are verified by two-view geometry between panoramas (``engine.sphere``);
this module gives the features that geometry is fitted to, and a flat table that
keeps the features of a whole recording in three arrays (saved in the descriptors
.npz as ``feat_offsets``, ``feat_uv``, ``feat_desc``).

Choices (all in one place):
- SIFT (OpenCV main module) on the grey frame downscaled to ``WORK_WIDTH`` = 256 columns
  (1.4 degrees per pixel; SIFT doubles the image internally, so the finest keypoints are
  located to a fraction of 0.7 degree). Cost, measured with benchmarks/bench_sphere.py and
  one-off runs on tests/data/examplepano_1024.jpg on the shared 2-core machine under
  a load of ~8: ~40 ms per 1024x512 frame at 256 columns, ~80 ms at 384 columns, while
  the default descriptor (effnet-vlad) took ~43 ms per frame at the same moment. 384 columns
  found more features on the panorama (335 vs 183) and about the same on real GoPro MAX
  frames (~350 vs ~320) and the same inliers on their 1 m and 9 m steps; 256 keeps
  extraction at about the descriptor's cost. ``CONTRAST`` = 0.02 (OpenCV's default is
  0.04) keeps keypoints in low-contrast indoor scenes; the strongest ``FEATURES_MAX``
  are kept anyway.
- The panorama wraps: the frame is padded with ``WRAP_PAD`` columns from the other
  side, so keypoints at the seam keep their full support; keypoints are only taken
  from the original columns (mask), so none is found twice. Rows outside the band (below)
  are cut off before SIFT, but for ``WRAP_PAD`` rows of support.
- Only rows in ``BAND`` (fractions of the height) give keypoints: above 0.08 (within
  ~14 degrees of the zenith) the projection stretches the image more than 3.5 times
  horizontally, so SIFT's scale/orientation invariance does not hold; below 0.80
  (more than ~54 degrees below the horizon) the frame shows the robot, tripod or the
  person carrying the camera, which turn with the camera and would vote for "no rotation".
- Descriptors are RootSIFT (L1-normalised, square root; Arandjelovic & Zisserman 2012:
  Euclidean distance then compares like the Hellinger kernel, which matches better),
  quantised to uint8 by ``ROOT_SCALE`` = 512 (the elements are at most ~0.4 after the
  square root, so 255 is never reached in practice; 1/512 is far below matching noise).
- ``FEATURES_MAX`` = 400 keypoints per frame, the strongest by detector response:
  enough for tens of inliers on a revisit and small enough to store (51 KB per frame)
  and to fit in a few milliseconds per pair.
"""

from __future__ import annotations

import threading

from dataclasses import dataclass
from typing import Mapping, Optional, Sequence

import cv2
import numpy as np

from .errors import InputError

FEATURES_VERSION = 1          # bump when extraction changes (part of the descriptor cache key)
FEATURES_MAX = 400
WORK_WIDTH = 256
CONTRAST = 0.02
WRAP_PAD = 16                 # pixels at WORK_WIDTH of support kept round the band and the seam
BAND = (0.08, 0.80)
ROOT_SCALE = 512.0
DESC_DIM = 128

_local = threading.local()   # one detector per thread: the app extracts in two threads at once


def _detector():
    if getattr(_local, "sift", None) is None:
        _local.sift = cv2.SIFT_create(FEATURES_MAX, 3, CONTRAST)
    return _local.sift


@dataclass
class LocalFeatures:
    uv: np.ndarray     # float32 (k, 2): column, row as fractions of the frame's width, height, in [0, 1)
    desc: np.ndarray   # uint8 (k, 128) RootSIFT, quantised

    def __len__(self) -> int:
        return int(self.uv.shape[0])


def empty() -> LocalFeatures:
    return LocalFeatures(np.zeros((0, 2), np.float32), np.zeros((0, DESC_DIM), np.uint8))


def root_sift(desc: np.ndarray) -> np.ndarray:
    """SIFT descriptors (float, (k, 128)) to quantised RootSIFT (uint8)."""
    d = np.asarray(desc, np.float32)
    d = d / np.maximum(d.sum(axis=1, keepdims=True), 1e-12)
    return np.clip(np.rint(np.sqrt(d) * ROOT_SCALE), 0, 255).astype(np.uint8)


def extract(rgb: np.ndarray, max_features: int = FEATURES_MAX) -> LocalFeatures:
    """SIFT features of an equirectangular RGB frame (H x W x 3 uint8), see the module notes."""
    if not isinstance(rgb, np.ndarray) or rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[1] < 2:
        raise InputError(f"local features need an H x W x 3 image, got shape {getattr(rgb, 'shape', None)}")
    grey = cv2.cvtColor(np.ascontiguousarray(rgb, dtype=np.uint8), cv2.COLOR_RGB2GRAY)
    h, w = grey.shape
    if w > WORK_WIDTH:
        new_h = max(2, int(round(h * WORK_WIDTH / w)))
        grey = cv2.resize(grey, (WORK_WIDTH, new_h), interpolation=cv2.INTER_AREA)
    gh, gw = grey.shape
    top, bottom = int(round(BAND[0] * gh)), int(round(BAND[1] * gh))
    # SIFT only sees the band and a margin of support around it, and the seam wrapped round.
    y0, y1 = max(0, top - WRAP_PAD), min(gh, bottom + WRAP_PAD)
    pad = min(WRAP_PAD, gw // 2)
    rows = grey[y0:y1]
    padded = np.concatenate([rows[:, gw - pad:], rows, rows[:, :pad]], axis=1)
    mask = np.zeros(padded.shape, np.uint8)
    mask[top - y0:bottom - y0, pad:pad + gw] = 255
    sift = _detector()
    sift.setNFeatures(int(max_features))
    keypoints, desc = sift.detectAndCompute(padded, mask)
    if desc is None or not keypoints:
        return empty()
    xy = np.array([kp.pt for kp in keypoints], np.float64)
    # Pixel centres: pixel x covers [x - 0.5, x + 0.5), so column fraction is (x + 0.5) / W.
    u = ((xy[:, 0] - pad + 0.5) / gw) % 1.0
    v = np.clip((xy[:, 1] + y0 + 0.5) / gh, 0.0, np.nextafter(1.0, 0.0))
    keep = slice(0, int(max_features))   # OpenCV may keep ties beyond nfeatures
    return LocalFeatures(np.stack([u, v], axis=1)[keep].astype(np.float32), root_sift(desc)[keep])


@dataclass
class FeatureTable:
    """Features of a whole recording, frame ``i`` in rows ``offsets[i]:offsets[i + 1]``."""

    offsets: np.ndarray   # int64 (n + 1,), offsets[0] == 0, non-decreasing
    uv: np.ndarray        # float16 (N, 2) (enough: 1/2048 of the width is ~0.2 degree)
    desc: np.ndarray      # uint8 (N, 128)

    def __len__(self) -> int:
        return int(self.offsets.shape[0]) - 1

    def of(self, i: int) -> LocalFeatures:
        s, e = int(self.offsets[i]), int(self.offsets[i + 1])
        uv = self.uv[s:e].astype(np.float32)
        uv[:, 0] %= 1.0                  # float16 rounds 0.9999 up to 1.0: wrap it
        uv[:, 1] = np.minimum(uv[:, 1], np.nextafter(np.float32(1.0), np.float32(0.0)))
        return LocalFeatures(uv, self.desc[s:e])

    def subset(self, rows: Sequence[int]) -> "FeatureTable":
        return FeatureTable.from_list([self.of(int(i)) for i in rows])

    @classmethod
    def from_list(cls, feats: Sequence[LocalFeatures]) -> "FeatureTable":
        counts = np.array([len(f) for f in feats], np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        uv = np.concatenate([f.uv for f in feats]).astype(np.float16) if feats else np.zeros((0, 2), np.float16)
        desc = np.concatenate([f.desc for f in feats]).astype(np.uint8) if feats else np.zeros((0, DESC_DIM), np.uint8)
        return cls(offsets, uv.reshape(-1, 2), desc.reshape(-1, DESC_DIM))

    def to_arrays(self) -> dict:
        return {"feat_offsets": np.asarray(self.offsets, np.int64),
                "feat_uv": np.asarray(self.uv, np.float16),
                "feat_desc": np.asarray(self.desc, np.uint8)}

    @classmethod
    def from_arrays(cls, arrays: Mapping, frames: Optional[int] = None) -> Optional["FeatureTable"]:
        """The table saved by ``to_arrays`` (None when its keys are absent).

        Raises InputError (one line) when the arrays do not fit together, or do not
        cover ``frames`` frames when that is given.
        """
        keys = ("feat_offsets", "feat_uv", "feat_desc")
        present = [k in arrays for k in keys]
        if not any(present):
            return None
        if not all(present):
            missing = [k for k, p in zip(keys, present) if not p]
            raise InputError(f"local features are incomplete (missing {', '.join(missing)})")
        offsets = np.asarray(arrays["feat_offsets"])
        uv = np.asarray(arrays["feat_uv"])
        desc = np.asarray(arrays["feat_desc"])
        if offsets.ndim != 1 or offsets.size < 1 or not np.issubdtype(offsets.dtype, np.integer):
            raise InputError(f"local features have bad offsets (shape {offsets.shape}, {offsets.dtype})")
        if uv.ndim != 2 or uv.shape[1] != 2 or desc.ndim != 2 or desc.shape[1] != DESC_DIM \
                or uv.shape[0] != desc.shape[0]:
            raise InputError(f"local features have mismatched shapes (uv {uv.shape}, descriptors {desc.shape})")
        if offsets[0] != 0 or offsets[-1] != uv.shape[0] or np.any(np.diff(offsets) < 0):
            raise InputError(f"local feature offsets do not index {uv.shape[0]} features")
        if frames is not None and offsets.size != frames + 1:
            raise InputError(f"local features cover {offsets.size - 1} frames, expected {frames}")
        return cls(offsets.astype(np.int64), uv.astype(np.float16), desc.astype(np.uint8))
