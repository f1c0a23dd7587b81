"""Render speed of the second synthetic world family (engine.synth2): frames/s per route.

Usage: PYTHONPATH=$PWD python benchmarks/bench_render2.py [--width 256] [--seed 0]
       [--frames N] [--sheet /tmp/world2_sheet.png]
Each route is rendered in full (or its first N frames) on one core; the time includes
building the world. ``--sheet`` also writes a contact sheet of five frames per route.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from engine.synth2 import ROUTES, make_recording  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--sheet", default=None)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    rows = []
    total_n, total_s = 0, 0.0
    for route in ROUTES:
        t0 = time.perf_counter()
        rec = make_recording(route, args.seed, width=args.width, max_frames=args.frames)
        dt = time.perf_counter() - t0
        total_n += len(rec)
        total_s += dt
        print(f"{route:14s} {rec.look:8s} {rec.meta['layout']:11s} {len(rec):4d} frames "
              f"{rec.meta['length_m']:6.1f} m  revisits {len(rec.meta['revisits'])}  "
              f"{len(rec) / dt:6.1f} frames/s")
        if args.sheet:
            idx = np.linspace(0, len(rec) - 1, 5).round().astype(int)
            rows.append(np.hstack([rec.frames[i] for i in idx]))
    print(f"all            {total_n} frames in {total_s:.1f} s: {total_n / total_s:.1f} frames/s "
          f"at {args.width}x{args.width // 2}")
    if args.sheet:
        cv2.imwrite(args.sheet, cv2.cvtColor(np.vstack(rows), cv2.COLOR_RGB2BGR))


if __name__ == "__main__":
    main()
