"""Read ahead: a recording's frames are decoded in a thread while the last ones are described.

Decoding (FFmpeg, OpenCV, bag decompression) runs in C and lets go of the GIL, and so does
the descriptor's network (torch); on two cores the two overlap instead of taking turns.
Measured on the 2-minute 4K clip of benchmarks/bench_video_sampling.py, see
benchmarks/results/video_sampling.md.

``prefetched(items)`` yields what ``items`` yields, in order, with at most ``depth`` items
read ahead. An exception raised by ``items`` reaches the consumer at the point where the
item would have come, so readers' one-line errors stay what they were. When the consumer
stops early (cancel, an error of its own, ``close()``), the thread stops reading at its
next item and closes ``items`` itself, so the reader's files are released in the thread
that used them.
"""

from __future__ import annotations

import os
import queue
import threading
from typing import Iterator, TypeVar

T = TypeVar("T")

_DONE = object()


def cores_left(reader_threads: int) -> int:
    """CPU cores left to describing while a reader keeps ``reader_threads`` threads busy (>= 1).

    Why: the descriptor's network (torch) starts a thread per core by default; beside a
    reader that keeps its own threads busy, those extra threads wait for cores the decoder
    holds. Readers whose read-ahead thread mostly waits say 0 and the network keeps every
    core (alone, effnet-vlad describes 120 frames in 2.3 s on two threads, 3.3 s on one).
    Measured on the 2-minute 3840x1920 camera-like clip of benchmarks/bench_video_sampling.py
    (two decoding threads, 2-core machine, quiet): describing every second took 5.8-6.3 s with
    one torch thread against 6.4-6.9 s with two (three runs each).
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:   # not on Linux
        cores = os.cpu_count() or 1
    return max(1, cores - max(0, int(reader_threads)))


class _Failed:
    def __init__(self, error: BaseException) -> None:
        self.error = error


def prefetched(items: Iterator[T], depth: int = 2) -> Iterator[T]:
    """``items`` read up to ``depth`` ahead in a daemon thread (see the module notes)."""
    slots: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
    stop = threading.Event()

    def put(value) -> bool:
        """Hand ``value`` over unless the consumer has gone; False when it has."""
        while not stop.is_set():
            try:
                slots.put(value, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put(item):
                    return
            put(_DONE)
        except BaseException as err:  # handed to the consumer, raised there
            put(_Failed(err))
        finally:
            close = getattr(items, "close", None)
            if close is not None:
                close()

    worker = threading.Thread(target=produce, name="panotopo-read-ahead", daemon=True)
    worker.start()
    try:
        while True:
            value = slots.get()
            if value is _DONE:
                return
            if isinstance(value, _Failed):
                raise value.error
            yield value
    finally:
        stop.set()
        worker.join()
