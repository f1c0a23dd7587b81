"""Robust location and spread (median and MAD) of similarity samples.

Shared by the calibration of the paper's thresholds (``engine.calibrate``) and the per-node
backgrounds of retrieval (``engine.retrieval``); a module of its own so that neither imports
the other for it.
"""

from __future__ import annotations

import numpy as np

# MAD to standard deviation for a normal distribution.
_MAD_TO_SD = 1.4826


def _nanmedian_rows(values: np.ndarray) -> np.ndarray:
    """Median of each row ignoring NaNs (NaN for all-NaN rows), by one sort: NaNs sort last.

    The same numbers as ``np.nanmedian(values, axis=1)``, several times faster for the
    (nodes x sample) background blocks.
    """
    s = np.sort(values, axis=1)
    cnt = np.count_nonzero(~np.isnan(values), axis=1)
    rows = np.arange(s.shape[0])
    lo = s[rows, np.maximum((cnt - 1) // 2, 0)]
    hi = s[rows, np.minimum(cnt // 2, s.shape[1] - 1)]
    med = np.where(cnt % 2 == 1, lo, 0.5 * (lo + hi))
    return np.where(cnt > 0, med, np.nan)


def robust_stats(values: np.ndarray, axis: int = -1) -> tuple[np.ndarray, np.ndarray]:
    """Median and MAD-based spread along ``axis`` (NaNs ignored); spread floored at 1e-3."""
    if values.ndim == 2 and axis in (1, -1):
        med = _nanmedian_rows(values)
        mad = _nanmedian_rows(np.abs(values - med[:, None]))
    else:
        med = np.nanmedian(values, axis=axis)
        mad = np.nanmedian(np.abs(values - np.expand_dims(med, axis)), axis=axis)
    return med, np.maximum(mad * _MAD_TO_SD, 1e-3)


