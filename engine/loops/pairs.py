"""The plain values that flow between the stages of ``verified`` (``engine.loops.verified``).

``Pairs`` holds node pairs (a < b) with the evidence each stage adds, one array per field;
``Status`` is a pair's tier. Each stage takes a ``Pairs`` and returns a new one (or the
statuses), so a stage can be read, tested and replaced alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from enum import Enum
from typing import Optional

import numpy as np


class Status(str, Enum):
    """A pair's tier: automatic (accepted), candidate (a person decides) or dropped."""

    AUTO = "auto"
    CANDIDATE = "candidate"
    DROPPED = ""


@dataclass
class Pairs:
    """Candidate node pairs (a < b) with their evidence, one entry per pair (None: not measured)."""

    a: np.ndarray                      # int64 node index
    b: np.ndarray                      # int64 node index, b - a > neighbour window
    cosine: np.ndarray                 # float32 descriptor cosine
    score: np.ndarray                  # calibrated score (stage 1)
    support: Optional[np.ndarray] = None        # best mean calibrated score along the stretch (stage 2)
    direction: Optional[np.ndarray] = None      # +1 forward, -1 reverse (stage 2)
    confidence: Optional[np.ndarray] = None     # one ranking number (stages 3 and 4)
    matches: Optional[np.ndarray] = None        # local feature matches (stage 4; -1 unknown)
    inliers: Optional[np.ndarray] = None        # two-view inliers (stage 4; -1 unknown)
    inlier_ratio: Optional[np.ndarray] = None
    yaw: Optional[np.ndarray] = None            # heading of b relative to a, degrees (NaN unknown)
    path_inliers: Optional[np.ndarray] = None   # each end with its path neighbour outside the window
    step_inliers: Optional[np.ndarray] = None   # each end with its next node (the smaller end)
    plane_share: Optional[np.ndarray] = None    # share of inliers on one plane (NaN unknown)
    distance_steps: Optional[np.ndarray] = None  # the two views apart, in node steps (NaN unknown)
    bearing: Optional[np.ndarray] = None        # direction of b seen from a, degrees in a's frame (NaN unknown)

    def __len__(self) -> int:
        return int(self.a.size)

    def take(self, keep: np.ndarray) -> "Pairs":
        """The pairs selected by ``keep`` (a mask or indices), every field alike."""
        return Pairs(**{f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[keep]
                        for f in fields(self)})

    def set_row(self, i: int, other: "Pairs", j: int) -> None:
        """Row ``i`` becomes ``other``'s row ``j`` (a match moved to another pair of its place)."""
        for f in fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if mine is not None and theirs is not None:
                mine[i] = theirs[j]


@dataclass
class Steps:
    """Every consecutive node pair (i, i + 1) read as a relative motion, in node i's original frame."""

    yaw: np.ndarray        # degrees, heading of i + 1 relative to i (NaN: unknown)
    motion: np.ndarray     # degrees, azimuth of i + 1 seen from i (NaN: unknown)
    still: np.ndarray      # bool: no parallax, the camera turned where it stood
    ambiguous: np.ndarray  # bool: turns more than ambiguous_turn_deg (the loops may outvote it)


def recording_of(m: int, chain_starts=(0,)) -> np.ndarray:
    """(m,) int64: which recording (0, 1, ...) each node belongs to, from the first node of each."""
    starts = np.unique(np.asarray(chain_starts, np.int64))
    return (np.searchsorted(starts[starts > 0], np.arange(m), side="right")).astype(np.int64)


@dataclass
class LoopCandidate:
    a: int                        # node index, a < b
    b: int
    similarity: float             # cos(node a, node b)
    window_count: int             # "ours": largest candidate-window count; 0 otherwise
    yaw: Optional[float] = None   # relative heading in degrees, when estimated
    score: Optional[float] = None  # any later verification score
    status: str = "auto"          # tier: "auto" (accepted) or "candidate" (for a person to review)
    evidence: dict = field(default_factory=dict)  # named numbers behind it (graph.EVIDENCE_KEYS)
