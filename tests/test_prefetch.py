"""Reading ahead in a thread changes nothing a reader's consumer can see: order, errors, closing."""

from __future__ import annotations

import threading
import time

import pytest

from engine.errors import InputError
from engine.prefetch import prefetched


def test_items_come_in_order_and_all_of_them():
    assert list(prefetched(iter(range(100)), depth=3)) == list(range(100))


def test_a_readers_error_reaches_the_consumer_where_the_item_would_have_come():
    def reader():
        yield 1
        yield 2
        raise InputError("clip.mp4: frame 3 cannot be decoded")

    got = []
    with pytest.raises(InputError, match="frame 3 cannot be decoded"):
        for item in prefetched(reader()):
            got.append(item)
    assert got == [1, 2]


def test_a_consumer_that_stops_early_stops_the_thread_and_closes_the_reader():
    closed = threading.Event()
    read = []

    def reader():
        try:
            for i in range(10_000):
                read.append(i)
                yield i
        finally:
            closed.set()

    stream = prefetched(reader(), depth=2)
    assert next(stream) == 0
    stream.close()
    assert closed.wait(2.0)
    time.sleep(0.2)
    assert len(read) <= 5                                        # read ahead by at most a few
    assert not any(t.name == "panotopo-read-ahead" for t in threading.enumerate())


def test_cancelling_a_video_describe_stops_reading_before_the_call_returns(tmp_path):
    import numpy as np

    from engine.errors import Cancelled
    from engine.pipeline import DescribeSettings, describe
    from engine.synth.writers import write_video

    rng = np.random.default_rng(0)
    frames = [np.ascontiguousarray(np.roll(rng.integers(0, 255, (64, 128, 3), np.uint8), 4 * i, axis=1))
              for i in range(60)]
    clip = write_video(tmp_path / "walk.mp4", frames, fps=10)
    stop = threading.Event()

    def progress(done, total, stage):
        if done >= 2:
            stop.set()

    with pytest.raises(Cancelled) as caught:
        describe(clip, DescribeSettings(interval=0.1, options={"input_height": 32}), progress=progress, cancel=stop)
    # The error is still held (its traceback keeps describe's frames alive, as a log would):
    # the threads must have stopped anyway, before describe returned.
    alive = [t.name for t in threading.enumerate() if t.name.startswith(("panotopo-read-ahead", "panotopo-decode"))]
    assert not alive and caught.value.__traceback__ is not None


def test_the_network_gets_the_cores_a_busy_reader_leaves_and_never_none():
    from engine.prefetch import cores_left

    assert cores_left(0) >= 1
    assert cores_left(1) == max(1, cores_left(0) - 1)
    assert cores_left(10_000) == 1


def test_torchs_thread_count_is_limited_inside_the_block_and_restored_after_an_error():
    import torch

    from engine.descriptors.accel import cpu_threads

    before = torch.get_num_threads()
    with pytest.raises(RuntimeError):
        with cpu_threads(1):
            assert torch.get_num_threads() == 1
            raise RuntimeError("describing failed")
    assert torch.get_num_threads() == before
    with cpu_threads(before + 8):          # never more than torch had
        assert torch.get_num_threads() == before
