"""VLAD on the model's device (torch), batched: the same vectors as ``vlad.vlad`` and
``anyloc.anyloc_vlad`` (numpy, one image at a time), without copying features to the host.

Always float32 (autocast is switched off inside), whatever precision the network ran in:
residual sums over hundreds of patches lose too much in bfloat16.
Layout is cluster-major as in ``vlad.py``: block ``j`` (C numbers) belongs to cluster ``j``.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import InputError
from .accel import full_precision


def as_centers(centers, device: torch.device) -> torch.Tensor:
    """float32 (k, C) tensor on ``device`` from a numpy array or tensor."""
    return torch.as_tensor(np.asarray(centers, dtype=np.float32), device=device)


def _assign(features: torch.Tensor, centers: torch.Tensor) -> torch.Tensor:
    """(B, N) index of the centre most similar by cosine (ties: the lowest index, as numpy)."""
    return torch.argmax(features @ F.normalize(centers, dim=1).T, dim=-1)


def _residual_sums(features: torch.Tensor, centers: torch.Tensor, labels: torch.Tensor,
                   weights: torch.Tensor | None = None) -> torch.Tensor:
    """sum over patches p of cluster j of w(p) (f_p - c_j): (B, [S,] k, C).

    ``weights`` (S, N) gives one weighted sum per window ``s`` (sector VLAD); None = all 1.
    """
    b, n, c = features.shape
    k = centers.shape[0]
    # scatter, not F.one_hot: one_hot checks the labels' range on the host, a wait for the device
    onehot = torch.zeros(b, n, k, dtype=features.dtype, device=features.device)
    onehot.scatter_(2, labels.unsqueeze(2), 1.0)                     # (B, N, k)
    resid = features - centers[labels]                               # (B, N, C)
    if weights is None:
        return onehot.transpose(1, 2) @ resid                        # (B, k, C)
    return torch.einsum("sn,bnk,bnc->bskc", weights, onehot, resid)


def vlad_batch(features: torch.Tensor, centers: torch.Tensor) -> torch.Tensor:
    """VLAD (B, k*C) float32 of unit ``features`` (B, N, C) against ``centers`` (k, C).

    Hard assignment by cosine, residuals to the centres *as given* summed per cluster,
    each block L2-normalised (empty clusters stay zero), the vector L2-normalised. With unit
    centres this is ``vlad.vlad``; with AnyLoc's shorter k-means centres, ``anyloc_vlad``.
    """
    if features.ndim != 3 or centers.ndim != 2 or features.shape[2] != centers.shape[1]:
        raise InputError(f"VLAD: features {tuple(features.shape)} and centres {tuple(centers.shape)} do not match")
    with full_precision(features.device):
        f = features.float()
        c = centers.to(f.device, torch.float32)
        sums = _residual_sums(f, c, _assign(f, c))
        return F.normalize(F.normalize(sums, dim=2).flatten(1), dim=1)


def sector_vlad_batch(features: torch.Tensor, centers: torch.Tensor, sector_weights: torch.Tensor,
                      global_weight: float) -> torch.Tensor:
    """Global VLAD and per-sector VLADs, concatenated: (B, (1+S)*k*C), as ``efficientnet.sector_vlad``.

    ``sector_weights`` (S, N): each patch's window weight per sector (patches row-major).
    The global part carries ``global_weight`` of the squared norm, the sectors share the rest.
    """
    with full_precision(features.device):
        f = features.float()
        c = centers.to(f.device, torch.float32)
        w = sector_weights.to(f.device, torch.float32)
        s = w.shape[0]
        labels = _assign(f, c)
        g = F.normalize(F.normalize(_residual_sums(f, c, labels), dim=2).flatten(1), dim=1)
        parts = _residual_sums(f, c, labels, w)                      # (B, S, k, C)
        parts = F.normalize(F.normalize(parts, dim=3).flatten(2), dim=2).flatten(1)
        out = torch.cat([g * global_weight ** 0.5, parts * ((1.0 - global_weight) / s) ** 0.5], dim=1)
        return F.normalize(out, dim=1)


def kmeans_cosine_torch(features: np.ndarray, k: int, device: torch.device, iters: int = 30,
                        seed: int = 0, chunk: int = 65536) -> np.ndarray:
    """``vlad.kmeans_cosine`` with its iterations on ``device``: the same float64 steps
    (seeds drawn on the host by ``vlad.kmeans_start``, assignment by argmax dot with the first
    index on ties, sums per cluster, the worst-represented rows re-seeding empty clusters,
    stop when no label changes), so the centres agree with the CPU's to float64 rounding.

    Why: on a GPU the CPU's k-means was the slow part of a map vocabulary: 100,000 x 1536
    rows, 32 clusters, 8.6 s on an H200 machine's 16 CPU cores, 0.55 s on the H200 (0.51 s on
    an H100), the same centres to the last bit (``benchmarks/bench_gpu.py``). Float64, not
    float32, because a float32 run on CUDA gave other centres than the CPU (issue 15).
    Per-cluster sums are a one-hot product (fixed reduction order), not atomic adds.
    """
    from .vlad import kmeans_start

    x_host, start = kmeans_start(features, k, seed)
    x = torch.from_numpy(x_host).to(device)
    n = x.shape[0]
    centers = torch.from_numpy(start).to(device)
    labels = None
    for _ in range(iters):
        new_labels = torch.empty(n, dtype=torch.int64, device=device)
        best = torch.empty(n, dtype=torch.float64, device=device)
        sums = torch.zeros_like(centers)
        for lo in range(0, n, chunk):
            part = x[lo:lo + chunk].double()
            sims = part @ centers.T
            best[lo:lo + chunk], new_labels[lo:lo + chunk] = sims.max(dim=1)
            sums += F.one_hot(new_labels[lo:lo + chunk], k).double().T @ part
        counts = torch.bincount(new_labels, minlength=k)
        empty = torch.nonzero(counts == 0).flatten()
        if empty.numel():
            worst = torch.argsort(best, stable=True)[: empty.numel()]
            sums[empty] = x[worst].double()
        centers = sums / sums.norm(dim=1, keepdim=True).clamp_min(1e-12)
        if labels is not None and empty.numel() == 0 and torch.equal(labels, new_labels):
            break
        labels = new_labels
    return centers.cpu().numpy().astype(np.float32)


def kmeans_on(device: torch.device, features: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """Map-vocabulary k-means where the features were made: on CUDA ``kmeans_cosine_torch``,
    elsewhere the numpy ``vlad.kmeans_cosine`` (Apple MPS has no float64)."""
    from .vlad import kmeans_cosine

    if device.type == "cuda":
        return kmeans_cosine_torch(features, k, device, seed=seed)
    return kmeans_cosine(features, k, seed=seed)
