"""Sampled frames per second of the embedded descriptor (effnet-vlad) on this CPU.

Run: python benchmarks/bench_describe.py [--frames N] [--input-height H]
Frames are the example panorama at 1920x960 (a typical 360 video frame), rolled
by a different amount each time; the panorama shift is included, as in a real run.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine import descriptors  # noqa: E402
from engine.shift import apply_shift, canonical_shift  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--input-height", type=int, default=224)
    ap.add_argument("--batch-size", type=int, default=8)
    args = ap.parse_args()
    here = Path(__file__).resolve().parents[1]
    pano = cv2.imread(str(here / "tests" / "data" / "examplepano_1024.jpg"))[:, :, ::-1]
    pano = cv2.resize(pano, (1920, 960), interpolation=cv2.INTER_LINEAR)
    frames = [np.roll(pano, 37 * i, axis=1) for i in range(args.frames)]
    model = descriptors.get("effnet-vlad", input_height=args.input_height, batch_size=args.batch_size)
    model.describe(iter(frames[:2]), 2)  # load weights, warm up

    t0 = time.perf_counter()
    shifted = [apply_shift(f, canonical_shift(f)) for f in frames]
    t1 = time.perf_counter()
    vecs = model.describe(iter(shifted), len(shifted))
    t2 = time.perf_counter()
    n = len(frames)
    print(f"effnet-vlad {args.input_height}x{2 * args.input_height} d={vecs.shape[1]}: "
          f"{n / (t2 - t0):.1f} sampled frames/s "
          f"(shift {1000 * (t1 - t0) / n:.1f} ms/frame, describe {1000 * (t2 - t1) / n:.1f} ms/frame)")


if __name__ == "__main__":
    main()
