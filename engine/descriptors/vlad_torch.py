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
    onehot = F.one_hot(labels, k).to(features.dtype)                 # (B, N, k)
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
