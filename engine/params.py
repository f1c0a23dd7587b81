"""Parameters of node creation and loop detection (plain data, shared by CLI, GUI, tests)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Optional

METHODS = ("simple", "shift-simple", "ours", "verified")
# Methods whose descriptors are computed on panorama-shifted frames.
SHIFTED_METHODS = ("shift-simple", "ours", "verified")
# "verified" (beyond the paper, engine.loops_verified): thresholds calibrated from the
# recording itself, sequence support, yaw-aligned verification; loop_sim_th, window_size
# and count_th are not used by it, and node_sim_th None means "calibrate from the recording".
# long_runs is read by "verified" only: off trades the returns with a lateral offset it finds
# for the rare false loop it adds (README results).
METHOD_DESCRIPTIONS = {
    "simple": "Simple threshold: any pair with similarity >= loop_sim_th (no panorama shift)",
    "shift-simple": "Panorama shift + simple threshold",
    "ours": "Panorama shift + spatial consistency check (the paper's method)",
    "verified": "Calibrated scores + sequence support + yaw-aligned verification (beyond the paper)",
}


@dataclass(frozen=True)
class MapParams:
    method: str = "verified"
    node_sim_th: Optional[float] = None   # None: the descriptor's calibrated default
    loop_sim_th: Optional[float] = None   # None: the descriptor's calibrated default
    window_size: int = 5
    count_th: int = 2
    neighbor_node_num: int = 5
    long_runs: bool = True                # verified: step 5, long runs (returns with a lateral offset)

    def resolved(self, defaults: dict) -> "MapParams":
        """Fill every None from a descriptor's ``defaults``."""
        filled = {k: defaults[k] for k, v in asdict(self).items() if v is None and k in defaults}
        return replace(self, **filled)

    def as_dict(self) -> dict:
        return asdict(self)

    @property
    def uses_shift(self) -> bool:
        return self.method != "simple"
