"""Sample a video by decoding only the frames the samples need (PyAV, FFmpeg).

Decoding is what a long 4K recording costs (a 2-minute 3840x1920 H.264 clip takes
about a minute to decode fully on 2 cores); sampling at 1 Hz keeps 1 frame in 30.
A compressed video can only be decoded from a key frame onwards, so:

1. **Index** (``read_index``): one demux pass reads every packet's presentation time
   and key flag, without decoding (I/O only). Stamps are presentation times in
   seconds from the first frame; a frame's index is its position in presentation
   order, which equals ``round(stamp * fps)`` for constant-frame-rate video.
2. **Plan** (``plan_samples``): for t_k = k * interval, either
   - *key frames*: the key frame nearest to each t_k, when EVERY t_k has a key frame
     of its own within ``keyframe_tolerance(interval)`` = max(0.25 s, interval / 4),
     plus half a frame (one decode per sample); or
   - *exact*: the first frame with stamp >= t_k (``engine.frames.sample_indices``,
     the same frames as the OpenCV reader).
3. **Decode** (``AvSampler.frames``): picks are grouped by the key frame their
   decoding starts from; for each group the reader seeks to that key frame and
   decodes forward to the group's last pick, then drains the decoder. GOPs without
   a pick are never decoded. This decodes the fewest frames either way: seeking per
   sample when the GOP is short, one forward run when several samples share a GOP.
   Runs are independent, so two threads decode them at once, each on its own
   container, and the frames are delivered in order.

Delivered frames carry the exact stamp of the decoded frame (its pts), never the
requested time. ``SampleStats`` tells how many packets went to the decoder.
"""

from __future__ import annotations

import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Iterator, Optional

import numpy as np

from ..errors import InputError
from ..frames import Frame, check_equirectangular_size, sample_indices

try:  # PyAV is optional at run time: VideoSource falls back to OpenCV without it
    import av
    import av.error
except ImportError:  # pragma: no cover - exercised only where PyAV is not installed
    av = None

# A key frame may stand in for the sample time t_k when it is this close to it.
KEYFRAME_MIN_TOLERANCE_S = 0.25
KEYFRAME_INTERVAL_FRACTION = 0.25


def keyframe_tolerance(interval: float) -> float:
    """How far (seconds) a key frame may lie from its sample time: max(0.25 s, interval / 4).

    interval / 4 keeps consecutive samples between 0.5 and 1.5 intervals apart, so the
    sampling stays regular; the 0.25 s floor is a quarter metre of travel at 1 m/s
    (a walking robot or person), far below the place scale of a topological map (nodes
    are metres apart), so a map built from key frames sees the same places. With a
    camera's usual 0.5-1 s GOP every sample at 1 Hz then finds its key frame.
    """
    return max(KEYFRAME_MIN_TOLERANCE_S, KEYFRAME_INTERVAL_FRACTION * interval)


class AvUnavailable(Exception):
    """PyAV is missing or cannot read this file the way the sampler needs (caller falls back)."""


@dataclass(frozen=True)
class StreamIndex:
    """What one demux pass learns about the video stream (no decoding)."""

    stamps: np.ndarray      # float64 seconds from the first frame, presentation order
    pts: np.ndarray         # int64 pts (stream time base), presentation order
    key: np.ndarray         # bool, presentation order: the frame is a key frame
    decode_pos: np.ndarray  # int64, presentation order: the packet's position in decode order
    fps: float
    declared: int = 0       # frames the container declares (0: it does not say)

    @property
    def missing(self) -> int:
        """Declared frames the demuxer could not read (a cut-off or damaged file)."""
        return max(0, self.declared - len(self))

    def __len__(self) -> int:
        return int(self.stamps.size)


@dataclass(frozen=True)
class SamplePlan:
    indices: np.ndarray  # int64 frames to deliver, increasing
    mode: str            # "keyframes" or "exact"


