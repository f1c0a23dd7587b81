"""DINOv2 vision transformers in plain PyTorch, loadable from the official checkpoints.

Module names and parameter shapes follow the published ``dinov2_vit{s,b,l,g}14[_reg4]_pretrain.pth``
state dicts exactly (``patch_embed.proj``, ``cls_token``, ``pos_embed`` for 518 px = 37 x 37
patches + 1, ``register_tokens`` for the _reg variants, ``mask_token``, ``blocks.N.{norm1,
attn.qkv, attn.proj, ls1.gamma, norm2, mlp.*, ls2.gamma}``, ``norm``), so a checkpoint loads with
``strict=True``. Inference only: no dropout, no drop-path, no masking.

``extract(images, layer, facet)`` returns the patch features AnyLoc uses: the output of block
``layer`` ("token") or one third of that block's fused qkv projection ("query", "key", "value"),
with the CLS and register tokens removed. Blocks after ``layer`` are never run.

Checkpoint files are found (in this order) at the path the user gives, in the torch hub cache
(``torch.hub.get_dir()/checkpoints/``), or downloaded by torch hub when explicitly allowed.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import torch
import torch.nn.functional as F
from torch import nn

from ..errors import InputError

PATCH = 14
# The checkpoints' positional embeddings are for 518 x 518 px images (37 x 37 patches).
PRETRAIN_GRID = 37
FACETS = ("query", "key", "value", "token")
# Where torch hub downloads the official checkpoints from (only used with allow_download).
OFFICIAL_URL = "https://dl.fbaipublicfiles.com/dinov2"


@dataclass(frozen=True)
class Arch:
    """One DINOv2 backbone: the numbers that fix its state-dict shapes."""

    key: str            # "vits14", "vitb14_reg", ...
    title: str          # "ViT-S/14"
    embed_dim: int
    depth: int
    num_heads: int
    ffn: str            # "mlp" or "swiglu"
    registers: int      # 0, or 4 for the _reg variants

    @property
    def hub_name(self) -> str:
        """Torch hub model name: ``dinov2_vits14`` / ``dinov2_vits14_reg``."""
        return f"dinov2_{self.key}"

    @property
    def checkpoint_name(self) -> str:
        """Official file name: ``dinov2_vits14_pretrain.pth`` / ``dinov2_vits14_reg4_pretrain.pth``."""
        base = self.key.replace("_reg", "")
        reg = f"_reg{self.registers}" if self.registers else ""
        return f"dinov2_{base}{reg}_pretrain.pth"

    @property
    def url(self) -> str:
        base = self.key.replace("_reg", "")
        return f"{OFFICIAL_URL}/dinov2_{base}/{self.checkpoint_name}"

    @property
    def label(self) -> str:
        return self.title + (" with registers" if self.registers else "")

    @property
    def hidden_dim(self) -> int:
        """FFN hidden size: 4 x width for the MLP; SwiGLU keeps 2/3 of that, rounded up to 8."""
        hidden = 4 * self.embed_dim
        if self.ffn == "swiglu":
            hidden = (int(hidden * 2 / 3) + 7) // 8 * 8
        return hidden


def _arch_table() -> dict[str, Arch]:
    base = {
        "vits14": ("ViT-S/14", 384, 12, 6, "mlp"),
        "vitb14": ("ViT-B/14", 768, 12, 12, "mlp"),
        "vitl14": ("ViT-L/14", 1024, 24, 16, "mlp"),
        "vitg14": ("ViT-G/14", 1536, 40, 24, "swiglu"),
    }
    table = {}
    for key, (title, dim, depth, heads, ffn) in base.items():
        table[key] = Arch(key, title, dim, depth, heads, ffn, 0)
        table[key + "_reg"] = Arch(key + "_reg", title, dim, depth, heads, ffn, 4)
    return table


ARCHS: dict[str, Arch] = _arch_table()


def get_arch(backbone: str) -> Arch:
    name = backbone.strip().lower().removeprefix("dinov2_").replace("_reg4", "_reg")
    if name not in ARCHS:
        raise InputError(f"unknown DINOv2 backbone '{backbone}' (choose one of {', '.join(ARCHS)})")
    return ARCHS[name]


# ---------------------------------------------------------------- layers

class PatchEmbed(nn.Module):
    def __init__(self, dim: int):
        super().__init__()
        self.proj = nn.Conv2d(3, dim, kernel_size=PATCH, stride=PATCH)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.proj(x).flatten(2).transpose(1, 2)   # (B, h*w, D), row-major patches


class LayerScale(nn.Module):
    def __init__(self, dim: int):
        super().__init__()
        self.gamma = nn.Parameter(torch.ones(dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.gamma


class Attention(nn.Module):
    def __init__(self, dim: int, num_heads: int):
        super().__init__()
        self.num_heads = num_heads
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, n, d = x.shape
        # The fused output is [q | k | v], each split into heads: (3, B, heads, N, d/heads).
        qkv = self.qkv(x).reshape(b, n, 3, self.num_heads, d // self.num_heads).permute(2, 0, 3, 1, 4)
        out = F.scaled_dot_product_attention(qkv[0], qkv[1], qkv[2])
        return self.proj(out.transpose(1, 2).reshape(b, n, d))


class Mlp(nn.Module):
    def __init__(self, dim: int, hidden: int):
        super().__init__()
        self.fc1 = nn.Linear(dim, hidden)
        self.fc2 = nn.Linear(hidden, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.fc2(F.gelu(self.fc1(x)))


class SwiGLU(nn.Module):
    """The ViT-G feed-forward: one fused projection to [x1 | x2], silu(x1) * x2, back to dim."""

    def __init__(self, dim: int, hidden: int):
        super().__init__()
        self.w12 = nn.Linear(dim, 2 * hidden)
        self.w3 = nn.Linear(hidden, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x1, x2 = self.w12(x).chunk(2, dim=-1)
        return self.w3(F.silu(x1) * x2)


class Block(nn.Module):
    def __init__(self, arch: Arch):
        super().__init__()
        dim = arch.embed_dim
        self.norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.attn = Attention(dim, arch.num_heads)
        self.ls1 = LayerScale(dim)
        self.norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.mlp = SwiGLU(dim, arch.hidden_dim) if arch.ffn == "swiglu" else Mlp(dim, arch.hidden_dim)
        self.ls2 = LayerScale(dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x + self.ls1(self.attn(self.norm1(x)))
        return x + self.ls2(self.mlp(self.norm2(x)))


# ---------------------------------------------------------------- the model

class DinoVisionTransformer(nn.Module):
    def __init__(self, arch: Arch):
        super().__init__()
        self.arch = arch
        dim = arch.embed_dim
        self.patch_embed = PatchEmbed(dim)
        self.cls_token = nn.Parameter(torch.zeros(1, 1, dim))
        self.pos_embed = nn.Parameter(torch.zeros(1, PRETRAIN_GRID * PRETRAIN_GRID + 1, dim))
        if arch.registers:
            self.register_tokens = nn.Parameter(torch.zeros(1, arch.registers, dim))
        # Unused at inference (masked-image training only) but part of the official state dict.
        self.mask_token = nn.Parameter(torch.zeros(1, dim))
        self.blocks = nn.ModuleList(Block(arch) for _ in range(arch.depth))
        self.norm = nn.LayerNorm(dim, eps=1e-6)
        # The official hub models differ here: _reg models interpolate with antialiasing and
        # an explicit output size, the others with a +0.1 offset in the scale factor.
        self.interpolate_antialias = bool(arch.registers)
        self.interpolate_offset = 0.0 if arch.registers else 0.1
        self._pos_cache: Optional[tuple] = None   # (key, embedding): see interpolate_pos_encoding

    @property
    def num_prefix_tokens(self) -> int:
        """CLS + register tokens that precede the patch tokens."""
        return 1 + self.arch.registers

    def interpolate_pos_encoding(self, rows: int, cols: int) -> torch.Tensor:
        """Positional embedding (1, 1 + rows*cols, D) for a rows x cols patch grid (bicubic).

        Kept for the last grid while inference mode is on: every frame of a recording has the
        same grid, and the bicubic resize of ViT-G/14's 1536 channels was 9 % of a batch's GPU
        time (H200 profile, issue 15). The key holds the embedding's version counter, so weights
        changed in place are never served stale.
        """
        n = self.pos_embed.shape[1] - 1
        if rows == cols == PRETRAIN_GRID:
            return self.pos_embed
        key = (rows, cols, str(self.pos_embed.device), self.pos_embed.dtype, self.pos_embed._version)
        cacheable = torch.is_inference_mode_enabled()
        if cacheable and self._pos_cache is not None and self._pos_cache[0] == key:
            return self._pos_cache[1]
        with torch.autocast(self.pos_embed.device.type, enabled=False):   # float32 whatever the caller runs in
            out = self._interpolated_pos(rows, cols, n)
        if cacheable:
            self._pos_cache = (key, out)
        return out

    def _interpolated_pos(self, rows: int, cols: int, n: int) -> torch.Tensor:
        m = int(math.sqrt(n))
        pos = self.pos_embed.float()
        grid = pos[:, 1:].reshape(1, m, m, -1).permute(0, 3, 1, 2)
        if self.interpolate_offset:
            scale = ((rows + self.interpolate_offset) / m, (cols + self.interpolate_offset) / m)
            grid = F.interpolate(grid, scale_factor=scale, mode="bicubic",
                                 antialias=self.interpolate_antialias)
        else:
            grid = F.interpolate(grid, size=(rows, cols), mode="bicubic",
                                 antialias=self.interpolate_antialias)
        grid = grid.permute(0, 2, 3, 1).reshape(1, rows * cols, -1)
        return torch.cat([pos[:, :1], grid], dim=1).to(self.pos_embed.dtype)

    def prepare_tokens(self, images: torch.Tensor) -> torch.Tensor:
        """[CLS, registers..., patches...] with positional embedding (registers get none)."""
        _, _, h, w = images.shape
        if h % PATCH or w % PATCH:
            raise InputError(f"DINOv2 input {w}x{h} px: both sides must be multiples of {PATCH}")
        x = self.patch_embed(images)
        x = torch.cat([self.cls_token.expand(x.shape[0], -1, -1), x], dim=1)
        x = x + self.interpolate_pos_encoding(h // PATCH, w // PATCH)
        if self.arch.registers:
            x = torch.cat([x[:, :1], self.register_tokens.expand(x.shape[0], -1, -1), x[:, 1:]], dim=1)
        return x

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """All tokens after the last block and the final norm: (B, prefix + patches, D)."""
        x = self.prepare_tokens(images)
        for block in self.blocks:
            x = block(x)
        return self.norm(x)

    def extract(self, images: torch.Tensor, layer: int, facet: str = "value") -> torch.Tensor:
        """Patch features (B, h*w, D) of block ``layer`` for ``facet``; CLS and registers dropped.

        "query"/"key"/"value" are the thirds of ``blocks[layer].attn.qkv``'s output (all heads,
        head-major, as AnyLoc's hook on that module sees it); "token" is the block's output.
        """
        if not 0 <= layer < self.arch.depth:
            raise InputError(f"{self.arch.label} has layers 0..{self.arch.depth - 1}, not {layer}")
        if facet not in FACETS:
            raise InputError(f"unknown facet '{facet}' (choose one of {', '.join(FACETS)})")
        x = self.prepare_tokens(images)
        for block in self.blocks[:layer]:
            x = block(x)
        block = self.blocks[layer]
        if facet == "token":
            out = block(x)
        else:
            qkv = block.attn.qkv(block.norm1(x))
            d = self.arch.embed_dim
            part = FACETS.index(facet)
            out = qkv[..., part * d:(part + 1) * d]
        return out[:, self.num_prefix_tokens:]


# ---------------------------------------------------------------- checkpoints

def hub_checkpoint_dir() -> Path:
    """Where torch hub keeps downloaded checkpoints (honours TORCH_HOME)."""
    return Path(torch.hub.get_dir()) / "checkpoints"


def find_checkpoint(arch: Arch, weights: Optional[str | os.PathLike] = None) -> Optional[Path]:
    """The checkpoint to use: the user's path (must exist) or the hub cache copy; None if neither."""
    if weights is not None:
        path = Path(weights).expanduser()
        if not path.is_file():
            raise InputError(f"{path}: no such DINOv2 checkpoint file (expected {arch.checkpoint_name})")
        return path
    cached = hub_checkpoint_dir() / arch.checkpoint_name
    return cached if cached.is_file() else None


