"""AnyLoc descriptors on DINOv2 (Keetha et al., RA-L 2023): AnyLoc-VLAD and AnyLoc-GeM.

Per image: resize to ``input_height`` x 2*``input_height`` (a 2:1 panorama stays whole), centre-crop
both sides to multiples of 14, ImageNet mean/std, DINOv2 patch features of one layer and facet
(CLS and register tokens dropped), each L2-normalised. Then

* AnyLoc-VLAD: hard assignment by cosine to ``num_clusters`` centres, residuals to the centre
  summed per cluster, intra-normalised, L2-normalised: ``num_clusters * C`` numbers
  (32 x 1536 = 49,152 for ViT-G/14). Centres come from AnyLoc's released ``c_centers.pt``
  (a domain vocabulary) or from cosine k-means on the recording itself ("map").
* AnyLoc-GeM: generalised mean (p = 3) over the patches, signed root, L2-normalised: C numbers.

Optionally both are projected by PCA (fitted on the recording's own descriptors) to ``pca_dim``.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Iterable, Iterator, Optional

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import InputError
from ..progress import CancelToken, Progress, check, report
from . import dinov2
from .accel import (check_precision, compute, full_precision, pick_device, resolve_precision,
                    to_network_input)
from .base import DescriptorModel, in_batches
from .mapvocab import pool_recording, sample_rows
from .vlad import l2_normalize, vlad
from .vlad_torch import kmeans_on, vlad_batch

# Layer per backbone when the user sets none: the layers AnyLoc's paper compares the ViTs at
# (its ablation over layers picked 31 of 40 for ViT-G, 20 of 24 for ViT-L, 10 of 12 for S and B).
DEFAULT_LAYERS = {"vits14": 10, "vitb14": 10, "vitl14": 20, "vitg14": 31}
# A map vocabulary is clustered from at most this many patch features (a uniform random
# sample of all of them): k-means cost and memory stay bounded on long recordings.
MAX_VOCAB_FEATURES = 100_000
VOCAB_FILE = "c_centers.pt"


# ---------------------------------------------------------------- small helpers

def input_size(input_height: int) -> tuple[int, int]:
    """(height, width) fed to the ViT: H x 2H cropped down to multiples of 14."""
    if input_height < dinov2.PATCH:
        raise InputError(f"input height {input_height} px is below one {dinov2.PATCH} px patch")
    return (input_height // dinov2.PATCH) * dinov2.PATCH, (2 * input_height // dinov2.PATCH) * dinov2.PATCH


def preprocess(rgb: np.ndarray, input_height: int) -> np.ndarray:
    """float32 (3, h, w) network input of one image, on the CPU: resized to H x 2H, centre-cropped
    to multiples of 14, mean/std normalised (``accel.to_network_input``, as ``describe`` does)."""
    x = to_network_input([rgb], (input_height, 2 * input_height), input_size(input_height),
                         torch.device("cpu"), "AnyLoc")
    return x[0].numpy()


def file_identity(path: Path, probe: int = 1 << 20) -> str:
    """Cheap content identity of a (possibly multi-GB) file: name, size, sha1 of head and tail."""
    size = path.stat().st_size
    digest = hashlib.sha1()
    with open(path, "rb") as f:
        digest.update(f.read(probe))
        if size > probe:
            f.seek(max(size - probe, probe))
            digest.update(f.read(probe))
    return f"{path.name}:{size}:{digest.hexdigest()[:12]}"


def anyloc_vlad(features: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """AnyLoc's VLAD of unit ``features`` (N, C): cosine assignment, residuals to the centres as given.

    AnyLoc's released centres are k-means means of unit vectors, shorter than 1; it assigns by
    cosine but subtracts the raw centre. ``vlad`` assigns by dot product with the centres it is
    given, so it gets the unit centres and each feature scaled by 1/|c| of its cluster: the
    argmax is unchanged (a positive factor per row) and f/|c| - c/|c| = (f - c)/|c|, a positive
    factor per cluster that the intra-normalisation removes. Unit centres give plain ``vlad``.
    """
    norms = np.maximum(np.linalg.norm(centers, axis=1), 1e-12).astype(np.float32)
    unit = (centers / norms[:, None]).astype(np.float32)
    if features.shape[0] == 0:
        return vlad(features, unit)
    labels = np.argmax(features @ unit.T, axis=1)
    return vlad(features / norms[labels][:, None], unit)


def gem(features: np.ndarray, p: float) -> np.ndarray:
    """AnyLoc's GeM over rows: m = mean(f^p), then sign(m) |m|^(1/p) (features may be negative).

    For a non-integer p the power of a negative value is taken as sign(f) |f|^p.
    """
    f = features.astype(np.float64)
    powered = np.power(f, p) if float(p).is_integer() else np.sign(f) * np.abs(f) ** p
    m = powered.mean(axis=0)
    return (np.sign(m) * np.abs(m) ** (1.0 / p)).astype(np.float32)


def gem_batch(features: torch.Tensor, p: float) -> torch.Tensor:
    """``gem`` of each image's patches, on the device: (B, N, C) -> float32 (B, C)."""
    with full_precision(features.device):
        f = features.float()
        powered = f.pow(p) if float(p).is_integer() else f.sign() * f.abs().pow(p)
        m = powered.mean(dim=1)
        return m.sign() * m.abs().pow(1.0 / p)