@dataclass
class SampleStats:
    """What the last ``frames()`` call did: for tests and benchmarks."""

    mode: str = ""
    decoded: int = 0       # packets sent to the decoder (decoded frames)
    delivered: int = 0
    seeks: int = 0
    runs: list = field(default_factory=list)  # (first, last) decode positions per run


def plan_samples(index: StreamIndex, interval: float, use_keyframes: bool = True) -> SamplePlan:
    """Which frames sampling every ``interval`` seconds delivers (see module doc).

    Key frames are used only when every sample time t_k has its own key frame within
    ``keyframe_tolerance(interval)`` plus half a frame; otherwise every sample is the exact
    frame, so a recording is sampled one way throughout (no mixture of early and late
    samples). Known limit: a GOP slightly longer than the interval (30 frames at 29.97 fps
    sampled at 1 Hz) drifts 1 ms per sample off the sample times, so on recordings longer
    than about 4 minutes it fails the rule and is sampled exactly (correct, but slower).
    """
    exact = sample_indices(index.stamps, interval)
    if not use_keyframes or interval <= 0 or exact.size == 0:
        return SamplePlan(exact, "exact")
    key_idx = np.flatnonzero(index.key)
    if key_idx.size == 0:
        return SamplePlan(exact, "exact")
    key_t = index.stamps[key_idx]
    targets = index.stamps[0] + np.arange(exact.size) * interval
    right = np.clip(np.searchsorted(key_t, targets), 0, key_t.size - 1)
    left = np.clip(right - 1, 0, key_t.size - 1)
    nearest = np.where(np.abs(key_t[left] - targets) <= np.abs(key_t[right] - targets), left, right)
    # + half a frame: frames are discrete, so a key frame can only be "on" a sample time to
    # within half a frame (a 0.5005 s GOP at 29.97 fps is at most 0.25025 s from 1 Hz times)
    half_frame = 0.5 / index.fps if index.fps > 0 else 0.0
    ok = np.abs(key_t[nearest] - targets) <= keyframe_tolerance(interval) + half_frame + 1e-9
    if not np.all(ok) or np.unique(nearest).size != nearest.size:
        return SamplePlan(exact, "exact")
    return SamplePlan(key_idx[nearest].astype(np.int64), "keyframes")


def _one_line(err: BaseException) -> str:
    """FFmpeg's reason without the errno and the C function name."""
    text = getattr(err, "strerror", None) or str(err)
    return " ".join(str(text).split()) or type(err).__name__


def read_index(path: Path, stream: int = 0) -> StreamIndex:
    """Demux ``path`` once (no decoding): pts, key flags and decode order of every frame of
    its video stream number ``stream`` (0: the first).

    Raises AvUnavailable when PyAV is missing, cannot open the container, or the
    stream has no usable presentation times (the OpenCV reader handles those), and
    InputError when the file is broken part way. A file that ends before the frames it
    declares is indexed as far as it goes (``StreamIndex.missing``; the sampler decides).
    """
    if av is None:
        raise AvUnavailable("PyAV is not installed")
    try:
        container = av.open(str(path))
    except (av.error.FFmpegError, OSError) as err:
        raise AvUnavailable(_one_line(err)) from None
    try:
        if len(container.streams.video) <= stream:
            raise AvUnavailable("no video stream" if stream == 0 else f"no video stream {stream}")
        stream = container.streams.video[stream]
        pts: list[int] = []
        key: list[bool] = []
        try:
            for packet in container.demux(stream):
                if packet.size == 0:  # the demuxer's end-of-stream marker
                    continue
                if packet.is_corrupt:  # cut short by the end of a damaged file: not a frame
                    break
                if packet.pts is None:
                    raise AvUnavailable("packets without presentation times")
                pts.append(int(packet.pts))
                key.append(bool(packet.is_keyframe))
        except av.error.FFmpegError as err:
            raise InputError(f"{path}: video is damaged ({_one_line(err)})") from None
        declared = int(stream.frames or 0)  # the container's own count (mp4: its index); 0 unknown
        fps = float(stream.average_rate or stream.guessed_rate or 0.0)
        time_base = Fraction(stream.time_base) if stream.time_base else None
    finally:
        container.close()
    if not pts:
        raise InputError(f"{path}: video has no frames")
    if time_base is None:
        raise AvUnavailable("no time base")
    dec_pts = np.asarray(pts, dtype=np.int64)
    order = np.argsort(dec_pts, kind="stable")  # decode order -> presentation order
    pres_pts = dec_pts[order]
    if np.any(np.diff(pres_pts) <= 0):
        raise AvUnavailable("repeated presentation times")
    stamps = (pres_pts - pres_pts[0]).astype(np.float64) * float(time_base)
    return StreamIndex(stamps=stamps, pts=pres_pts, key=np.asarray(key, bool)[order],
                       decode_pos=order.astype(np.int64), fps=fps, declared=declared)


