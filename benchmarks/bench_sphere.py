"""Cost of local features and two-view geometry, and inliers of true vs false revisits.

    PYTHONPATH=$PWD OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_sphere.py [--quick]

Times are CPU milliseconds of this process (``time.process_time``).

1. ``engine.features.extract`` ms per 1024x512 frame (tests/data/examplepano_1024.jpg).
2. ``engine.sphere.two_view`` ms per pair: a rolled real panorama (a clean rotation), a
   synthetic moving pair with 30 % and with 70 % wrong matches (the last runs all draws),
   real GoPro MAX steps (when /work/shared/data is there).
3. On synthetic recordings (``engine.synth``, ground-truth poses): every frame's best
   descriptor matches (``TOP`` most similar frames more than ``GAP_S`` seconds away) are
   verified; inliers of pairs < 1 m apart vs > 6 m apart. "Hardest" is every frame's most
   similar frame among those > 6 m away (chosen with the ground truth): the look-alikes a
   loop threshold must reject. Numbers for choosing loop thresholds, which this script
   does not do.
4. With ``--pairs FILE.npz`` (a descriptors file with local features): ``two_view`` ms per
   pair for 300 random pairs of frames more than 5 apart (mostly false, the RANSAC caps'
   worst case) and 100 consecutive pairs (true), mean / 90 % / max.
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
from engine.features import LocalFeatures, extract  # noqa: E402
from engine.frames import Frame  # noqa: E402
from engine.pipeline import DescribeSettings, describe_frames  # noqa: E402
from engine.sphere import bearings, to_uv, two_view, verify_pairs  # noqa: E402
from engine.synth import make_recording  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GOPRO = Path("/work/shared/data/real/panoramax-gopromax")
TOP = 3
GAP_S = 15.0
FPS = 2.0
CASES = [("loop", "outdoor", 1), ("loop", "indoor", 2), ("crossing", "outdoor", 3), ("reverse", "indoor", 4),
         ("offset", "outdoor", 5)]


def timed(fn, repeat):
    """Median milliseconds of CPU time of this process (on a shared machine wall time mostly
    measures the neighbours; run with one BLAS/OpenMP thread so CPU time is one core's)."""
    fn()
    times = []
    for _ in range(repeat):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return 1000 * float(np.median(times))


def synthetic_pair(rng, outliers, n=400):
    dirs = bearings(np.stack([rng.random(n), rng.uniform(0.1, 0.8, n)], axis=1))
    xa = dirs * rng.uniform(2.0, 10.0, (n, 1))
    c, s = np.cos(0.7), np.sin(0.7)
    xb = xa @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [0.8, -0.5, 0.1]
    uv_b = to_uv(xb)
    bad = rng.random(n) < outliers
    uv_b[bad] = rng.random((bad.sum(), 2)) * [1, 0.7] + [0, 0.1]
    desc = rng.integers(0, 256, (n, 128)).astype(np.uint8)
    return (LocalFeatures(to_uv(xa).astype(np.float32), desc), LocalFeatures(uv_b.astype(np.float32), desc))


def costs(repeat):
    pano = cv2.cvtColor(cv2.imread(str(ROOT / "tests/data/examplepano_1024.jpg")), cv2.COLOR_BGR2RGB)
    print(f"extract, 1024x512 frame: {timed(lambda: extract(pano), repeat):.1f} ms ({len(extract(pano))} features)")
    # The default descriptor on the same frames, same machine and moment, for scale.
    model = descriptors.get(descriptors.DEFAULT_DESCRIPTOR)
    batch = [np.roll(pano, 37 * i, axis=1) for i in range(16)]
    ms = timed(lambda: model.describe(iter(batch), count=len(batch)), max(1, repeat // 5)) / len(batch)
    print(f"{descriptors.DEFAULT_DESCRIPTOR} describe, 1024x512 frame: {ms:.1f} ms")
    fa = extract(pano)
    pairs = {"rolled real panorama": (fa, extract(np.roll(pano, 123, axis=1)))}
    rng = np.random.default_rng(0)
    pairs["synthetic, 30% wrong"] = synthetic_pair(rng, 0.3)
    pairs["synthetic, 70% wrong"] = synthetic_pair(rng, 0.7)
    if GOPRO.exists():
        g = [extract(cv2.resize(cv2.cvtColor(cv2.imread(str(GOPRO / f"{i}.jpg")), cv2.COLOR_BGR2RGB), (1024, 512),
                                interpolation=cv2.INTER_AREA)) for i in (1, 2, 5)]
        pairs["GoPro 1->2 (~1 m)"] = (g[0], g[1])
        pairs["GoPro 1->5 (~9 m)"] = (g[0], g[2])
    for name, (a, b) in pairs.items():
        tv = two_view(a, b)
        ms = timed(lambda: two_view(a, b), repeat)
        print(f"two_view, {name}: {ms:.1f} ms  ({len(a)}/{len(b)} features, {tv.matches} matches, "
              f"{tv.inliers} inliers, {tv.model})")


def revisits(cases):
    print(f"\nbest {TOP} descriptor matches > {GAP_S:.0f} s apart of every frame ({FPS:g} fps, 512x256):")
    print("| recording | pairs < 1 m | inliers (10/50/90 %) | pairs > 6 m | inliers (50/90/99 %, max) "
          "| hardest > 6 m: inliers (50/90/99 %, max) | ms per pair |")
    print("|---|---|---|---|---|---|---|")
    near_all, far_all, hard_all = [], [], []
    for route, look, seed in cases:
        rec = make_recording(route, look, seed=seed, width=512, height=256, fps=FPS)
        frames = (Frame(k, float(t), rgb) for k, (t, rgb) in enumerate(zip(rec.stamps, rec.frames)))
        descs = describe_frames(frames, len(rec.stamps), DescribeSettings(interval=1.0 / FPS))
        sim = descs.vectors @ descs.vectors.T
        t = descs.stamps
        sim[np.abs(t[:, None] - t[None, :]) <= GAP_S] = -np.inf
        a = np.repeat(np.arange(len(t)), TOP)
        b = np.argsort(-sim, axis=1)[:, :TOP].ravel()
        keep = np.isfinite(sim[a, b])
        a, b = a[keep], b[keep]
        x, y = rec.poses.x[descs.frames], rec.poses.y[descs.frames]
        apart = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
        hard_sim = np.where(apart > 6.0, sim, -np.inf)
        ha = np.arange(len(t))
        hb = np.argmax(hard_sim, axis=1)
        ha, hb = ha[np.isfinite(hard_sim[ha, hb])], hb[np.isfinite(hard_sim[ha, hb])]
        t0 = time.process_time()
        out = verify_pairs(descs.features, a, b)
        ms = 1000 * (time.process_time() - t0) / max(1, a.size)
        hard = verify_pairs(descs.features, ha, hb)["inliers"]
        dist = apart[a, b]
        near, far = out["inliers"][dist < 1.0], out["inliers"][dist > 6.0]
        near_all.append(near)
        far_all.append(far)
        hard_all.append(hard)
        print(f"| {route} {look} {seed} | {near.size} | {_pct(near, (10, 50, 90))} | {far.size} | "
              f"{_pct(far, (50, 90, 99))}, {_max(far)} | {_pct(hard, (50, 90, 99))}, {_max(hard)} | {ms:.1f} |",
              flush=True)
    near, far, hard = (np.concatenate(x) for x in (near_all, far_all, hard_all))
    print(f"| all | {near.size} | {_pct(near, (10, 50, 90))} | {far.size} | {_pct(far, (50, 90, 99))}, "
          f"{_max(far)} | {_pct(hard, (50, 90, 99))}, {_max(hard)} | |")


def candidate_pairs(path, seed=0):
    """CPU ms per pair of ``two_view`` on pairs of a recording's stored features."""
    from engine.descriptors.base import Descriptors

    table = Descriptors.load(path).features
    n = len(table)
    rng = np.random.default_rng(seed)
    far = []
    while len(far) < 300:
        i, j = (int(x) for x in rng.integers(0, n, 2))
        if abs(i - j) > 5:
            far.append((i, j))
    near = [(int(i), int(i) + 1) for i in rng.integers(0, n - 1, 100)]
    print(f"\ntwo_view on pairs of {Path(path).name} ({n} frames): ms mean / 90 % / max, inliers 50/90 %, max")
    for name, pairs in (("random, > 5 frames apart", far), ("consecutive", near)):
        ms, inl = [], []
        for i, j in pairs:
            fa, fb = table.of(i), table.of(j)
            t = time.process_time()
            tv = two_view(fa, fb)
            ms.append(1000 * (time.process_time() - t))
            inl.append(tv.inliers if tv.model != "none" else 0)
        ms, inl = np.array(ms), np.array(inl)
        print(f"{name}: {ms.mean():.2f} / {np.percentile(ms, 90):.2f} / {ms.max():.2f} ms, "
              f"{_pct(inl, (50, 90))}, {_max(inl)}")


def _max(x):
    return int(x.max()) if x.size else "-"


def _pct(x, qs):
    return "/".join(f"{np.percentile(x, q):.0f}" for q in qs) if x.size else "-"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="one recording, fewer repeats")
    ap.add_argument("--pairs", metavar="FILE.npz", help="also time pairs of this descriptors file's features")
    args = ap.parse_args()
    cv2.setNumThreads(1)          # one core, so CPU time is comparable with the descriptor's
    import torch
    torch.set_num_threads(1)
    costs(5 if args.quick else 20)
    if args.pairs:
        candidate_pairs(args.pairs)
    revisits(CASES[:1] if args.quick else CASES)


if __name__ == "__main__":
    main()
