"""The PyAV video sampler: which frames it delivers, with which stamps, and what it decodes.

Real H.264 clips are written with PyAV + libx264 (B-frames on: the veryfast preset).
Every frame shows its own number as 12 black/white bars, so a test can read WHICH
frame it got, independently of the index and stamp the reader reports.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

av = pytest.importorskip("av")

from engine.errors import InputError  # noqa: E402
from engine.frames import sample_indices  # noqa: E402
from engine.sources import VideoSource, open_recording  # noqa: E402
from engine.sources import video_av  # noqa: E402

FPS = 25
SECONDS = 12
N = FPS * SECONDS
BITS = 12
W, H = 256, 128


def numbered_frame(n: int) -> np.ndarray:
    """Frame ``n``: bar b is white when bit b of n is set."""
    img = np.zeros((H, W, 3), np.uint8)
    bar = W // BITS
    for b in range(BITS):
        if (n >> b) & 1:
            img[:, b * bar:(b + 1) * bar] = 255
    return img


def frame_number(rgb: np.ndarray) -> int:
    """The number a decoded ``numbered_frame`` shows (bar edges left out: chroma bleeds)."""
    bar = rgb.shape[1] // BITS
    return sum(1 << b for b in range(BITS) if rgb[:, b * bar + 3:(b + 1) * bar - 3].mean() > 128)


def write_clip(path: Path, gop: int, n: int = N, faststart: bool = False) -> Path:
    options = {"movflags": "faststart"} if faststart else {}
    with av.open(str(path), "w", options=options) as out:
        stream = out.add_stream("libx264", rate=FPS)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        stream.options = {"preset": "veryfast",
                          "x264-params": f"keyint={gop}:min-keyint={gop}:scenecut=0"}
        for i in range(n):
            for packet in stream.encode(av.VideoFrame.from_ndarray(numbered_frame(i), format="rgb24")):
                out.mux(packet)
        for packet in stream.encode(None):
            out.mux(packet)
    return path


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("clips")
    return {"gop1s": write_clip(d / "gop1s.mp4", gop=FPS),
            "gop10s": write_clip(d / "gop10s.mp4", gop=10 * FPS)}


def delivered(src: VideoSource, interval: float):
    return list(src.frames(interval))


@pytest.mark.parametrize("clip", ["gop1s", "gop10s"])
@pytest.mark.parametrize("interval", [1.0, 0.6, 0.7, 2.5])
def test_delivered_stamp_and_index_are_those_of_the_delivered_picture(clips, clip, interval):
    with VideoSource(clips[clip]) as src:
        got = delivered(src, interval)
        assert got, "no frames"
        for f in got:
            assert frame_number(f.rgb) == f.index          # the index names the picture
            assert f.stamp == pytest.approx(f.index / FPS, abs=1e-6)  # the stamp is its pts
        assert [f.index for f in got] == list(src.sample_indices(interval))
        assert src.expected_samples(interval) == len(got)


@pytest.mark.parametrize("clip", ["gop1s", "gop10s"])
def test_frames_asked_for_narrower_come_shrunk_with_their_full_width_kept(clips, clip):
    import cv2

    with VideoSource(clips[clip]) as src:
        full = delivered(src, 1.0)
        small = list(src.frames(1.0, max_width=W // 2))
    assert [f.index for f in small] == [f.index for f in full]
    assert [f.stamp for f in small] == [f.stamp for f in full]
    for s, f in zip(small, full):
        assert s.rgb.shape == (H // 2, W // 2, 3) and s.source_width == W and s.width == W
        assert frame_number(s.rgb) == s.index                      # the same picture, smaller
        shrunk = cv2.resize(f.rgb, (W // 2, H // 2), interpolation=cv2.INTER_AREA)
        assert np.abs(s.rgb.astype(int) - shrunk).mean() < 8     # area averaging, as OpenCV does
    with VideoSource(clips[clip]) as src:                       # wider than the frame: full size
        assert all(f.source_width == 0 and f.rgb.shape[1] == W for f in src.frames(1.0, max_width=4 * W))


def test_a_consumer_that_stops_early_leaves_no_decoding_thread_or_open_file(clips):
    import threading

    with VideoSource(clips["gop1s"]) as src:
        stream = src.frames(0.5)                   # many decode runs, decoded ahead in threads
        first = [next(stream) for _ in range(3)]
        stream.close()
    assert [frame_number(f.rgb) for f in first] == [f.index for f in first]
    assert not [t for t in threading.enumerate() if t.name.startswith("panotopo-decode")]
    fds = Path("/proc/self/fd")
    if fds.is_dir():                                # Linux: no descriptor left on the clip
        targets = []
        for fd in fds.iterdir():
            try:
                targets.append(str(fd.resolve()))
            except OSError:
                continue
        assert str(clips["gop1s"].resolve()) not in targets


@pytest.mark.parametrize("interval", [1.0, 0.6, 0.7])
def test_long_gop_still_delivers_the_frame_at_each_sample_time(clips, interval):
    with VideoSource(clips["gop10s"]) as src:
        got = delivered(src, interval)
        assert src.sampler.last_stats.mode == "exact"
        targets = np.arange(len(got)) * interval
        late = np.array([f.stamp for f in got]) - targets
        # the first frame at or after each sample time: never early, less than a frame late
        assert np.all(late > -1e-6) and np.all(late < 1.0 / FPS)
        assert len(got) == int((N - 1) / FPS // interval) + 1


def test_key_frames_are_used_when_every_sample_time_has_one_nearby(clips):
    with VideoSource(clips["gop1s"]) as src:
        for interval in (1.0, 3.0):  # key frames every 1 s lie on every sample time
            got = delivered(src, interval)
            stats = src.sampler.last_stats
            assert stats.mode == "keyframes"
            assert stats.decoded == len(got)  # one decoded frame per sample, nothing else
        # at 0.5 s half the sample times are 0.5 s from a key frame (> 0.25 s): exact frames,
        # each decoded from its GOP's key frame; GOPs are decoded only up to their last sample
        got = delivered(src, 0.5)
        stats = src.sampler.last_stats
        assert stats.mode == "exact"
        assert [f.index for f in got] == list(sample_indices(np.arange(N) / FPS, 0.5))
        assert len(got) < stats.decoded < 0.75 * N


def test_long_gop_decodes_only_up_to_the_last_sample_of_each_gop(clips):
    with VideoSource(clips["gop10s"]) as src:
        got = delivered(src, 5.0)  # samples at 0, 5, 10 s; key frames at 0 and 10 s
        stats = src.sampler.last_stats
        assert [f.index for f in got] == [0, 5 * FPS, 10 * FPS]
        # GOP 0..10 s decoded up to 5 s, GOP 10..12 s only its key frame (+ B-frame reordering)
        assert stats.decoded <= 5 * FPS + 1 + 4
        assert stats.decoded < N // 2


def test_keyframe_tolerance_rule():
    assert video_av.keyframe_tolerance(1.0) == 0.25
    assert video_av.keyframe_tolerance(0.2) == 0.25
    assert video_av.keyframe_tolerance(4.0) == 1.0


@pytest.mark.parametrize("clip,interval", [("gop10s", 1.0), ("gop10s", 0.7), ("gop1s", 1.0)])
def test_opencv_fallback_delivers_the_same_frames(clips, clip, interval):
    with VideoSource(clips[clip], use_pyav=False) as cv_src, VideoSource(clips[clip]) as av_src:
        assert cv_src.sampler is None and av_src.sampler is not None
        a, b = delivered(cv_src, interval), delivered(av_src, interval)
        assert [f.index for f in a] == [f.index for f in b]
        assert np.allclose([f.stamp for f in a], [f.stamp for f in b], atol=0.5 / FPS)
        assert [frame_number(f.rgb) for f in a] == [f.index for f in b]
        assert np.allclose(cv_src.stamps(), av_src.stamps(), atol=0.5 / FPS)
        # random access (OpenCV) shows the picture the sampler delivered under that index
        for f in b[::3]:
            assert frame_number(av_src.frame_at(f.index).rgb) == f.index


def test_without_pyav_the_opencv_reader_is_used(clips, monkeypatch):
    monkeypatch.setattr(video_av, "av", None)
    with VideoSource(clips["gop1s"]) as src:
        got = delivered(src, 1.0)
        assert src.sampler is None and src.reader_threads == 0   # decodes in the read-ahead thread
        assert [frame_number(f.rgb) for f in got] == [f.index for f in got] == list(range(0, N, FPS))


def test_the_pyav_sampler_says_how_many_threads_it_keeps_decoding(clips):
    with VideoSource(clips["gop1s"]) as src:
        assert src.sampler is not None and src.reader_threads == video_av.DECODE_THREADS


def test_truncated_or_corrupt_video_is_one_clear_line(clips, tmp_path):
    good = write_clip(tmp_path / "fast.mp4", gop=FPS, n=100, faststart=True).read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(good[: len(good) // 2])  # index at the front, pictures cut off
    noise = bytearray(good)
    mid = len(noise) // 2
    noise[mid:mid + 3000] = np.random.default_rng(0).integers(0, 256, 3000, dtype=np.uint8).tobytes()
    (tmp_path / "noise.mp4").write_bytes(bytes(noise))
    plain = clips["gop1s"].read_bytes()
    (tmp_path / "nomoov.mp4").write_bytes(plain[: len(plain) // 2])  # index at the end, lost
    for name in ("cut.mp4", "noise.mp4", "nomoov.mp4"):
        with pytest.raises(InputError) as err:
            with open_recording(tmp_path / name) as src:
                list(src.frames(1.0))
        message = str(err.value)
        assert name in message and "\n" not in message


def test_keyframes_only_delivers_every_key_frame_decoding_nothing_else(clips):
    with VideoSource(clips["gop1s"], keyframes_only=True) as src:
        for interval in (1.0, 0.3):                       # the interval plays no part
            got = delivered(src, interval)
            stats = src.sampler.last_stats
            assert stats.mode == "all-keyframes"
            assert [f.index for f in got] == list(range(0, N, FPS))   # the clip's key frames
            assert [frame_number(f.rgb) for f in got] == [f.index for f in got]
            assert stats.decoded == len(got)
        assert src.expected_samples(1.0) == len(got) == len(src.sample_indices(1.0))
    with VideoSource(clips["gop10s"], keyframes_only=True) as src:   # sparse key frames: few samples
        got = delivered(src, 1.0)
        assert [f.index for f in got] == [0, 10 * FPS]
        assert src.sampler.last_stats.decoded == 2


def test_keyframes_sampling_through_describe_and_the_command_line(clips, tmp_path, capsys):
    import json

    from engine.cli import main

    out = tmp_path / "k.npz"
    code = main(["describe", str(clips["gop1s"]), "-o", str(out), "--no-cache", "--input-height", "32", "-q",
                 "--interval", "keyframes"])
    assert code == 0, capsys.readouterr().err
    with np.load(out) as z:
        assert z["frames"].tolist() == list(range(0, N, FPS))
        assert json.loads(str(z["meta"]))["sampling"] == "keyframes"
    with pytest.raises(SystemExit) as exit_:                 # argparse: one line, status 2
        main(["describe", str(clips["gop1s"]), "-o", str(tmp_path / "x.npz"), "--interval", "often"])
    lines = capsys.readouterr().err.strip().splitlines()
    assert exit_.value.code == 2 and len(lines) == 1 and "keyframes" in lines[0]
    folder = tmp_path / "photos"                            # only videos have key frames
    folder.mkdir()
    code = main(["describe", str(folder), "-o", str(tmp_path / "x.npz"), "--no-cache", "-q", "--interval", "keyframes"])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "key frames" in lines[0]
