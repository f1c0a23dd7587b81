"""Speed of the synthetic renderer: frames per second at 256x128 and 512x256.

Run: python benchmarks/bench_render.py   (prints one line per size and a route total)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.synth import make_recording, make_route, render  # noqa: E402


def bench(look: str, width: int, frames: int, people: int = 5) -> float:
    route = make_route("demo", look, seed=0, people=people)
    tr = route.trajectory
    idx = [int(round(i * (tr.t.size - 1) / max(frames - 1, 1))) for i in range(frames)]
    render(route.world, tr.x[0], tr.y[0], tr.yaw[0], tr.t[0], width, width // 2)   # warm-up
    t0 = time.perf_counter()
    for k in idx:
        render(route.world, tr.x[k], tr.y[k], tr.yaw[k], tr.t[k], width, width // 2)
    return frames / (time.perf_counter() - t0)


def main() -> None:
    for look in ("indoor", "outdoor"):
        for width, n in ((256, 200), (512, 100)):
            fps = bench(look, width, n)
            print(f"{look:8s} {width}x{width // 2}: {fps:6.1f} frames/s (5 walkers)")
    # A whole ~100 m route: the crossing route at 5 fps, 0.8 m/s.
    for width in (256, 512):
        t0 = time.perf_counter()
        rec = make_recording("crossing", "indoor", seed=0, width=width, height=width // 2,
                             fps=5.0, speed=0.8, people=3)
        dt = time.perf_counter() - t0
        print(f"crossing indoor {rec.meta['length_m']:.0f} m, {len(rec)} frames at "
              f"{width}x{width // 2}: {dt:.1f} s")


if __name__ == "__main__":
    main()
