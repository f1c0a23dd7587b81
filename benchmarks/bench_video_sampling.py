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

It prints a table with the ratios to (1) and extrapolates every row to an hour of 4K30.
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


def time_describe(path: Path, interval: float, use_pyav: bool, model) -> tuple[float, int]:
    """What ``panotopo describe`` does, through one reader (the model is loaded beforehand)."""
    from engine.pipeline import DescribeSettings, describe_source
    from engine.sources import VideoSource

    t0 = time.perf_counter()
    with VideoSource(path, use_pyav=use_pyav) as src:
        descs = describe_source(src, DescribeSettings(interval=interval), model, str(path))
    return time.perf_counter() - t0, len(descs)


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
    ap.add_argument("--no-describe", action="store_true")
    args = ap.parse_args()
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
    full, n = time_opencv_full(clip)
    rows = [("OpenCV decode of all frames", full, n, n, "all")]
    model = None
    if not args.no_describe:
        from engine import descriptors

        model = descriptors.get("effnet-vlad")
        model.describe(iter([np.zeros((H // 4, W // 4, 3), np.uint8)]), 1)  # load the weights
    for interval in args.interval:
        t, k, decoded, mode = time_sampler(clip, interval)
        rows.append((f"AvSampler every {interval:g} s", t, k, decoded, mode))
        if model is not None:
            for use_pyav, reader in ((False, "OpenCV"), (True, "PyAV")):
                t, k = time_describe(clip, interval, use_pyav, model)
                rows.append((f"describe every {interval:g} s, {reader} reader", t, k, None, ""))
    print(f"\n{clip.name}: {n} frames, {n / FPS:.0f} s\n")
    print("| what | seconds | x full decode | frames out | frames decoded | mode |")
    print("|------|--------:|--------------:|-----------:|---------------:|------|")
    for what, t, k, decoded, mode in rows:
        print(f"| {what} | {t:.1f} | {t / full:.2f} | {k} | {'' if decoded is None else decoded} | {mode} |")
    hour = 3600 * FPS / n
    for what, t, *_ in rows:
        print(f"an hour of 4K30, {what}: about {t * hour / 60:.1f} min")


if __name__ == "__main__":
    main()
