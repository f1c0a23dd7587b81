"""Sampling a long 4K video: full decode vs the key-frame-aware sampler vs describe.

Run: python benchmarks/bench_video_sampling.py [--cache DIR] [--seconds 120] [--interval 1.0]

Writes once (to ``--cache``, default ~/.cache/panotopo-bench) a 3840x1920 30 fps H.264
clip with a key frame every ``--gop`` seconds (default 2; PyAV + libx264, ultrafast preset;
the example panorama upscaled and rolled 8 px per frame, so every frame is textured and
different), then times:

1. decoding every frame with OpenCV (``grab()`` only: what the old reader paid to sample);
2. ``engine.sources.video_av.AvSampler`` at the interval (decoded-frame count included);
3. ``engine.pipeline.describe_source`` (what ``panotopo describe`` runs) at the interval
   through the OpenCV reader and through the PyAV sampler (sample, read ahead, shift,
   columns, colours, local features, effnet-vlad; model loaded beforehand).

4. ``--interval keyframes`` (issue 44): the sampler and describe at every key frame only,
   and what it costs in exactness: the distance from each exact sample time t_k = k * 1 s
   to the nearest delivered stamp, against the exact sampler's (under a frame);
5. for the exact sampler: its time against the time decoding its decoded frames costs at the
   full-decode rate (frames decoded / all frames x full decode): the frames that must be decoded.

6. ``--conversion``: the cost of turning camera frames into 1,024-column panoramas
   (``engine.sources.projection.Converter`` on decoded-size YUV frames: a GoPro MAX .360 pair
   of 4096x1344 strips, an Insta360 5.7K pair of 2880x2880 fisheyes, one 5760x2880 side-by-side
   frame), wall and CPU milliseconds per frame.

It prints a table with the ratios to (1) and extrapolates every row to an hour of 4K30
(linearly in the clip's length; the key-frame rows per key frame: an hour at this GOP has
3600 / GOP key frames).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

W, H, FPS, GOP_S, ROLL_PX = 3840, 1920, 30, 2, 8


def write_clip(path: Path, seconds: int, gop_s: float = GOP_S, preset: str = "ultrafast") -> Path:
    """The benchmark clip (skipped when it exists)."""
    import av

    if path.exists():
        return path
    here = Path(__file__).resolve().parents[1]
    pano = cv2.imread(str(here / "tests" / "data" / "examplepano_1024.jpg"))[:, :, ::-1]
    pano = np.ascontiguousarray(cv2.resize(pano, (W, H), interpolation=cv2.INTER_CUBIC))
    tmp = path.with_suffix(".part.mp4")
    with av.open(str(tmp), "w") as out:
        stream = out.add_stream("libx264", rate=FPS)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        stream.options = {"preset": preset, "crf": "23",
                          "x264-params": f"keyint={round(gop_s * FPS)}:min-keyint={round(gop_s * FPS)}:scenecut=0"}
        for i in range(seconds * FPS):
            frame = av.VideoFrame.from_ndarray(np.roll(pano, ROLL_PX * i, axis=1), format="rgb24")
            for packet in stream.encode(frame):
                out.mux(packet)
        for packet in stream.encode(None):
            out.mux(packet)
    tmp.rename(path)
    return path


def time_opencv_full(path: Path) -> tuple[float, int]:
    t0 = time.perf_counter()
    cap = cv2.VideoCapture(str(path))
    n = 0
    while cap.grab():
        n += 1
    cap.release()
    return time.perf_counter() - t0, n


def time_sampler(path: Path, interval: float) -> tuple[float, int, int, str]:
    from engine.sources.video_av import AvSampler

    t0 = time.perf_counter()
    sampler = AvSampler(path)  # includes the index pass (demux, no decoding)
    n = sum(1 for _ in sampler.frames(interval))
    stats = sampler.last_stats
    return time.perf_counter() - t0, n, stats.decoded, stats.mode


def time_keyframes(path: Path) -> tuple[float, int, int, np.ndarray]:
    """The sampler at every key frame only (``--interval keyframes``): time, frames, decoded, stamps."""
    from engine.sources.video_av import AvSampler

    t0 = time.perf_counter()
    sampler = AvSampler(path, keyframes_only=True)
    stamps = np.array([f.stamp for f in sampler.frames(1.0)])
    return time.perf_counter() - t0, int(stamps.size), sampler.last_stats.decoded, stamps


def stamp_error(stamps: np.ndarray, duration: float, interval: float = 1.0) -> tuple[float, float]:
    """(mean, max) seconds from each exact sample time k * interval to the nearest delivered stamp."""
    targets = np.arange(0.0, duration + 1e-9, interval)
    d = np.abs(stamps[None, :] - targets[:, None]).min(axis=1)
    return float(d.mean()), float(d.max())


def time_describe(path: Path, interval: float, use_pyav: bool, model,
                  keyframes_only: bool = False) -> tuple[float, int]:
    """What ``panotopo describe`` does, through one reader (the model is loaded beforehand)."""
    from engine.pipeline import DescribeSettings, describe_source
    from engine.sources import VideoSource

    t0 = time.perf_counter()
    with VideoSource(path, use_pyav=use_pyav, keyframes_only=keyframes_only) as src:
        settings = DescribeSettings(interval=interval, sampling="keyframes" if keyframes_only else "interval")
        descs = describe_source(src, settings, model, str(path))
    return time.perf_counter() - t0, len(descs)


def time_conversion(repeats: int = 5) -> None:
    """Item 6 of the module doc."""
    import av

    from engine.sources.projection import Converter, Projection

    rng = np.random.default_rng(0)
    cases = {"GoPro .360 5.6K (2 x 4096x1344 HEVC strips)": (Projection("eac", "gopro", extra=32), [(4096, 1344)] * 2),
             "Insta360 5.7K (2 x 2880x2880 fisheyes)": (Projection("dual-fisheye", "two-streams", fov=200),
                                                        [(2880, 2880)] * 2),
             "dual fisheye side by side 5760x2880": (Projection("dual-fisheye", "side-by-side", fov=200),
                                                     [(5760, 2880)])}
    print("| camera frames -> 1,024-column panorama | native panorama | ms per frame | CPU ms per frame |")
    print("|---|---|---:|---:|")
    for name, (p, shapes) in cases.items():
        frames = [av.VideoFrame.from_ndarray(rng.integers(0, 255, (h * 3 // 2, w), dtype=np.uint8),
                                             format="yuvj420p") for w, h in shapes]
        conv = Converter(p, shapes, out_width=1024)
        conv(frames)   # the filter graph and v360's maps are built once per reader thread
        c0, t0 = time.process_time(), time.perf_counter()
        for _ in range(repeats):
            conv(frames)
        wall, cpu = (time.perf_counter() - t0) / repeats, (time.process_time() - c0) / repeats
        print(f"| {name} | {conv.native[0]}x{conv.native[1]} | {wall * 1000:.0f} | {cpu * 1000:.0f} |")


CPU: dict = {}   # row name -> process CPU seconds (all threads), robust to a loaded machine


def cpu_of(what: str, fn, *args, **kw):
    """``fn(*args, **kw)``, its process CPU seconds kept under ``what``."""
    c0 = time.process_time()
    out = fn(*args, **kw)
    CPU[what] = time.process_time() - c0
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "panotopo-bench")
    ap.add_argument("--seconds", type=int, default=120)
    ap.add_argument("--interval", type=float, nargs="+", default=[1.0, 2.0])
    ap.add_argument("--gop", type=float, default=GOP_S, help="seconds between key frames (default 2)")
    ap.add_argument("--preset", default="ultrafast",
                    help="libx264 preset of the clip: ultrafast (no CABAC, B-frames or deblocking: the cheapest "
                         "stream to decode) or e.g. veryfast (CABAC, B-frames, deblocking, as cameras write)")
    ap.add_argument("--write-only", action="store_true")
    ap.add_argument("--conversion", action="store_true", help="only time the projection conversion (item 6)")
    ap.add_argument("--no-describe", action="store_true")
    ap.add_argument("--no-opencv-describe", action="store_true", help="describe through the PyAV reader only")
    args = ap.parse_args()
    if args.conversion:
        time_conversion()
        return
    args.cache.mkdir(parents=True, exist_ok=True)
    preset = "" if args.preset == "ultrafast" else f"_{args.preset}"
    clip = args.cache / f"roll_{W}x{H}_{FPS}fps_gop{args.gop:g}s_{args.seconds}s{preset}.mp4"
    t0 = time.perf_counter()
    existed = clip.exists()
    write_clip(clip, args.seconds, args.gop, args.preset)
    if not existed:
        print(f"wrote {clip} in {time.perf_counter() - t0:.0f} s")
    if args.write_only:
        return
    full, n = cpu_of("OpenCV decode of all frames", time_opencv_full, clip)
    rows = [("OpenCV decode of all frames", full, n, n, "all")]
    model = None
    if not args.no_describe:
        from engine import descriptors

        model = descriptors.get("effnet-vlad")
        model.describe(iter([np.zeros((H // 4, W // 4, 3), np.uint8)]), 1)  # load the weights
    notes = []
    readers = ((True, "PyAV"),) if args.no_opencv_describe else ((False, "OpenCV"), (True, "PyAV"))
    for interval in args.interval:
        t, k, decoded, mode = cpu_of(f"AvSampler every {interval:g} s", time_sampler, clip, interval)
        rows.append((f"AvSampler every {interval:g} s", t, k, decoded, mode))
        if mode == "exact":
            must = decoded / n * full
            notes.append(f"exact every {interval:g} s: {t:.1f} s against {must:.1f} s for decoding its {decoded} "
                         f"decoded frames at the full-decode rate ({t / must:.2f}x)")
            must_cpu = decoded / n * CPU["OpenCV decode of all frames"]
            cpu = CPU[f"AvSampler every {interval:g} s"]
            notes.append(f"exact every {interval:g} s, CPU: {cpu:.1f} CPU-s against {must_cpu:.1f} CPU-s "
                         f"({cpu / must_cpu:.2f}x)")
        if model is not None:
            for use_pyav, reader in readers:
                t, k = cpu_of(f"describe every {interval:g} s, {reader} reader", time_describe, clip, interval,
                              use_pyav, model)
                rows.append((f"describe every {interval:g} s, {reader} reader", t, k, None, ""))
    t, k, decoded, stamps = cpu_of("AvSampler key frames only", time_keyframes, clip)
    rows.append(("AvSampler key frames only", t, k, decoded, "all-keyframes"))
    key_rows = [(len(rows) - 1, k)]
    mean_err, max_err = stamp_error(stamps, (n - 1) / FPS)
    notes.append(f"key frames only: {k} samples for {int((n - 1) / FPS) + 1} exact 1 Hz times; nearest key frame "
                 f"to a 1 Hz time: mean {mean_err:.3f} s, max {max_err:.3f} s (exact sampler: under 1/{FPS} s)")
    if model is not None:
        t, k = cpu_of("describe key frames only, PyAV reader", time_describe, clip, 1.0, True, model,
                      keyframes_only=True)
        rows.append(("describe key frames only, PyAV reader", t, k, None, ""))
        key_rows.append((len(rows) - 1, k))
    print(f"\n{clip.name}: {n} frames, {n / FPS:.0f} s\n")
    print("| what | seconds | CPU-s | x full decode | frames out | frames decoded | mode |")
    print("|------|--------:|------:|--------------:|-----------:|---------------:|------|")
    for what, t, k, decoded, mode in rows:
        print(f"| {what} | {t:.1f} | {CPU.get(what, float('nan')):.1f} | {t / full:.2f} | {k} | "
              f"{'' if decoded is None else decoded} | {mode} |")
    hour = 3600 * FPS / n
    for what, t, *_ in rows:
        print(f"an hour of 4K30, {what}: about {t * hour / 60:.1f} min")
    keys_per_hour = 3600 / args.gop
    for i, k in key_rows:
        what, t = rows[i][0], rows[i][1]
        print(f"an hour of 4K30 at a {args.gop:g} s GOP, {what}: {t / k:.3f} s per key frame x "
              f"{keys_per_hour:.0f} key frames = about {t / k * keys_per_hour / 60:.1f} min; from CPU time "
              f"({CPU[what] / k:.3f} CPU-s per key frame, both cores busy): about "
              f"{CPU[what] / k * keys_per_hour / 2 / 60:.1f} min")
    for note in notes:
        print(note)


if __name__ == "__main__":
    main()