def pca_project(vectors: np.ndarray, dim: int) -> np.ndarray:
    """Rows projected on their own top ``dim`` principal axes (at most n rows), L2-normalised."""
    x = vectors.astype(np.float64)
    x = x - x.mean(axis=0, keepdims=True)
    # Gram-matrix route: n x n eigenproblem, cheap while n (frames) << d (49,152 for ViT-G).
    gram = x @ x.T
    vals, vecs = np.linalg.eigh(gram)
    order = np.argsort(vals)[::-1][:min(dim, x.shape[0])]
    vals, vecs = np.maximum(vals[order], 1e-12), vecs[:, order]
    axes = (x.T @ vecs) / np.sqrt(vals)          # (d, dim) unit principal axes
    return l2_normalize(x @ axes).astype(np.float32)


def resolve_backbone(backbone: Optional[str], weights: Optional[str]) -> dinov2.Arch:
    """The DINOv2 architecture to build: read from the ``weights`` file's tensor shapes when
    ``backbone`` is not given (ViT-G/14 when neither is); a given ``backbone`` must agree with
    the file."""
    if weights is None:
        return dinov2.get_arch(backbone or "vitg14")
    path = Path(weights).expanduser()
    if not path.is_file():
        arch = dinov2.get_arch(backbone or "vitg14")
        raise InputError(f"{path}: no such DINOv2 checkpoint file (expected {arch.checkpoint_name})")
    found = dinov2.checkpoint_arch(path)
    if backbone is not None:
        asked = dinov2.get_arch(backbone)
        if asked != found:
            raise InputError(f"{path.name} holds DINOv2 {found.label}, but --backbone {backbone} asks "
                             f"for {asked.label}: drop --backbone or use --backbone {found.key}")
    return found


# ---------------------------------------------------------------- vocabularies

def vocabulary_root() -> Path:
    """Folder holding AnyLoc's unpacked cache (``<root>/vocabulary/...``).

    ``$PANOTOPO_ANYLOC_CACHE`` if set, else ``<torch hub dir>/anyloc``.
    """
    env = os.environ.get("PANOTOPO_ANYLOC_CACHE")
    return Path(env).expanduser() if env else Path(torch.hub.get_dir()) / "anyloc"


def domain_vocabulary_path(domain: str, backbone: str, layer: int, facet: str, k: int) -> Path:
    """AnyLoc's layout: ``vocabulary/dinov2_vitg14/l31_value_c32/<domain>/c_centers.pt``."""
    arch = dinov2.get_arch(backbone)
    return vocabulary_root() / "vocabulary" / arch.hub_name / f"l{layer}_{facet}_c{k}" / domain / VOCAB_FILE


