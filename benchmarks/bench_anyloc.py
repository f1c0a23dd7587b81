"""Speed of AnyLoc-VLAD on this machine: sampled frames per second per DINOv2 backbone.

Random weights in the official checkpoint format (speed does not depend on the values),
a fixed random 32-cluster vocabulary (so k-means is not timed), synthetic 2:1 panoramas.
Timed: preprocessing + DINOv2 up to the AnyLoc layer + VLAD, after one warm-up batch.

    python benchmarks/bench_anyloc.py [--backbones vits14 vitb14] [--height 224] [--frames 16]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.descriptors import dinov2  # noqa: E402
from engine.descriptors.anyloc import AnyLocVLAD, save_vocabulary  # noqa: E402


def panoramas(n: int, height: int) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    return [rng.integers(0, 256, (height, 2 * height, 3), dtype=np.uint8) for _ in range(n)]


def bench(backbone: str, height: int, frames: int, batch: int, workdir: Path) -> dict:
    arch = dinov2.get_arch(backbone)
    weights = workdir / arch.checkpoint_name
    if not weights.exists():
        torch.save(dinov2.random_dinov2(backbone).state_dict(), weights)
    vocab = workdir / f"{backbone}_c_centers.pt"
    save_vocabulary(vocab, np.random.default_rng(1).normal(size=(32, arch.embed_dim)))
    model = AnyLocVLAD(backbone=backbone, weights=str(weights), vocabulary=str(vocab),
                       input_height=height, batch_size=batch, device="cpu")
    t0 = time.perf_counter()
    model.backbone()
    load_s = time.perf_counter() - t0
    model.describe(iter(panoramas(batch, height)), batch)          # warm-up
    imgs = panoramas(frames, height)
    t0 = time.perf_counter()
    out = model.describe(iter(imgs), frames)
    dt = time.perf_counter() - t0
    return {"backbone": arch.title, "layer": model.layer, "input": "x".join(map(str, model.size[::-1])),
            "batch": batch, "dim": out.shape[1], "fps": frames / dt, "ms": 1000 * dt / frames,
            "load_s": load_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backbones", nargs="+", default=["vits14", "vitb14"])
    ap.add_argument("--height", type=int, default=224)
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 4])
    args = ap.parse_args()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, CPU")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for backbone in args.backbones:
            for batch in args.batches:
                rows.append(bench(backbone, args.height, args.frames, batch, Path(tmp)))
    print(f"{'backbone':10} {'layer':>5} {'input':>8} {'batch':>5} {'dim':>6} {'frames/s':>9} {'ms/frame':>9} {'load s':>7}")
    for r in rows:
        print(f"{r['backbone']:10} {r['layer']:>5} {r['input']:>8} {r['batch']:>5} {r['dim']:>6} "
              f"{r['fps']:>9.2f} {r['ms']:>9.0f} {r['load_s']:>7.1f}")


if __name__ == "__main__":
    main()
