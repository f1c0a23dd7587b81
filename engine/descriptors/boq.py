"""Bag-of-Queries (Ali-bey et al., CVPR 2024; github amaralibey/Bag-of-Queries, MIT), its DINOv2
variant: DINOv2 ViT-B/14 and two BoQ blocks, 12,288 numbers per image.

Written for panotopo from the published architecture; names and shapes follow the official
``dinov2_12288.pth`` (GitHub release v1.0) so it loads unchanged:

* ``backbone.dino.*``: torch hub's DINOv2 ViT-B/14 (``mask_token`` and the final ``norm``
  included; the norm is not applied, as in the official forward).
* ``aggregator.proj_c`` (3x3 conv 768 -> 384), ``aggregator.norm_input``,
  ``aggregator.boqs.{0,1}.{encoder (a post-norm transformer encoder layer, ReLU, 4x width),
  queries (1, 64, 384), self_attn, norm_q, cross_attn, norm_out}``, ``aggregator.fc``
  (2 x 64 query outputs -> 32 per channel).

Forward: every DINOv2 block, CLS dropped, the patch map through ``proj_c`` and a LayerNorm;
each block refines the patch tokens (encoder layer) and its learned queries (self-attention,
norm) read them by cross-attention (norm); the 2 x 64 query outputs are mixed per channel by
``fc`` into 32: 384 x 32 = 12,288 numbers (channel-major), L2-normalised. Heads: 64 channels
each (6 for 384). Sizes are read from the file, so small test models load too.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..errors import InputError
from . import dinov2
from .globalnet import GlobalNetDescriptor, check_layout, dinov2_arch

HEAD_CHANNELS = 64   # the official model uses proj_channels // 64 attention heads


class QueryBlock(nn.Module):
    def __init__(self, dim: int, queries: int):
        super().__init__()
        heads = max(1, dim // HEAD_CHANNELS)
        self.encoder = nn.TransformerEncoderLayer(d_model=dim, nhead=heads, dim_feedforward=4 * dim,
                                                  dropout=0.0, batch_first=True)
        self.queries = nn.Parameter(torch.zeros(1, queries, dim))
        self.self_attn = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.norm_q = nn.LayerNorm(dim)
        self.cross_attn = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.norm_out = nn.LayerNorm(dim)

    def forward(self, tokens: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(refined tokens, query outputs (B, queries, dim))."""
        tokens = self.encoder(tokens)
        q = self.queries.expand(tokens.shape[0], -1, -1)
        # The queries do not depend on the image; kept as computed so the weights load as they are.
        q = self.norm_q(q + self.self_attn(q, q, q, need_weights=False)[0])
        out = self.cross_attn(q, tokens, tokens, need_weights=False)[0]
        return tokens, self.norm_out(out)


class BoQAggregator(nn.Module):
    def __init__(self, channels: int, proj: int, queries: int, layers: int, row_dim: int):
        super().__init__()
        self.proj_c = nn.Conv2d(channels, proj, kernel_size=3, padding=1)
        self.norm_input = nn.LayerNorm(proj)
        self.boqs = nn.ModuleList(QueryBlock(proj, queries) for _ in range(layers))
        self.fc = nn.Linear(layers * queries, row_dim)

    def forward(self, patches: torch.Tensor) -> torch.Tensor:
        """(B, C, h, w) -> (B, proj * row_dim), L2-normalised."""
        x = self.norm_input(self.proj_c(patches).flatten(2).transpose(1, 2))
        outs = []
        for block in self.boqs:
            x, out = block(x)
            outs.append(out)
        mixed = self.fc(torch.cat(outs, dim=1).transpose(1, 2))            # (B, proj, row_dim)
        return F.normalize(mixed.flatten(1), dim=-1)


class BoQBackbone(nn.Module):
    """``dino``: the DINOv2 model; forward = all blocks, no final norm, patch map (B, C, h, w)."""

    def __init__(self, arch: dinov2.Arch):
        super().__init__()
        self.dino = dinov2.DinoVisionTransformer(arch)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        b, _, h, w = images.shape
        x = self.dino.prepare_tokens(images)
        for block in self.dino.blocks:
            x = block(x)
        x = x[:, self.dino.num_prefix_tokens:]
        return x.transpose(1, 2).reshape(b, -1, h // dinov2.PATCH, w // dinov2.PATCH)


class BoQNet(nn.Module):
    def __init__(self, arch: dinov2.Arch, proj: int = 384, queries: int = 64, layers: int = 2, row_dim: int = 32):
        super().__init__()
        self.backbone = BoQBackbone(arch)
        self.aggregator = BoQAggregator(arch.embed_dim, proj, queries, layers, row_dim)
        self.output_dim = proj * row_dim

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.aggregator(self.backbone(images))


def boq_from_state(state: dict, where: str) -> BoQNet:
    """A BoQNet holding ``state`` (the official DINOv2 BoQ layout); InputError for any other."""
    what = "BoQ (DINOv2)"
    arch = dinov2_arch(state, "backbone.dino.", what, where)
    try:
        proj = state["aggregator.proj_c.weight"].shape[0]
        layers = 1 + max(int(k.split(".")[2]) for k in state if k.startswith("aggregator.boqs."))
        queries = state["aggregator.boqs.0.queries"].shape[1]
        row_dim = state["aggregator.fc.weight"].shape[0]
    except (KeyError, AttributeError, ValueError, IndexError) as exc:
        raise InputError(f"{where}: not a {what} checkpoint ({exc.args[0] if exc.args else exc} is missing)") from None
    with torch.device("meta"):
        probe = BoQNet(arch, proj, queries, layers, row_dim)
    check_layout(probe, state, what, where)
    net = BoQNet(arch, proj, queries, layers, row_dim)
    net.load_state_dict(state, strict=True)
    return net


class BoQ(GlobalNetDescriptor):
    """BoQ-DINOv2 global descriptor: 12,288 numbers per panorama (input 322 x 644 by default)."""

    name = "boq"
    title = "BoQ (DINOv2)"
    hub_files = ("dinov2_12288.pth",)
    download_url = "https://github.com/amaralibey/Bag-of-Queries/releases/download/v1.0/dinov2_12288.pth"
    # 322 px: BoQ's README feeds its DINOv2 model 322 x 322 images; a 2:1 panorama goes in whole
    # at 322 x 644 (23 x 46 patches).
    default_height = 322

    def build(self, state: dict, where: str) -> BoQNet:
        return boq_from_state(state, where)
