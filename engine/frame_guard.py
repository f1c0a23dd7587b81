"""Guards around reading a recording's frames: bad frames and memory, before the work.

* ``checked_frames``: one undecodable frame no longer has to end a long run. Without
  ``skip`` the reader's error is raised with a hint to the skip option; with it, the
  frame is skipped, its index recorded, and reading goes on frame by frame (the reader's
  single forward pass ended with the error).
* ``check_describe_memory``: refuses, before decoding anything, a run whose descriptors
  would not fit ``limits.MAX_DESCRIBE_BYTES``.
"""

from __future__ import annotations

from typing import Iterator, Optional

from . import limits
from .errors import InputError
from .frames import Frame, FrameSource

SKIP_HINT = "to skip undecodable frames, use --skip-bad-frames (in the app: Skip bad frames)"


def checked_frames(source: FrameSource, interval: float, skip: bool, skipped: list[int],
                   max_width: Optional[int] = None) -> Iterator[Frame]:
    """``source.frames(interval, max_width)``, skipping frames that cannot be decoded when
    ``skip`` (their indices are appended to ``skipped``)."""
    stream = source.frames(interval, max_width=max_width)
    last = -1
    while True:
        try:
            frame = next(stream)
        except StopIteration:
            return
        except InputError as exc:
            if not skip:
                raise InputError(f"{exc}; {SKIP_HINT}") from None
            break
        last = frame.index
        yield frame
    for index in source.sample_indices(interval):
        if index <= last:
            continue
        try:
            frame = source.frame_at(int(index))
        except InputError:
            skipped.append(int(index))
            continue
        yield frame


def bytes_per_frame(model) -> int:
    """What describing keeps in memory per sampled frame: the vector (float32), the
    column signatures and colour histogram (float16, ~4 KiB together) and, for models
    that pool local features after a first pass (effnet-vlad), those features (float16)."""
    dim = int(getattr(model, "dimension", 0) or getattr(model, "dim", 0) or 4096)
    per = 4 * dim + 4096
    height, channels = getattr(model, "input_height", 0), getattr(model, "channels", 0)
    if height and channels:
        per += 2 * (height // 16) * (2 * height // 16) * int(channels)
    return per


def check_describe_memory(count: int, model, where: str) -> None:
    """InputError when ``count`` sampled frames would not fit the describe memory budget."""
    need = int(count) * bytes_per_frame(model)
    if need > limits.MAX_DESCRIBE_BYTES:
        raise InputError(
            f"{where}: {count:,} sampled frames would need about {need / 2**30:.1f} GiB of descriptors in "
            f"memory (limit {limits.MAX_DESCRIBE_BYTES / 2**30:g} GiB); use a larger --interval, a smaller "
            f"--input-height or a shorter recording")