def save_vocabulary(path: str | os.PathLike, centers: np.ndarray) -> None:
    """Write ``centers`` (k, C) as AnyLoc does: ``torch.save`` of a float32 tensor."""
    torch.save(torch.from_numpy(np.ascontiguousarray(centers, dtype=np.float32)), Path(path))


def load_vocabulary(path: str | os.PathLike, k: Optional[int] = None, dim: Optional[int] = None) -> np.ndarray:
    """Centres (k, C) float32 from an AnyLoc ``c_centers.pt`` (a file, or a folder holding one)."""
    path = Path(path).expanduser()
    if path.is_dir():
        path = path / VOCAB_FILE
    if not path.is_file():
        raise InputError(f"{path}: no such vocabulary file")
    try:
        centers = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # zip/pickle/EOF errors all mean a damaged or foreign file
        raise InputError(f"{path}: cannot read the vocabulary, the file is truncated or not a "
                         f"PyTorch tensor ({exc.__class__.__name__})") from None
    if not isinstance(centers, torch.Tensor) or centers.ndim != 2:
        raise InputError(f"{path}: not a VLAD vocabulary (expected a 2-D tensor of cluster centres)")
    arr = centers.detach().float().numpy()
    if k is not None and arr.shape[0] != k:
        raise InputError(f"{path}: vocabulary has {arr.shape[0]} clusters, expected {k}")
    if dim is not None and arr.shape[1] != dim:
        raise InputError(f"{path}: vocabulary centres have {arr.shape[1]} dimensions, the backbone "
                         f"gives {dim} (a vocabulary for another backbone?)")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{path}: vocabulary contains NaN or infinite values")
    return arr


# ---------------------------------------------------------------- models

class _AnyLocBase(DescriptorModel):
    """DINOv2 patch features, batched, shared by AnyLoc-VLAD and AnyLoc-GeM."""

    def __init__(self, backbone: Optional[str] = None, weights: Optional[str] = None,
                 allow_download: bool = False, layer: Optional[int] = None, facet: str = "value",
                 input_height: int = 224, batch_size: int = 4, device: str = "auto",
                 pca_dim: Optional[int] = None, precision: str = "auto") -> None:
        self.arch = resolve_backbone(backbone, weights)
        self.layer = DEFAULT_LAYERS[self.arch.key.replace("_reg", "")] if layer is None else int(layer)
        if not 0 <= self.layer < self.arch.depth:
            raise InputError(f"{self.arch.label} has layers 0..{self.arch.depth - 1}, not {self.layer}")
        if facet not in dinov2.FACETS:
            raise InputError(f"unknown facet '{facet}' (choose one of {', '.join(dinov2.FACETS)})")
        self.facet = facet
        self.input_height = int(input_height)
        self.size = input_size(self.input_height)
        if int(batch_size) < 1:
            raise InputError(f"batch size must be at least 1, got {batch_size}")
        self.batch_size = int(batch_size)
        if pca_dim is not None and int(pca_dim) < 1:
            raise InputError(f"PCA dimension must be at least 1, got {pca_dim}")
        self.pca_dim = None if pca_dim is None else int(pca_dim)
        self.device = pick_device(device)
        self.precision = check_precision(precision)
        self.dtype = resolve_precision(self.precision, self.device)
        self.allow_download = bool(allow_download)
        # Resolve the checkpoint now (fast, fails early); read it only when describing.
        self.weights_path = dinov2.find_checkpoint(self.arch, weights)
        if self.weights_path is None and not self.allow_download:
            raise InputError(dinov2.missing_weights_message(self.arch))
        self._model: Optional[dinov2.DinoVisionTransformer] = None

    @property
    def dim(self) -> int:
        return self.arch.embed_dim

    def backbone(self) -> dinov2.DinoVisionTransformer:
        """The loaded DINOv2 model (read from disk on first use)."""
        if self._model is None:
            weights = None if self.weights_path is None else str(self.weights_path)
            model = dinov2.load_dinov2(self.arch.key, weights, self.allow_download)
            self._model = model.to(self.device)
        return self._model

    def input_columns(self) -> int:
        return 2 * self.input_height  # resized whole to input_height x 2*input_height, then cropped

    def weights_identity(self) -> str:
        if self.weights_path is None:
            return f"{self.arch.checkpoint_name}:official-download"
        return file_identity(self.weights_path)

    def patch_features(self, images: Iterable[np.ndarray], count: int,
                       progress: Optional[Progress], cancel: Optional[CancelToken],
                       stage: str) -> Iterator[torch.Tensor]:
        """Unit patch features, float32 (B, h*w, C) on the device, ``batch_size`` images at a time."""
        model = self.backbone()
        for batch in in_batches(images, self.batch_size, count, progress, cancel, stage):
            x = to_network_input(batch, (self.input_height, 2 * self.input_height), self.size,
                                 self.device, "AnyLoc")
            with compute(self.device, self.dtype):   # never yield inside: the context would leak
                feats = F.normalize(model.extract(x, self.layer, self.facet).float(), dim=-1)
            yield feats

    def _finish(self, rows: np.ndarray) -> np.ndarray:
        """Optional PCA, then float32 L2-normalised rows."""
        if self.pca_dim is not None and rows.shape[0] > 0 and self.pca_dim < rows.shape[1]:
            rows = pca_project(rows, self.pca_dim)
        return l2_normalize(rows).astype(np.float32)

    def _common_settings(self) -> dict:
        return {"name": self.name, "backbone": self.arch.key, "weights": self.weights_identity(),
                "layer": self.layer, "facet": self.facet, "input_size": list(self.size),
                "pca_dim": self.pca_dim,
                "precision": "float32" if self.dtype is None else str(self.dtype).removeprefix("torch.")}


