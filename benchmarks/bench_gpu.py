"""End-to-end `describe` speed on a GPU (or the CPU) and CPU/GPU agreement, as a markdown table.

Self-contained: random weights in the official layouts (speed does not depend on the
values), synthetic 2:1 panoramas, nothing downloaded. Timed: the whole `describe` (upload of
the uint8 frames, resize + normalise on the device, the network, VLAD on the device, rows back
to the host) after a warm-up of six batches; the map vocabulary's k-means is included for the
map-vocabulary rows (that is what a user runs). Beside it: the same with a given vocabulary
(the steady state of a long recording, whose k-means is a one-off), and the DINOv2 forward
pass alone on one batch already on the device (what the rest of ``describe`` costs is the gap).
Below the table: the map vocabulary's k-means on the CPU and on the device (time, largest
centre difference) and the run's peak host memory.

Agreement: the same frames described on the CPU in float32 and on the benchmark device at the
row's precision; row cosine min / median, once with each side's own map vocabulary (what two
users get) and once with the CPU's vocabulary on both sides (the network and VLAD alone). On a machine without a GPU the "device" is the
CPU, so the float32 rows agree exactly and the bfloat16 rows measure autocast alone (the
stand-in for a GPU's bfloat16). Agreement is computed on ``--agree-frames`` frames (the CPU
side of ViT-G/14 is slow).

    python benchmarks/bench_gpu.py                      # CUDA if present: 224 x 448, S/B/G, batch 32
    python benchmarks/bench_gpu.py --cpu-small          # no GPU: 112 x 224, S/B only, few frames
    python benchmarks/bench_gpu.py --models effnet-vlad anyloc-vitg14 --frames 256 --batch 32
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.descriptors import dinov2  # noqa: E402
from engine.descriptors.accel import compute, to_network_input  # noqa: E402
from engine.descriptors.anyloc import AnyLocVLAD, save_vocabulary  # noqa: E402
from engine.descriptors.efficientnet import EfficientNetVLAD  # noqa: E402
from engine.descriptors.vlad import kmeans_cosine  # noqa: E402
from engine.descriptors.vlad_torch import kmeans_cosine_torch  # noqa: E402

MODELS = ("effnet-vlad", "anyloc-vits14", "anyloc-vitb14", "anyloc-vitg14")


def panoramas(n: int, height: int, seed: int = 0) -> list[np.ndarray]:
    """Smooth random 2:1 panoramas at twice the input height (so the resize really runs)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        small = rng.integers(0, 256, (height // 8, height // 4, 3)).astype(np.float32)
        big = torch.nn.functional.interpolate(torch.from_numpy(small).permute(2, 0, 1)[None],
                                              size=(2 * height, 4 * height), mode="bilinear")
        out.append(big[0].permute(1, 2, 0).clamp(0, 255).byte().numpy())
    return out


NETWORKS: dict = {}   # (backbone, device) -> loaded DINOv2: each ViT is read from disk once per device


def make(model: str, height: int, batch: int, device: str, precision: str, workdir: Path,
         centres=None):
    """A describer for ``model`` (effnet-vlad, or anyloc-<backbone>): map vocabulary, or ``centres``."""
    if model == "effnet-vlad":
        return EfficientNetVLAD(input_height=height // 16 * 16, batch_size=batch, device=device,
                                precision=precision, vocabulary=centres)
    backbone = model.split("-", 1)[1]
    arch = dinov2.get_arch(backbone)
    weights = workdir / arch.checkpoint_name
    if not weights.exists():
        torch.save(dinov2.random_dinov2(backbone).state_dict(), weights)
    vocab = None
    if centres is not None:
        vocab = workdir / f"{backbone}_c_centers.pt"
        save_vocabulary(vocab, centres)
    d = AnyLocVLAD(weights=str(weights), input_height=height, batch_size=batch, device=device,
                   precision=precision, vocabulary=None if vocab is None else str(vocab))
    key = (backbone, str(d.device))
    if key not in NETWORKS:
        NETWORKS[key] = d.backbone()
    d._model = NETWORKS[key]
    return d


def centres_of(describer) -> np.ndarray:
    return describer.vocabulary if isinstance(describer, EfficientNetVLAD) else describer.centers


def sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def timed(describer, frames: list[np.ndarray]) -> tuple[np.ndarray, float]:
    # Warm-up of six batches: kernels chosen, and the page-locked input buffers that CUDA
    # allocates for the first few batches in flight (a one-off ~30 ms each, H200 profile) exist.
    warm = min(len(frames), 6 * describer.batch_size)
    describer.describe(iter(frames[:warm]), warm)
    sync(describer.device)
    t0 = time.perf_counter()
    out = describer.describe(iter(frames), len(frames))
    sync(describer.device)
    return out, time.perf_counter() - t0


def network_alone(describer, frames: list[np.ndarray], reps: int = 8) -> float:
    """Frames/s of the DINOv2 forward pass alone on one batch already on the device (NaN for effnet)."""
    if not isinstance(describer, AnyLocVLAD):
        return float("nan")
    b = describer.batch_size
    x = to_network_input(frames[:b], (describer.input_height, 2 * describer.input_height),
                         describer.size, describer.device, "bench")
    net = describer.backbone()
    with compute(describer.device, describer.dtype):
        net.extract(x, describer.layer, describer.facet)
        sync(describer.device)
        t0 = time.perf_counter()
        for _ in range(reps):
            net.extract(x, describer.layer, describer.facet)
        sync(describer.device)
    return reps * b / (time.perf_counter() - t0)


def kmeans_agreement(device: torch.device, rows: int, dim: int, k: int = 32) -> str:
    """One line: the map vocabulary's k-means on the CPU (numpy) and on ``device``, time and largest
    centre difference, on clustered random unit rows."""
    rng = np.random.default_rng(0)
    x = (rng.standard_normal((4 * k, dim))[rng.integers(0, 4 * k, rows)]
         + 0.7 * rng.standard_normal((rows, dim))).astype(np.float32)
    t0 = time.perf_counter()
    cpu = kmeans_cosine(x, k)
    t_cpu = time.perf_counter() - t0
    if device.type != "cuda":
        return f"k-means {rows} x {dim}, k {k}: CPU {t_cpu:.1f} s (no CUDA device here)"
    kmeans_cosine_torch(x[:k * 4], k, device)   # warm-up
    sync(device)
    t0 = time.perf_counter()
    dev = kmeans_cosine_torch(x, k, device)
    t_dev = time.perf_counter() - t0
    return (f"k-means {rows} x {dim}, k {k}: CPU (numpy float64) {t_cpu:.1f} s, {device.type} "
            f"(torch float64) {t_dev:.2f} s, largest centre difference {np.abs(cpu - dev).max():.2e}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=None, choices=MODELS)
    ap.add_argument("--height", type=int, default=None, help="input height (width = 2 x); default 224, 112 with --cpu-small")
    ap.add_argument("--frames", type=int, default=None, help="frames timed (default 256, 8 with --cpu-small)")
    ap.add_argument("--agree-frames", type=int, default=None, help="frames compared CPU vs device (default 8, 4 with --cpu-small)")
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--precisions", nargs="+", default=["float32", "bfloat16"])
    ap.add_argument("--device", default="auto")
    ap.add_argument("--kmeans-rows", type=int, default=None, help="rows of the k-means check (default 100000, 4000 with --cpu-small)")
    ap.add_argument("--cpu-small", action="store_true", help="CPU-sized run: 112 px, ViT-S/B only, few frames")
    args = ap.parse_args()
    small = args.cpu_small
    models = args.models or (["effnet-vlad", "anyloc-vits14", "anyloc-vitb14"] if small else list(MODELS))
    height = args.height or (112 if small else 224)
    n_frames = args.frames or (8 if small else 256)
    n_agree = args.agree_frames or (4 if small else 8)
    batch = min(args.batch, 4) if small else args.batch
    device = torch.device("cuda" if args.device == "auto" and torch.cuda.is_available() else
                          ("cpu" if args.device == "auto" else args.device))
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else f"CPU ({torch.get_num_threads()} threads)"
    frames = panoramas(max(n_frames, n_agree), height)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for model in models:
            reference = None
            for precision in args.precisions:
                d = make(model, height, batch, str(device), precision, Path(tmp))
                alone = network_alone(d, frames)
                out, dt = timed(d, frames[:n_frames])
                if reference is None:   # CPU float32 on the agreement frames, once per model
                    ref = make(model, height, batch, "cpu", "float32", Path(tmp))
                    reference = ref.describe(iter(frames[:n_agree]), n_agree)
                    ref_centres = centres_of(ref)
                    # The same vocabulary given as a file: features pooled in float32 as they come
                    # (the map path pools float16-buffered ones), so compare like with like.
                    ref_fixed = make(model, height, batch, "cpu", "float32", Path(tmp), centres=ref_centres)
                    reference_fixed = ref_fixed.describe(iter(frames[:n_agree]), n_agree)
                mine = make(model, height, batch, str(device), precision, Path(tmp))
                cos = np.sum(reference * mine.describe(iter(frames[:n_agree]), n_agree), axis=1)
                fixed = make(model, height, batch, str(device), precision, Path(tmp), centres=ref_centres)
                _, dt_fixed = timed(fixed, frames[:n_frames])
                cos_fixed = np.sum(reference_fixed * fixed.describe(iter(frames[:n_agree]), n_agree), axis=1)
                rows.append((model, precision, d.settings().get("precision", precision), alone,
                             n_frames / dt, n_frames / dt_fixed,
                             cos.min(), np.median(cos), cos_fixed.min(), np.median(cos_fixed), out.shape[1]))
                print(f"  {model} {precision}: network {alone:.1f}, describe {n_frames / dt:.1f} (map vocabulary), "
                      f"{n_frames / dt_fixed:.1f} (given vocabulary) frames/s", file=sys.stderr, flush=True)
            NETWORKS.clear()
    kmeans_line = kmeans_agreement(device, args.kmeans_rows or (4000 if small else 100_000), 1536)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"Device: {name}; torch {torch.__version__}; input {height} x {2 * height}; batch {batch}; "
          f"{n_frames} frames timed, {n_agree} compared with CPU float32 (random weights)\n")
    print("| model | precision | ran as | network alone, frames/s | describe, map vocabulary (k-means included), frames/s "
          "| describe, given vocabulary, frames/s | cos vs CPU fp32, own map vocabulary: min / median "
          "| same vocabulary: min / median | dim |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|")
    for model, asked, ran, alone, fps, fps_fixed, cmin, cmed, fmin, fmed, dim in rows:
        net = "-" if alone != alone else f"{alone:.1f}"
        print(f"| {model} | {asked} | {ran} | {net} | {fps:.1f} | {fps_fixed:.1f} | {cmin:.4f} / {cmed:.4f} "
              f"| {fmin:.4f} / {fmed:.4f} | {dim} |")
    print(f"\n{kmeans_line}\nPeak host memory (max RSS) of the whole run: {peak:.1f} GiB")


if __name__ == "__main__":
    main()
