"""Does the panorama shift help? Canonical-heading agreement and the Table I recall effect.

    python benchmarks/bench_shift.py --mode agreement [--seeds 0,1,2,3,4]
    python benchmarks/bench_shift.py --mode methods   [--seeds 0,1,2] [--layout sectors]
    python benchmarks/bench_shift.py --mode verified  [--seeds 8,9]   [--layout sectors]

``agreement``: for same-place pairs (<= 1 m apart, >= 20 s apart) of every synthetic
route, the share whose canonical headings (``engine.shift.canonical_shift``) agree with
the true relative yaw within 20 degrees. ``methods``: simple, shift-simple and ours on
crossing and reverse routes at the same calibrated threshold (the harness of
``engine.benchmark``), with the ``effnet-vlad`` layout given. ``verified``: the
``verified`` method (and ``ours``) on held-out seeds with that layout.
Recordings are 256x128 at 1 frame/s like bench_methods.py; descriptors are cached under
--cache with the layout in the file name (never mix caches of different versions).
The table goes to stdout.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

from engine.benchmark import (FPS, PAPER_METHODS, Case, Described, calibrated_params,  # noqa: E402
                              evaluate_methods, summary_table)
from engine.descriptors.base import Descriptors  # noqa: E402
from engine.frames import Frame  # noqa: E402
from engine.pipeline import DescribeSettings, describe_frames  # noqa: E402
from engine.shift import canonical_shift  # noqa: E402
from engine.synth import make_recording  # noqa: E402

# Disturbances per seed, as in bench_methods.py (seeds above 4 repeat seed % 5).
DISTURBANCES = {0: {}, 1: {}, 2: {"people": 3, "noise": 0.01}, 3: {"people": 3},
                4: {"people": 4, "lighting_drift": 0.3, "noise": 0.01}}


def case_for(route: str, look: str, seed: int) -> Case:
    return Case(route, look, seed, **DISTURBANCES[seed % 5])


def render(case: Case):
    return make_recording(case.route, case.look, case.seed, width=case.width, height=case.width // 2,
                          fps=FPS, people=case.people, lighting_drift=case.lighting_drift, noise=case.noise)


def same_place_pairs(x: np.ndarray, y: np.ndarray, min_gap: int = 20, radius: float = 1.0):
    i, j = np.triu_indices(x.size, min_gap)
    keep = np.hypot(x[i] - x[j], y[i] - y[j]) <= radius
    return i[keep], j[keep]


def heading_errors_deg(shifts: np.ndarray, yaw: np.ndarray, width: int, i: np.ndarray, j: np.ndarray):
    """|canonical heading difference - true yaw difference| per pair, in degrees.
    Render convention: a yaw turn by d radians rolls the content by d * W / (2 pi) columns."""
    err = (shifts[j] - shifts[i]) - (yaw[j] - yaw[i]) * width / (2 * np.pi)
    return np.abs((err * 360.0 / width + 180.0) % 360.0 - 180.0)


def agreement(seeds) -> str:
    lines = ["| route | look | pairs | agree within 20 deg | within 45 deg |", "|---|---|---|---|---|"]
    for route in ("crossing", "reverse", "offset", "loop"):
        for look in ("indoor", "outdoor"):
            errs = []
            for seed in seeds:
                rec = render(case_for(route, look, seed))
                i, j = same_place_pairs(rec.poses.x, rec.poses.y)
                shifts = np.array([canonical_shift(f) for f in rec.frames])
                errs.append(heading_errors_deg(shifts, rec.poses.yaw, rec.frames.shape[2], i, j))
            e = np.concatenate(errs)
            lines.append(f"| {route} | {look} | {e.size} | {np.mean(e <= 20):.2f} | {np.mean(e <= 45):.2f} |")
    return "\n".join(lines)


def describe(case: Case, shifts, layout: str, input_height: int, cache: Path) -> Described:
    by_shift = {}
    rec = None
    for shift in shifts:
        path = cache / f"{case.name}_{layout}_h{input_height}_{'shift' if shift else 'noshift'}.npz"
        if path.is_file():
            by_shift[shift] = Descriptors.load(path)
            continue
        if rec is None:
            rec = render(case)
        settings = DescribeSettings(interval=1.0 / FPS, shift=shift,
                                    options={"input_height": input_height, "layout": layout})
        frames = (Frame(k, float(t), rgb) for k, (t, rgb) in enumerate(zip(rec.stamps, rec.frames)))
        by_shift[shift] = describe_frames(frames, len(rec), settings, source=case.name)
        path.parent.mkdir(parents=True, exist_ok=True)
        by_shift[shift].save(path)
    return Described(case, by_shift, case.poses(), {})


def methods_rows(seeds, routes, methods, shifts, layout, input_height, cache):
    rows = []
    for seed in seeds:
        for route in routes:
            for look in ("indoor", "outdoor"):
                t0 = time.perf_counter()
                d = describe(case_for(route, look, seed), shifts, layout, input_height, cache)
                rows += evaluate_methods(d, methods, calibrated_params(d, methods))
                print(f"{route} {look} {seed}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", choices=("agreement", "methods", "verified"), default="methods")
    ap.add_argument("--seeds", default=None)
    ap.add_argument("--layout", default="sectors")
    ap.add_argument("--input-height", type=int, default=128)
    ap.add_argument("--cache", default="/tmp/pshift/bench")
    args = ap.parse_args()
    cache = Path(args.cache)
    if args.mode == "agreement":
        seeds = [int(s) for s in (args.seeds or "0,1,2,3,4").split(",")]
        text = f"## Canonical heading agreement, same-place pairs, seeds {seeds}\n\n" + agreement(seeds)
    elif args.mode == "methods":
        seeds = [int(s) for s in (args.seeds or "0,1,2").split(",")]
        routes = ("crossing", "reverse")
        rows = methods_rows(seeds, routes, PAPER_METHODS, (True, False), args.layout, args.input_height, cache)
        text = (f"## Table I methods, layout {args.layout}, input height {args.input_height}, seeds {seeds}\n\n"
                + summary_table(rows, PAPER_METHODS, routes))
    else:
        seeds = [int(s) for s in (args.seeds or "8,9").split(",")]
        routes = ("crossing", "reverse", "offset", "loop")
        methods = ("ours", "verified")
        rows = methods_rows(seeds, routes, methods, (True,), args.layout, args.input_height, cache)
        text = (f"## verified and ours, layout {args.layout}, input height {args.input_height}, seeds {seeds}\n\n"
                + summary_table(rows, methods, routes))
    print(text)   # stdout only: benchmarks/results/ keeps runs.csv (benchmarks/runs.py), not one file per run
    return 0


if __name__ == "__main__":
    sys.exit(main())