class AnyLocVLAD(_AnyLocBase):
    """AnyLoc-VLAD-DINOv2: ``num_clusters`` x C dimensional (49,152 for ViT-G/14 and 32 clusters)."""

    name = "anyloc-vlad"
    # The paper's thresholds (METHOD.md): node_sim_th 0.80, loop_sim_th 0.55.
    defaults = {"node_sim_th": 0.80, "loop_sim_th": 0.55}

    def __init__(self, backbone: Optional[str] = None, weights: Optional[str] = None,
                 allow_download: bool = False, layer: Optional[int] = None, facet: str = "value",
                 vocabulary: Optional[str] = "map", num_clusters: int = 32, input_height: int = 224,
                 batch_size: int = 4, device: str = "auto", pca_dim: Optional[int] = None,
                 save_vocabulary: Optional[str] = None, precision: str = "auto") -> None:
        super().__init__(backbone, weights, allow_download, layer, facet, input_height,
                         batch_size, device, pca_dim, precision)
        if int(num_clusters) < 1:
            raise InputError(f"number of clusters must be at least 1, got {num_clusters}")
        self.num_clusters = int(num_clusters)
        self.save_vocabulary_to = save_vocabulary
        self.centers: Optional[np.ndarray] = None
        self.vocabulary_id = "map"
        self._resolve_vocabulary(vocabulary or "map")
        self.dtype = resolve_precision(self.precision, self.device, map_vocabulary=self.centers is None)

    def _resolve_vocabulary(self, vocabulary: str) -> None:
        """Load a vocabulary file, or a domain name from AnyLoc's cache; "map" builds one later."""
        if vocabulary == "map":
            return
        path = Path(vocabulary).expanduser()
        label = path.name
        if not path.exists() and os.sep not in vocabulary and "/" not in vocabulary \
                and not vocabulary.endswith(".pt"):
            path = domain_vocabulary_path(vocabulary, self.arch.key, self.layer, self.facet,
                                          self.num_clusters)
            label = vocabulary
            if not path.is_file():
                raise InputError(
                    f"no '{vocabulary}' vocabulary for {self.arch.hub_name} layer {self.layer} "
                    f"{self.facet} with {self.num_clusters} clusters: expected {path} "
                    f"(unpack AnyLoc's vocabulary cache there, see docs/anyloc.md, or use --vocabulary map)")
        self.centers = load_vocabulary(path, self.num_clusters, self.dim)
        if path.is_dir():
            path = path / VOCAB_FILE
        self.vocabulary_id = f"{label}:{file_identity(path).rsplit(':', 1)[1]}"

    @property
    def output_dim(self) -> int:
        return self.num_clusters * self.dim

    def describe(self, images: Iterable[np.ndarray], count: int,
                 progress: Optional[Progress] = None,
                 cancel: Optional[CancelToken] = None) -> np.ndarray:
        # VLAD runs on the device; a map vocabulary is clustered (float64, CPU or CUDA) from a seeded
        # sample of the first frames' features held on the host (bounded, see mapvocab).
        batches = self.patch_features(images, count, progress, cancel, "AnyLoc: DINOv2 features")

        def build(parts: list[np.ndarray]) -> np.ndarray:
            check(cancel)
            report(progress, 0, 1, "AnyLoc: vocabulary (k-means)")
            centers = kmeans_on(self.device, self._vocabulary_sample(parts), self.num_clusters)
            if self.save_vocabulary_to:
                save_vocabulary(self.save_vocabulary_to, centers)
            report(progress, 1, 1, "AnyLoc: vocabulary (k-means)")
            return centers

        out, self.centers = pool_recording(batches, vlad_batch, self.device, centers=self.centers,
                                           build=build, cancel=cancel)
        if out is None:
            out = np.zeros((0, self.output_dim), np.float32)
        return self._finish(out)

    @staticmethod
    def _vocabulary_sample(kept: list[np.ndarray]) -> np.ndarray:
        if sum(f.size for f in kept) == 0:
            raise InputError("no images to build a map vocabulary from")
        return sample_rows(kept, MAX_VOCAB_FEATURES, seed=0)

    def settings(self) -> dict:
        return {**self._common_settings(), "vocabulary": self.vocabulary_id,
                "num_clusters": self.num_clusters}


