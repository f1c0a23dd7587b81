"""Loop keys: the pair of source frames of a loop's two nodes, smaller first.

In a site (several recordings, ``gui.model.site``) the two ends are *site frames*: a
recording's source frame moved along by the recording's offset on the site's one
timeline, so that keys stay plain pairs of integers in the views. What is written to
disk never holds site frames: a journal record or a decision names each end by its
recording and its own source frame (``sessions`` beside ``frames``, as
``TopoMap.decisions()`` does), see ``address_key``.
"""

from __future__ import annotations

from typing import Optional, Sequence

LoopKey = tuple[int, int]


def frames_key(frames: Sequence[int]) -> LoopKey:
    a, b = int(frames[0]), int(frames[1])
    return (a, b) if a <= b else (b, a)


def address_key(frames: Sequence[int], sessions: Optional[Sequence[str]] = None) -> tuple:
    """A loop's address on disk as one hashable value, the same whichever end comes first:
    the frames key of one recording, or ((session, frame), (session, frame)) sorted."""
    if not sessions:
        return frames_key(frames)
    ends = sorted(((str(sessions[0]), int(frames[0])), (str(sessions[1]), int(frames[1]))))
    return tuple(ends)


def address_item(frames: Sequence[int], sessions: Optional[Sequence[str]] = None) -> dict:
    """``{"frames": [a, b]}`` (and ``"sessions": [sa, sb]``), in the order ``address_key`` sorts."""
    if not sessions:
        return {"frames": list(frames_key(frames))}
    (sa, fa), (sb, fb) = address_key(frames, sessions)
    return {"frames": [fa, fb], "sessions": [sa, sb]}
