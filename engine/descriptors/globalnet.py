"""Shared parts of the trained global-descriptor networks (MegaLoc, BoQ): finding and reading
their official weight files, checking a state dict's layout, and describing panoramas.

Each panorama (already shifted) is resized whole to ``input_height`` x 2*``input_height``
(both multiples of 14 for the DINOv2 patch grid), ImageNet mean/std, run through the network
in batches on the device, and its output row L2-normalised.

Weights are found, in order, at ``--weights PATH``, in the torch hub cache
(``$TORCH_HOME/hub/checkpoints/<official file name>``), in the Hugging Face cache where the
model is published there, or downloaded with ``allow_download`` (read with
``weights_only=True``). Nothing is ever downloaded otherwise.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path
from typing import Iterable, Optional, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..errors import InputError
from ..progress import CancelToken, Progress
from . import dinov2
from .accel import check_precision, compute, pick_device, resolve_precision, to_network_input
from .anyloc import file_identity
from .base import DescriptorModel, in_batches


def is_safetensors(path: Path) -> bool:
    """A safetensors file starts with an 8-byte header length and a JSON header ``{``."""
    try:
        with open(path, "rb") as f:
            head = f.read(9)
    except OSError:
        return False
    return len(head) == 9 and head[8:9] == b"{" and struct.unpack("<Q", head[:8])[0] < (1 << 32)


def read_state(path: Path, what: str) -> dict:
    """The plain state dict (name -> tensor) in a ``.safetensors`` or torch file; InputError otherwise."""
    try:
        if is_safetensors(path):
            from safetensors.torch import load_file

            state = load_file(str(path), device="cpu")
        else:
            state = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise InputError(f"{path}: no such {what} weights file") from None
    except (ImportError, ModuleNotFoundError):
        raise InputError(f"{path}: reading .safetensors needs the 'safetensors' package (pip install safetensors)") from None
    except (json.JSONDecodeError, Exception) as exc:  # zip/pickle/EOF/header errors: a damaged file
        raise InputError(f"{path}: cannot read the {what} weights, the file is truncated or not a "
                         f"PyTorch/safetensors checkpoint ({exc.__class__.__name__})") from None
    if isinstance(state, dict) and "state_dict" in state and isinstance(state["state_dict"], dict):
        state = state["state_dict"]     # a training checkpoint wrapping the weights
    if not isinstance(state, dict) or not state or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise InputError(f"{path}: not a {what} checkpoint (not a plain state dict of tensors)")
    return state


def check_layout(model: nn.Module, state: dict, what: str, where: str, optional: Sequence[str] = ()) -> None:
    """InputError naming the first missing, unexpected or wrongly shaped entry, unless ``state``
    has exactly ``model``'s keys and shapes (``optional`` keys may be absent)."""
    problem = dinov2.layout_problem(model, state, tuple(optional))
    if problem is not None:
        raise InputError(f"{where}: not a {what} checkpoint ({problem})")


def dinov2_arch(state: dict, prefix: str, what: str, where: str) -> dinov2.Arch:
    """The DINOv2 backbone stored under ``prefix``, read from its shapes."""
    arch = dinov2.arch_of_state(state, prefix)
    if arch is None:
        raise InputError(f"{where}: not a {what} checkpoint (no DINOv2 backbone under '{prefix}')")
    return arch


def hf_cache_files(repo_id: str, filename: str) -> list[Path]:
    """Copies of ``filename`` of Hugging Face model ``repo_id`` in the local HF hub cache."""
    root = os.environ.get("HF_HUB_CACHE")
    if not root:
        home = os.environ.get("HF_HOME") or str(Path.home() / ".cache" / "huggingface")
        root = str(Path(home) / "hub")
    snapshots = Path(root).expanduser() / f"models--{repo_id.replace('/', '--')}" / "snapshots"
    return sorted(snapshots.glob(f"*/{filename}")) if snapshots.is_dir() else []


class GlobalNetDescriptor(DescriptorModel):
    """A network that maps a batch of images to one global row each (MegaLoc, BoQ).

    Subclasses set ``title``, ``hub_files`` (official file names looked for in the torch hub
    cache), ``download_url``, ``docs`` and implement ``build(state, where) -> nn.Module``.
    """

    title = ""
    hub_files: tuple[str, ...] = ()
    hf_files: tuple[tuple[str, str], ...] = ()   # (repo id, file name) in the HF cache
    download_url = ""
    default_height = 322
    # No calibrated thresholds yet (no real weights here): the map calibrates them from the
    # recording (method "verified" does so by default; see docs/megaloc_boq.md).
    defaults: dict = {}

    def __init__(self, weights: Optional[str] = None, allow_download: bool = False,
                 input_height: Optional[int] = None, batch_size: int = 4, device: str = "auto",
                 precision: str = "auto", **others) -> None:
        # The CLI has one option set for every descriptor: an option of another one (backbone,
        # layer, vocabulary...) would silently change nothing here, so it is refused.
        bad = sorted(k for k, v in others.items() if v is not None)
        if bad:
            raise InputError(f"{self.name} has no option '{bad[0]}' (its network is fixed by its weights)")
        height = self.default_height if input_height is None else int(input_height)
        if height < 2 * dinov2.PATCH:
            raise InputError(f"{self.name}: input height {height} px is too small (at least {2 * dinov2.PATCH})")
        self.size = (height // dinov2.PATCH * dinov2.PATCH, 2 * height // dinov2.PATCH * dinov2.PATCH)
        if int(batch_size) < 1:
            raise InputError(f"batch size must be at least 1, got {batch_size}")
        self.batch_size = int(batch_size)
        self.device = pick_device(device)
        self.precision = check_precision(precision)
        self.dtype = resolve_precision(self.precision, self.device)
        self.allow_download = bool(allow_download)
        self.weights_path = self.find_weights(weights)
        if self.weights_path is None and not self.allow_download:
            raise InputError(self.missing_message())
        self._net: Optional[nn.Module] = None

    # -- weights ------------------------------------------------------------------------
    def find_weights(self, weights: Optional[str]) -> Optional[Path]:
        if weights is not None:
            path = Path(weights).expanduser()
            if not path.is_file():
                raise InputError(f"{path}: no such {self.title} weights file (expected {self.hub_files[0]})")
            return path
        for name in self.hub_files:
            cached = dinov2.hub_checkpoint_dir() / name
            if cached.is_file():
                return cached
        for repo, name in self.hf_files:
            found = hf_cache_files(repo, name)
            if found:
                return found[-1]
        return None

    def missing_message(self) -> str:
        return (f"{self.title} weights not found: put {self.hub_files[0]} in {dinov2.hub_checkpoint_dir()} "
                f"or pass --weights FILE (see {self.docs})")

    docs = "docs/megaloc_boq.md"

    def read_weights(self) -> tuple[dict, str]:
        if self.weights_path is not None:
            return read_state(self.weights_path, self.title), self.weights_path.name
        try:
            state = torch.hub.load_state_dict_from_url(self.download_url, map_location="cpu",
                                                       file_name=self.hub_files[0], weights_only=True)
        except Exception as exc:
            raise InputError(f"cannot download {self.hub_files[0]} ({exc.__class__.__name__}): "
                             f"{self.missing_message()}") from None
        return state, self.hub_files[0]

    def build(self, state: dict, where: str) -> nn.Module:
        raise NotImplementedError

    def network(self) -> nn.Module:
        """The network with its weights, on the device (read on first use)."""
        if self._net is None:
            state, where = self.read_weights()
            self._net = self.build(state, where).eval().to(self.device)
        return self._net

    def weights_identity(self) -> str:
        if self.weights_path is None:
            return f"{self.hub_files[0]}:official-download"
        return file_identity(self.weights_path)

    # -- description ----------------------------------------------------------------------
    def describe(self, images: Iterable[np.ndarray], count: int,
                 progress: Optional[Progress] = None,
                 cancel: Optional[CancelToken] = None) -> np.ndarray:
        net = self.network()
        rows: list[np.ndarray] = []
        for batch in in_batches(images, self.batch_size, count, progress, cancel, self.name):
            x = to_network_input(batch, self.size, self.size, self.device, self.name)
            with compute(self.device, self.dtype):
                rows.append(F.normalize(net(x).float(), dim=-1).cpu().numpy())
        if not rows:
            return np.zeros((0, self.output_dim()), np.float32)
        return np.concatenate(rows).astype(np.float32)

    def output_dim(self) -> int:
        return int(self.network().output_dim)

    def input_columns(self) -> int:
        return int(self.size[1])

    def settings(self) -> dict:
        return {"name": self.name, "weights": self.weights_identity(), "input_size": list(self.size),
                "precision": "float32" if self.dtype is None else str(self.dtype).removeprefix("torch.")}
