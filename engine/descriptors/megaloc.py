"""MegaLoc (Berton and Masone, CVPRW 2025; github gmberton/MegaLoc, MIT): DINOv2 ViT-B/14
and an optimal-transport (SALAD-style) aggregator, 8448 numbers per image.

Written for panotopo from the published architecture; the module names and shapes follow the
official weight files so they load unchanged:

* ``backbone.*``: the DINOv2 ViT-B/14 (``megaloc_model.py`` of 2026, ``model.safetensors`` on
  Hugging Face ``gberton/MegaLoc``, no ``mask_token``), or ``backbone.model.*`` (the v1.0 GitHub
  release ``megaloc.torch``, which wraps torch hub's DINOv2, ``mask_token`` included).
* ``aggregator.agg.{token_features.{0,2}, cluster_features.{0,3}, score.{0,3}, dust_bin}`` and
  ``aggregator.linear``: (64 clusters x 256 + 256-d scene token = 16,640) -> 8448.

Forward: all DINOv2 blocks and the final norm; the CLS token through ``token_features``, the
patch map through 1x1-conv MLPs to 256-d cluster features and 64 cluster scores; a Sinkhorn
(3 log-domain iterations, with a dustbin row) turns scores into soft assignments; features
summed per cluster, each cluster L2-normalised (layout: feature-major, cluster-minor, as the
official ``flatten``), the scene token L2-normalised in front, all L2-normalised, the linear
layer, L2-normalised. Sizes are read from the file, so small test models load too.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from ..errors import InputError
from . import dinov2
from .globalnet import GlobalNetDescriptor, check_layout, dinov2_arch

SINKHORN_ITERS = 3   # the official aggregator's setting


def sinkhorn_log(scores: torch.Tensor, dustbin: torch.Tensor, iters: int = SINKHORN_ITERS) -> torch.Tensor:
    """Log assignment (B, m, n) of n patches to m clusters from ``scores`` (B, m, n).

    A dustbin row (score ``dustbin``) is appended; row marginals are 1/(n+m) for each cluster
    and (n-m)/(n+m) for the dustbin, column marginals 1/(n+m); ``iters`` alternating
    log-domain normalisations; the result is scaled by n+m (so a column sums to ~1) and the
    dustbin row dropped.
    """
    b, m, n = scores.shape
    if n <= m:
        raise InputError(f"MegaLoc needs more image patches than its {m} clusters, got {n}: "
                         f"use a larger --input-height")
    aug = torch.cat([scores, dustbin.to(scores.dtype).expand(b, 1, n)], dim=1)
    log_norm = -math.log(n + m)
    log_rows = torch.full((m + 1,), log_norm, dtype=scores.dtype, device=scores.device)
    log_rows[-1] += math.log(n - m)
    log_cols = torch.full((n,), log_norm, dtype=scores.dtype, device=scores.device)
    u = torch.zeros(b, m + 1, dtype=scores.dtype, device=scores.device)
    v = torch.zeros(b, n, dtype=scores.dtype, device=scores.device)
    for _ in range(iters):
        u = log_rows - torch.logsumexp(aug + v[:, None, :], dim=2)
        v = log_cols - torch.logsumexp(aug + u[:, :, None], dim=1)
    return (aug + u[:, :, None] + v[:, None, :] - log_norm)[:, :m]


def _pointwise_mlp(cin: int, hidden: int, cout: int) -> nn.Sequential:
    """1x1 conv, (dropout slot: identity at inference), ReLU, 1x1 conv: weights at .0 and .3."""
    return nn.Sequential(nn.Conv2d(cin, hidden, 1), nn.Identity(), nn.ReLU(), nn.Conv2d(hidden, cout, 1))


class SinkhornAggregator(nn.Module):
    def __init__(self, channels: int, clusters: int, cluster_dim: int, token_dim: int, hidden: int):
        super().__init__()
        self.token_features = nn.Sequential(nn.Linear(channels, hidden), nn.ReLU(), nn.Linear(hidden, token_dim))
        self.cluster_features = _pointwise_mlp(channels, hidden, cluster_dim)
        self.score = _pointwise_mlp(channels, hidden, clusters)
        self.dust_bin = nn.Parameter(torch.tensor(1.0))

    def forward(self, patches: torch.Tensor, cls: torch.Tensor) -> torch.Tensor:
        """(B, C, h, w) patch map and (B, C) CLS token -> (B, token_dim + cluster_dim * clusters)."""
        feats = self.cluster_features(patches).flatten(2)                   # (B, d, n)
        assign = sinkhorn_log(self.score(patches).flatten(2), self.dust_bin).exp()   # (B, m, n)
        per_cluster = F.normalize(torch.einsum("bdn,bmn->bdm", feats, assign), dim=1)
        token = F.normalize(self.token_features(cls), dim=-1)
        return F.normalize(torch.cat([token, per_cluster.flatten(1)], dim=1), dim=-1)


class MegaLocHead(nn.Module):
    """``aggregator``: the Sinkhorn aggregator (``agg``) and the final ``linear`` projection."""

    def __init__(self, channels: int, clusters: int, cluster_dim: int, token_dim: int, hidden: int, out_dim: int):
        super().__init__()
        self.agg = SinkhornAggregator(channels, clusters, cluster_dim, token_dim, hidden)
        self.linear = nn.Linear(token_dim + clusters * cluster_dim, out_dim)

    def forward(self, patches: torch.Tensor, cls: torch.Tensor) -> torch.Tensor:
        return self.linear(self.agg(patches, cls))


class MegaLocNet(nn.Module):
    def __init__(self, arch: dinov2.Arch, clusters: int = 64, cluster_dim: int = 256, token_dim: int = 256,
                 hidden: int = 512, out_dim: int = 8448):
        super().__init__()
        self.backbone = dinov2.DinoVisionTransformer(arch)
        self.aggregator = MegaLocHead(arch.embed_dim, clusters, cluster_dim, token_dim, hidden, out_dim)
        self.output_dim = out_dim

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        b, _, h, w = images.shape
        tokens = self.backbone(images)                                      # final norm applied
        grid = tokens[:, 1:].reshape(b, h // dinov2.PATCH, w // dinov2.PATCH, -1).permute(0, 3, 1, 2)
        # The aggregator runs in float32 even under autocast: Sinkhorn's log-sum-exps need it.
        with torch.autocast(device_type=images.device.type, enabled=False):
            return F.normalize(self.aggregator(grid.float(), tokens[:, 0].float()), dim=-1)


def megaloc_from_state(state: dict, where: str) -> MegaLocNet:
    """A MegaLocNet holding ``state`` (either official layout); InputError for any other layout."""
    what = "MegaLoc"
    if any(k.startswith("backbone.model.") for k in state):      # v1.0 release: torch hub wrapper
        state = {("backbone." + k[len("backbone.model."):] if k.startswith("backbone.model.") else k): v
                 for k, v in state.items()}
    arch = dinov2_arch(state, "backbone.", what, where)
    try:
        hidden, channels = state["aggregator.agg.score.0.weight"].shape[:2]
        clusters = state["aggregator.agg.score.3.weight"].shape[0]
        cluster_dim = state["aggregator.agg.cluster_features.3.weight"].shape[0]
        token_dim = state["aggregator.agg.token_features.2.weight"].shape[0]
        out_dim = state["aggregator.linear.weight"].shape[0]
    except (KeyError, AttributeError, ValueError) as exc:
        raise InputError(f"{where}: not a MegaLoc checkpoint ({exc.args[0] if exc.args else exc} is missing)") from None
    with torch.device("meta"):   # shapes only, to check the file against
        probe = MegaLocNet(arch, clusters, cluster_dim, token_dim, hidden, out_dim)
    check_layout(probe, state, what, where, optional=("backbone.mask_token",))
    net = MegaLocNet(arch, clusters, cluster_dim, token_dim, hidden, out_dim)
    net.load_state_dict(state, strict=False)   # only the optional mask_token may be absent (unused)
    return net


class MegaLoc(GlobalNetDescriptor):
    """MegaLoc global descriptor: 8448 numbers per panorama (input 322 x 644 by default)."""

    name = "megaloc"
    title = "MegaLoc"
    hub_files = ("megaloc.torch",)
    hf_files = (("gberton/MegaLoc", "model.safetensors"),)
    download_url = "https://github.com/gmberton/MegaLoc/releases/download/v1.0/megaloc.torch"
    # 322 px high, the panorama whole at 322 x 644 (23 x 46 patches). MegaLoc's code fixes no
    # size (any multiple of 14); 322 is the training size of SALAD, whose aggregator MegaLoc
    # uses, and of BoQ's DINOv2 model. Not verified for MegaLoc's own training.
    default_height = 322

    def build(self, state: dict, where: str) -> MegaLocNet:
        return megaloc_from_state(state, where)
