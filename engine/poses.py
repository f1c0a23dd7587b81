"""Ground-truth poses: plain data for evaluation. Never used for mapping."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass
class Poses:
    t: np.ndarray                    # float64 (m,) seconds, increasing, on the map's clock
    x: np.ndarray                    # float64 (m,) metres
    y: np.ndarray                    # float64 (m,) metres
    yaw: Optional[np.ndarray] = None  # float64 (m,) radians, when known

    def __len__(self) -> int:
        return int(self.t.size)

    def at(self, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (x, y) at ``stamps`` by linear interpolation (clamped at the ends)."""
        stamps = np.asarray(stamps, dtype=np.float64)
        return np.interp(stamps, self.t, self.x), np.interp(stamps, self.t, self.y)