def missing_weights_message(arch: Arch) -> str:
    return (f"DINOv2 {arch.label} weights not found: put {arch.checkpoint_name} in "
            f"{hub_checkpoint_dir()} or pass --weights FILE (see docs/anyloc.md)")


def arch_of_state(state: dict, prefix: str = "") -> Optional[Arch]:
    """The architecture of the DINOv2 weights under ``prefix`` in ``state``, read from tensor
    shapes: a known backbone when width, depth and registers match one, else a custom one
    (64 channels per head, as every DINOv2 size has; used for tiny test models). None if the
    entries are not a DINOv2 layout."""
    sub = {k[len(prefix):]: v for k, v in state.items() if k.startswith(prefix)}
    sizes = _sizes(sub)
    if sizes is None or sizes[0] % 64:
        return None
    known = _guess_arch(sub)
    if known is not None:
        return known
    dim, depth, regs = sizes
    ffn = "swiglu" if "blocks.0.mlp.w12.weight" in sub else "mlp"
    return Arch(f"custom{dim}x{depth}", f"ViT-{dim}x{depth}/14", dim, depth, dim // 64, ffn, regs)


def _sizes(state: dict) -> Optional[tuple[int, int, int]]:
    """(width, depth, register tokens) of a DINOv2 state dict, or None if it is not one."""
    try:
        dim = int(state["cls_token"].shape[-1])
        depth = 1 + max(int(k.split(".")[1]) for k in state if k.startswith("blocks."))
    except (KeyError, ValueError, IndexError, AttributeError, TypeError):
        return None
    regs = int(state["register_tokens"].shape[1]) if "register_tokens" in state else 0
    return dim, depth, regs


def _guess_arch(state: dict) -> Optional[Arch]:
    """The architecture a state dict looks like (by width, depth and registers), if any."""
    sizes = _sizes(state)
    for arch in ARCHS.values():
        if (arch.embed_dim, arch.depth, arch.registers) == sizes:
            return arch
    return None


def layout_problem(model: nn.Module, state: dict, optional: tuple[str, ...] = ()) -> Optional[str]:
    """The first missing, wrongly shaped or unexpected entry of ``state`` against ``model``'s
    state dict ("X is missing", "X has shape ..., expected ..."), or None if they match.
    ``optional`` keys may be absent."""
    expected = {k: tuple(v.shape) for k, v in model.state_dict().items()}
    for key, shape in expected.items():
        if key not in state:
            if key in optional:
                continue
            return f"{key} is missing"
        got = tuple(getattr(state[key], "shape", ()))
        if got != shape:
            return f"{key} has shape {got}, expected {shape}"
    extra = sorted(set(state) - set(expected))
    return f"unexpected entry {extra[0]}" if extra else None


def check_state_dict(model: DinoVisionTransformer, state: dict, where: str) -> None:
    """Raise InputError naming the expected architecture unless keys and shapes match exactly."""
    arch = model.arch
    problem = layout_problem(model, state)
    if problem is None:
        return
    guess = _guess_arch(state)
    hint = f"; it looks like {guess.label}: use --backbone {guess.key}" if guess and guess != arch else ""
    raise InputError(f"{where}: not a DINOv2 {arch.label} checkpoint ({problem}){hint}")


def checkpoint_arch(path: str | os.PathLike) -> Arch:
    """The DINOv2 backbone a checkpoint holds, from its tensor shapes alone: width
    (``cls_token``), depth (highest ``blocks.N``) and register tokens. The file is memory-mapped,
    so even ViT-G/14's 4.5 GB are not read. InputError if it matches no known backbone."""
    path = Path(path).expanduser()
    try:
        try:
            state = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
        except RuntimeError:   # the legacy (pre-zip) format cannot be memory-mapped
            state = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise InputError(f"{path}: no such DINOv2 checkpoint file") from None
    except Exception as exc:
        raise InputError(f"{path}: cannot read the DINOv2 checkpoint, the file is truncated or not "
                         f"a PyTorch checkpoint ({exc.__class__.__name__})") from None
    arch = _guess_arch(state) if isinstance(state, dict) else None
    if arch is None:
        raise InputError(f"{path}: not a DINOv2 checkpoint of a known backbone (ViT-S/B/L/G/14, "
                         f"with or without registers); cannot tell its backbone from its tensors")
    return arch


def read_checkpoint(path: Path, arch: Arch) -> dict:
    """The state dict in ``path``; InputError for a truncated or foreign file."""
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file (expected {arch.checkpoint_name})") from None
    except Exception as exc:  # zip, pickle and EOF errors all mean a damaged file
        raise InputError(f"{path}: cannot read the DINOv2 {arch.label} checkpoint, the file is "
                         f"truncated or not a PyTorch checkpoint ({exc.__class__.__name__})") from None
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputError(f"{path}: not a DINOv2 {arch.label} checkpoint (not a plain state dict)")
    return state


def load_dinov2(backbone: str, weights: Optional[str | os.PathLike] = None,
                allow_download: bool = False) -> DinoVisionTransformer:
    """The DINOv2 ``backbone`` with its official weights, in eval mode on the CPU.

    Order: ``weights`` (a path), the torch hub cache, a torch hub download when
    ``allow_download``; otherwise InputError saying where to put the file.
    """
    arch = get_arch(backbone)
    path = find_checkpoint(arch, weights)
    model = DinoVisionTransformer(arch)
    if path is None:
        if not allow_download:
            raise InputError(missing_weights_message(arch))
        try:
            # weights_only: a downloaded file is data, never code (issue 16, finding 8).
            state = torch.hub.load_state_dict_from_url(arch.url, map_location="cpu",
                                                       file_name=arch.checkpoint_name, weights_only=True)
        except Exception as exc:
            raise InputError(f"cannot download {arch.checkpoint_name} ({exc.__class__.__name__}): "
                             f"{missing_weights_message(arch)}") from None
        where = arch.checkpoint_name
    else:
        state = read_checkpoint(path, arch)
        where = path.name
    check_state_dict(model, state, where)
    model.load_state_dict(state, strict=True)
    return model.eval()


def random_dinov2(backbone: str, seed: int = 0) -> DinoVisionTransformer:
    """A randomly initialised backbone (tests and speed benchmarks; never for real maps)."""
    arch = get_arch(backbone)
    gen = torch.Generator().manual_seed(seed)
    model = DinoVisionTransformer(arch)
    with torch.no_grad():
        for name, p in model.named_parameters():
            if name.endswith("gamma"):
                p.fill_(1.0)
            elif p.ndim == 1 and "norm" in name and name.endswith("weight"):
                p.fill_(1.0)
            else:
                p.copy_(torch.randn(p.shape, generator=gen) * 0.02)
    return model.eval()
