"""Loop keys: the pair of source frames of a loop's two nodes, smaller first."""

from __future__ import annotations

from typing import Sequence

LoopKey = tuple[int, int]


def frames_key(frames: Sequence[int]) -> LoopKey:
    a, b = int(frames[0]), int(frames[1])
    return (a, b) if a <= b else (b, a)
