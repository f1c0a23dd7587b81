"""Batch describe on Dask (engine/batch.py) against describing one recording after another.

    python benchmarks/bench_batch.py [--recordings 8] [--frames 24] [--width 512] [--workers 1,2]

Writes ``--recordings`` synthetic videos (random blocky panoramas, ``--width`` x width/2,
``--frames`` frames at 4 fps, every frame described), then times, wall clock:

* ``sequential``: one process, ``engine.pipeline.describe`` of each recording in turn (what a
  shell loop over ``panotopo describe`` costs, less the interpreter start per recording);
* ``batch Nw``: ``panotopo describe ... --out-dir`` as a subprocess on a local cluster of N
  workers (cluster start, torch import per worker, describing, shutdown: all included);
* ``rerun``: the same command again, everything already done (the cost of the skip check).

Each with its CPU time (user + system of the process and its children): on a shared machine the
wall clock follows the load, the CPU time shows the batch's own overhead.

Results (``--recordings 6 --frames 24``: 6 x 24 frames of 512x256, effnet-vlad on the CPU; the
2-core development machine shared with other jobs at a load average of 8-11, so the wall clock
mostly measures the others; docs/cluster.md):

    sequential (one process)                    42.0 s wall    16.0 s CPU
    batch, 1 worker(s)                          53.7 s         22.4 s
    rerun, all done (1 worker(s) asked)          1.9 s          0.8 s
    batch, 2 worker(s)                          70.5 s         32.4 s
    rerun, all done (2 worker(s) asked)          1.5 s          0.6 s

Before the task reset glibc's malloc thresholds on the worker (Dask's MALLOC_TRIM_THRESHOLD_,
engine/batch.py ``_malloc_for_arrays``), the 1-worker batch took 106 s wall / 42.3 s CPU.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import av
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def write_recording(path: Path, seed: int, frames: int, width: int, fps: int = 4) -> Path:
    rng = np.random.default_rng(seed)
    height = width // 2
    base = (rng.random((height // 8, width // 8, 3)) * 255).astype(np.uint8)
    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx264", rate=fps)
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        for i in range(frames):
            img = np.kron(np.roll(base, i, axis=1), np.ones((8, 8, 1), np.uint8))
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                out.mux(packet)
        for packet in stream.encode(None):
            out.mux(packet)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recordings", type=int, default=8)
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--width", type=int, default=512)
    ap.add_argument("--workers", default="1,2")
    args = ap.parse_args()

    work = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    try:
        recs = [write_recording(work / f"rec{k}.mp4", k, args.frames, args.width) for k in range(args.recordings)]
        interval = "0.25"
        rows = []

        def cpu() -> float:   # user + system seconds of the finished child processes (and theirs)
            r = resource.getrusage(resource.RUSAGE_CHILDREN)
            return r.ru_utime + r.ru_stime

        start, c0 = time.perf_counter(), cpu()
        subprocess.run([sys.executable, "-c", (
            "import sys; from engine.pipeline import describe, DescribeSettings, method_settings\n"
            "from engine.params import MapParams\n"
            f"s = method_settings(MapParams(), DescribeSettings(interval={interval}))\n"
            "for p in sys.argv[1:]: describe(p, s, cache=None)\n"), *map(str, recs)],
            cwd=ROOT, check=True)
        rows.append(("sequential (one process)", time.perf_counter() - start, cpu() - c0))

        for n in [int(x) for x in args.workers.split(",")]:
            out = work / f"out{n}"
            cmd = [sys.executable, "-m", "engine", "describe", *map(str, recs), "--out-dir", str(out),
                   "--interval", interval, "--workers", str(n), "-q"]
            start, c0 = time.perf_counter(), cpu()
            subprocess.run(cmd, cwd=ROOT, check=True)
            rows.append((f"batch, {n} worker(s)", time.perf_counter() - start, cpu() - c0))
            start, c0 = time.perf_counter(), cpu()
            subprocess.run(cmd, cwd=ROOT, check=True)
            rows.append((f"rerun, all done ({n} worker(s) asked)", time.perf_counter() - start, cpu() - c0))

        frames = args.recordings * args.frames
        print(f"{args.recordings} recordings x {args.frames} frames of {args.width}x{args.width // 2}"
              f" ({frames} frames), effnet-vlad, CPU")
        print(f"  {'':40s} {'wall':>7s}   {'CPU':>7s}")
        for name, seconds, cpu_s in rows:
            print(f"  {name:40s} {seconds:7.1f} s {cpu_s:7.1f} s")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