class AnyLocGeM(_AnyLocBase):
    """AnyLoc-GeM-DINOv2: GeM (p = 3) over the same patch features; C dimensional."""

    name = "anyloc-gem"
    # Not calibrated on real data yet (see docs/anyloc.md): GeM keeps the component shared by
    # every image, so cosines between unrelated places sit much higher than with VLAD; these
    # keep the paper's "dense nodes, strict loops" intent and should be re-checked with weights.
    defaults = {"node_sim_th": 0.95, "loop_sim_th": 0.85}

    def __init__(self, backbone: Optional[str] = None, weights: Optional[str] = None,
                 allow_download: bool = False, layer: Optional[int] = None, facet: str = "value",
                 input_height: int = 224, batch_size: int = 4, device: str = "auto",
                 pca_dim: Optional[int] = None, gem_p: float = 3.0, vocabulary: Optional[str] = None,
                 num_clusters: Optional[int] = None, precision: str = "auto") -> None:
        # vocabulary / num_clusters are accepted (the CLI passes one option set) and ignored.
        super().__init__(backbone, weights, allow_download, layer, facet, input_height,
                         batch_size, device, pca_dim, precision)
        if float(gem_p) <= 0:
            raise InputError(f"GeM power must be positive, got {gem_p}")
        self.gem_p = float(gem_p)

    def describe(self, images: Iterable[np.ndarray], count: int,
                 progress: Optional[Progress] = None,
                 cancel: Optional[CancelToken] = None) -> np.ndarray:
        rows = [gem_batch(f, self.gem_p).cpu().numpy()
                for f in self.patch_features(images, count, progress, cancel, "AnyLoc-GeM: DINOv2 features")]
        out = np.concatenate(rows) if rows else np.zeros((0, self.dim), np.float32)
        return self._finish(out)

    def settings(self) -> dict:
        return {**self._common_settings(), "gem_p": self.gem_p}