def truncation_message(path: Path, index: StreamIndex) -> str:
    return (f"{path}: video is truncated or damaged: {len(index)} of the {index.declared} frames "
            f"it declares can be read")


class AvSampler:
    """Sampled frames of one video, decoding only what the samples need.

    ``projection`` (``engine.sources.projection.Projection``, None = equirectangular): frames
    of another projection are converted to equirectangular as they are decoded, from one
    video stream or two (``inputs``: (file, video stream number) pairs, e.g. the two streams
    of a GoPro .360 or the two files of an Insta360 5.7K recording; each input has its own
    demuxer and decoder, their frames are paired by position in presentation order, and a
    frame counts as a key frame only where every input has one). ``keyframes_only``: ``frames`` delivers every key frame and nothing else
    (``--interval keyframes``). ``allow_truncated``: a file that ends before the frames it
    declares is read as far as it goes (``missing`` tells how many are lost) instead of
    refused (``--skip-bad-frames``).
    """

    def __init__(self, path: str | Path, use_keyframes: bool = True, projection=None,
                 keyframes_only: bool = False, allow_truncated: bool = False, inputs=None) -> None:
        self.path = Path(path)
        self.use_keyframes = use_keyframes
        self.keyframes_only = keyframes_only
        self.projection = projection if projection is not None and projection.converts else None
        if inputs is None:
            streams = self.projection.streams if self.projection is not None else 1
            inputs = [(self.path, k) for k in range(streams)]
        self.inputs = [(Path(f), int(k)) for f, k in inputs]
        indexes = [read_index(f, k) for f, k in self.inputs]
        self.missing = max(ix.missing for ix in indexes)
        if self.missing and not allow_truncated:
            worst = max(range(len(indexes)), key=lambda k: indexes[k].missing)
            raise InputError(truncation_message(self.inputs[worst][0], indexes[worst]) +
                             "; to read the frames before the damage, use --skip-bad-frames "
                             "(in the app: Skip bad frames)")
        self.indexes = _paired(self.path, indexes)
        self.index = self.indexes[0]
        self.shapes = [_stream_shape(f, k) for f, k in self.inputs]
        self.last_stats = SampleStats()

    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) of the delivered panoramas at full size."""
        if self.projection is None:
            return self.shapes[0]
        from .projection import native_size

        return native_size(self.projection, self.shapes)

    def plan(self, interval: float) -> SamplePlan:
        if self.keyframes_only:
            return SamplePlan(np.flatnonzero(self.index.key).astype(np.int64), "all-keyframes")
        return plan_samples(self.index, interval, self.use_keyframes)

    def _runs(self, picks: np.ndarray) -> list[tuple[int, int, list[int]]]:
        """Decode runs (first, last decode position, picks) covering ``picks``.

        A pick is decoded from the last key frame before it in decode order that is
        also presented no later than it (so open-GOP leading frames start one GOP
        earlier); picks that share a start key share one run.
        """
        idx = self.index
        key_dec = np.sort(idx.decode_pos[idx.key])  # decode positions of key frames
        pres_of = np.empty(len(idx), dtype=np.int64)  # decode position -> presentation position
        pres_of[idx.decode_pos] = np.arange(len(idx))
        runs: dict[int, list] = {}
        for i in picks:
            d = int(idx.decode_pos[i])
            j = int(np.searchsorted(key_dec, d, side="right")) - 1
            while j > 0 and idx.pts[pres_of[key_dec[j]]] > idx.pts[i]:
                j -= 1
            start = int(key_dec[j]) if j >= 0 else 0
            run = runs.setdefault(start, [start, d, []])
            run[1] = max(run[1], d)
            run[2].append(int(i))
        return [tuple(r) for _, r in sorted(runs.items())]

    def frame_at(self, index: int, max_width: Optional[int] = None) -> Frame:
        """Frame ``index`` (presentation order), decoded from its key frame (random access)."""
        if not 0 <= index < len(self.index):
            raise IndexError(f"frame {index} outside 0..{len(self.index) - 1}")
        decoders = _Decoders(self.inputs, self.indexes, max_width, self.projection, self.shapes)
        try:
            done = decoders.decode(self._runs(np.asarray([index]))[0])
        finally:
            decoders.close()
        (i, (rgb, source_width)), = done.frames
        return Frame(i, float(self.index.stamps[i]), rgb, source_width)

    def frames(self, interval: float = 1.0, max_width: Optional[int] = None) -> Iterator[Frame]:
        """Frames sampled every ``interval`` seconds (see module doc), in order.

        Decode runs are independent (each starts at a key frame), so ``DECODE_THREADS``
        threads decode them at once, each on a container of its own, at most
        ``RUNS_AHEAD`` runs ahead of the consumer (see ``DECODE_THREADS``).

        With ``max_width``, wider frames come shrunk to it by FFmpeg's area scaler in the
        same pass that converts them to RGB (``Frame.source_width`` keeps the full width):
        converting a 3840x1920 frame to RGB and shrinking it with OpenCV afterwards cost
        23 ms, converting straight to 1024 columns 4 ms (benchmarks/bench_video_sampling.py).
        """
        plan = self.plan(interval)
        stats = SampleStats(mode=plan.mode)
        self.last_stats = stats
        if plan.indices.size == 0:
            return
        decoders = _Decoders(self.inputs, self.indexes, max_width, self.projection, self.shapes)
        pending: deque = deque()
        pool = ThreadPoolExecutor(max_workers=DECODE_THREADS, thread_name_prefix="panotopo-decode")
        try:
            for run in self._runs(plan.indices):
                pending.append(pool.submit(decoders.decode, run))
                if len(pending) < RUNS_AHEAD:
                    continue
                yield from self._deliver(pending.popleft().result(), stats)
            while pending:
                yield from self._deliver(pending.popleft().result(), stats)
        finally:
            for future in pending:
                future.cancel()
            pool.shutdown(wait=True)
            decoders.close()

    def _deliver(self, done: "_DecodedRun", stats: SampleStats) -> Iterator[Frame]:
        stats.runs.append((done.first, done.last))
        stats.decoded += done.decoded
        stats.seeks += done.seeks
        for i, (rgb, source_width) in done.frames:
            stats.delivered += 1
            yield Frame(i, float(self.index.stamps[i]), rgb, source_width)


def _paired(path: Path, indexes: list[StreamIndex]) -> list[StreamIndex]:
    """The streams' indexes as one: frame i of every stream belongs to panorama i; cut to the
    shortest stream (a camera stopped mid-frame), key only where every stream has a key frame."""
    if len(indexes) == 1:
        return indexes
    n = min(len(ix) for ix in indexes)
    first = indexes[0]
    if n < 0.99 * max(len(ix) for ix in indexes) - 1:
        raise InputError(f"{path}: its two lens videos have {len(first)} and {len(indexes[1])} frames; "
                         f"the halves of a 360 picture must come in pairs")
    key = np.logical_and.reduce([ix.key[:n] for ix in indexes])
    if not key.any():
        raise InputError(f"{path}: its lens videos have no key frame in common")
    # presentation positions >= n are dropped; decode positions stay those of the file
    return [StreamIndex(stamps=first.stamps[:n], pts=ix.pts[:n], key=key, decode_pos=ix.decode_pos[:n],
                        fps=first.fps, declared=ix.declared) for ix in indexes]


def _stream_shape(path: Path, stream: int) -> tuple[int, int]:
    with av.open(str(path)) as container:
        s = container.streams.video[stream]
        return int(s.codec_context.width), int(s.codec_context.height)


# Threads that decode runs at once. A run after a seek starts at a key frame, and FFmpeg
# decodes one H.264/HEVC key frame on one thread (frame threads need a sequence of frames,
# camera streams have one slice per frame), so at 1 Hz on key frames one thread was the
# bottleneck: 28-34 ms (ultrafast) to 55 ms (veryfast) per 3840x1920 key frame against ~35 ms
# of describing per sample (benchmarks/bench_video_sampling.py). Two threads use both cores
# of the machine this was measured on; more would only queue behind the descriptor.
DECODE_THREADS = 2
# Runs decoded ahead of the consumer: enough to keep both threads busy while one run is
# being described, few enough that held frames stay small (at most a few full frames).
RUNS_AHEAD = 4


@dataclass
class _DecodedRun:
    first: int
    last: int
    frames: list      # (index, (rgb, source_width)) in the run's pick order
    decoded: int
    seeks: int


class _Decoders:
    """Per decoding thread, one container and packet reader per input (file, video stream),
    closed together at the end; with a projection, one converter per thread too."""

    def __init__(self, inputs, indexes, max_width: Optional[int], projection=None, shapes=None) -> None:
        if isinstance(inputs, (str, Path)):
            inputs = [(Path(inputs), 0)]
        if isinstance(indexes, StreamIndex):
            indexes = [indexes]
        self.inputs, self.indexes, self.max_width = list(inputs), list(indexes), max_width
        self.path = self.inputs[0][0]
        self.index = self.indexes[0]
        self.projection, self.shapes = projection, shapes
        self.orders = [_DecodeOrder(ix) for ix in self.indexes]   # read-only, shared by the threads
        self.pres_of = np.empty(len(self.index), dtype=np.int64)  # input 0: decode -> presentation position
        self.pres_of[self.index.decode_pos] = np.arange(len(self.index))
        self._local = threading.local()
        self._opened: list = []
        self._lock = threading.Lock()

    def _readers(self) -> list:
        readers = getattr(self._local, "readers", None)
        if readers is None:
            readers = []
            for (path, k), order in zip(self.inputs, self.orders):
                try:
                    container = av.open(str(path))
                except (av.error.FFmpegError, OSError) as err:
                    raise InputError(f"{path}: cannot open the video ({_one_line(err)})") from None
                with self._lock:
                    self._opened.append(container)
                stream = container.streams.video[k]
                stream.codec_context.thread_type = "AUTO"
                readers.append(_PacketReader(container, stream, order))
            self._local.readers = readers
        return readers

    def _converter(self):
        conv = getattr(self._local, "converter", None)
        if conv is None:
            from .projection import Converter

            conv = self._local.converter = Converter(self.projection, self.shapes, self.max_width)
        return conv

    def decode(self, run: tuple[int, int, list[int]]) -> _DecodedRun:
        """Decode one run (in a worker thread): its picks as RGB, checked, in pick order.
        ``run`` is in input 0's decode positions; the other inputs decode the same frames
        (same presentation positions) in theirs."""
        first, last, picks = run
        readers = self._readers()
        start = int(self.pres_of[first])          # presentation position of the run's key frame
        got: list[dict] = [{} for _ in readers]
        decoded, seeks = 0, 0
        for k, (packets, ix) in enumerate(zip(readers, self.indexes)):
            codec = packets.stream.codec_context
            wanted = {int(ix.pts[i]): i for i in picks}
            first_k = int(ix.decode_pos[start])
            last_k = max(int(ix.decode_pos[i]) for i in picks)
            seeks_before = packets.seeks
            try:
                for packet in packets.run(first_k, last_k):
                    decoded += k == 0
                    self._keep(codec.decode(packet), wanted, got[k])
                self._keep(codec.decode(None), wanted, got[k])
                codec.flush_buffers()
            except av.error.FFmpegError as err:
                raise InputError(f"{self.inputs[k][0]}: video is damaged ({_one_line(err)})") from None
            seeks += packets.seeks - seeks_before
        for i in picks:
            if any(i not in g for g in got):
                raise InputError(f"{self.path}: frame {i} cannot be decoded")
        if self.projection is None:
            frames = [(i, got[0][i]) for i in picks]
        else:
            conv = self._converter()
            frames = []
            for i in picks:
                rgb = conv([g.pop(i) for g in got])
                frames.append((i, (rgb, conv.native[0] if rgb.shape[1] < conv.native[0] else 0)))
        return _DecodedRun(first, last, frames, decoded, seeks)

    def _keep(self, frames, wanted: dict[int, int], got: dict) -> None:
        """RGB of the wanted decoded ``frames``: equirectangular ones checked 2:1 at full size
        and shrunk past ``max_width``; others at full size for the converter."""
        max_width = self.max_width
        for frame in frames:
            i = wanted.get(frame.pts)
            if i is None:
                continue
            if self.projection is not None:   # converted (from YUV) when every input has its frame
                got[i] = frame
                continue
            w, h = int(frame.width), int(frame.height)
            check_equirectangular_size(w, h, f"{self.path}: frame {i}")
            if max_width and w > max_width:
                small = frame.reformat(width=int(max_width), height=max(1, round(h * max_width / w)),
                                       format="rgb24", interpolation="AREA")
                got[i] = (small.to_ndarray(), w)
            else:
                got[i] = (frame.to_ndarray(format="rgb24"), 0)

    def close(self) -> None:
        with self._lock:
            for container in self._opened:
                container.close()
            self._opened.clear()


class _DecodeOrder:
    """One stream's index in decode order: each decode position's pts (-1 where the paired
    index dropped the frame) and each pts's decode position."""

    def __init__(self, index: StreamIndex) -> None:
        size = int(index.decode_pos.max()) + 1 if len(index) else 0
        self.dec_pts = np.full(size, -1, dtype=np.int64)
        self.dec_pts[index.decode_pos] = index.pts
        self.pos_of = {int(p): d for d, p in enumerate(self.dec_pts) if p >= 0}


class _PacketReader:
    """Packets of decode positions first..last of one stream, seeking forward over what is not needed."""

    def __init__(self, container, stream, order: _DecodeOrder) -> None:
        self.container, self.stream = container, stream
        self.seeks = 0
        self.dec_pts, self.pos_of = order.dec_pts, order.pos_of
        self.demux = None
        self.next_pos = 0  # decode position of the next packet self.demux yields

    def _restart(self, first: int) -> None:
        """Seek to the key frame at decode position ``first`` (read from the start when it is 0)."""
        if self.demux is not None or first > 0:  # a fresh reader's first run need not be the video's
            self.seeks += 1
            target = int(self.dec_pts[first])
            self.container.seek(target, stream=self.stream, backward=True, any_frame=False)
        self.demux = self.container.demux(self.stream)
        self.next_pos = -1  # unknown until the first packet

    def run(self, first: int, last: int) -> Iterator:
        if self.demux is None or self.next_pos != first:
            self._restart(first)
        retried = False
        while True:
            packet = next(self.demux, None)
            if packet is None:
                return
            if packet.size == 0 or packet.pts is None:
                continue
            pos = self.pos_of.get(int(packet.pts))
            if pos is None:
                continue
            if pos < first:
                continue
            if pos > first and self.next_pos == -1:
                if retried:  # seek landed past the key frame twice: give up on this run
                    return
                retried = True
                self.container.seek(0, stream=self.stream, backward=True, any_frame=False)
                self.demux = self.container.demux(self.stream)
                continue
            self.next_pos = pos + 1
            yield packet
            if pos >= last:
                return
