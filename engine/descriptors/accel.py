"""Device, numeric precision and on-device preprocessing shared by the torch descriptors.

* ``pick_device``: "auto" = CUDA, else Apple MPS, else the CPU.
* ``resolve_precision``: the autocast dtype of a (precision, device) pair. "auto" is bfloat16
  autocast plus TF32 on CUDA (float16 where the GPU has no bfloat16), except for models that
  cluster a map vocabulary from the recording, and plain float32 elsewhere; "float32" forces
  float32 everywhere (TF32 off too); "bfloat16"/"float16" force autocast (on the CPU too: that
  is how the CPU/GPU agreement under bfloat16 is measured on a machine without a GPU).
* ``compute``: the context a forward pass runs in (inference mode, autocast, TF32 flags set and
  restored afterwards, so one model's choice never leaks into another's).
* ``to_network_input``: uint8 RGB frames -> normalised float32 network input on the device,
  resized there (the host only copies bytes), or on the host where the device is the CPU and
  the frame shrinks by whole factors (``shrink_on_host``: the same block means, 9x faster).
* ``standardise``: each image's channels to zero mean and unit spread (effnet-vlad's ``photometric`` option).
"""

from __future__ import annotations

import contextlib
from typing import Iterator, Optional, Sequence

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import InputError

PRECISIONS = ("auto", "float32", "bfloat16", "float16")
FLAT_STD = 1e-3   # spread below which a channel counts as flat (a uniform frame): not divided by
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def pick_device(device: Optional[str] = "auto") -> torch.device:
    """"auto" = CUDA if present, else Apple MPS, else CPU; an explicit device must exist."""
    device = (device or "auto").lower()
    mps = getattr(torch.backends, "mps", None)
    mps_ok = bool(mps is not None and mps.is_available())
    if device == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda")
        return torch.device("mps" if mps_ok else "cpu")
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(f"device '{device}' asked for, but CUDA is not available here")
    if device == "mps" and not mps_ok:
        raise InputError("device 'mps' asked for, but Apple MPS is not available here")
    try:
        return torch.device(device)
    except RuntimeError:
        raise InputError(f"unknown device '{device}' (use auto, cpu, cuda or mps)") from None


def check_precision(precision: Optional[str]) -> str:
    """The precision name, checked (None means "auto")."""
    precision = (precision or "auto").lower()
    if precision not in PRECISIONS:
        raise InputError(f"unknown precision '{precision}' (choose one of {', '.join(PRECISIONS)})")
    return precision


def resolve_precision(precision: Optional[str], device: torch.device,
                      map_vocabulary: bool = False) -> Optional[torch.dtype]:
    """Autocast dtype for ``precision`` on ``device``; None = plain float32 (TF32 off).

    "auto" uses bfloat16 on CUDA because it runs the tensor cores (AnyLoc ViT-G/14 model alone
    255-350 frames/s at 224 x 448 on an H100, issue 15); float16 only where bfloat16 is missing
    (pre-Ampere GPUs). But "auto" stays float32 when the model clusters a map vocabulary from
    the recording (``map_vocabulary``): k-means on bfloat16 features lands in another local
    optimum than on float32 ones, and the descriptors then share almost nothing (effnet-vlad,
    40 synthetic frames, CPU float32 vs bfloat16 autocast: row cosine median 0.12 with
    k-means++, 0.90 even with seeds drawn by index), while float32 features that differ by
    ~1e-6, as a GPU's without TF32 do, give the same centres (cosine > 0.9999999).
    """
    precision = check_precision(precision)
    if precision == "float32":
        return None
    if precision == "auto":
        if device.type != "cuda" or map_vocabulary:
            return None
        return torch.bfloat16 if torch.cuda.is_bf16_supported() else torch.float16
    return torch.bfloat16 if precision == "bfloat16" else torch.float16


@contextlib.contextmanager
def compute(device: torch.device, dtype: Optional[torch.dtype]) -> Iterator[None]:
    """Inference mode and autocast to ``dtype``; on CUDA, TF32 matmuls and convolutions only
    with autocast (``dtype`` not None).

    The global TF32 flags are restored on exit. cuDNN's own TF32 flag defaults to True, which
    made float32 convolutions on CUDA differ from the CPU by ~1e-3 (issue 15): a float32 run
    switches it off.
    """
    tf32 = dtype is not None
    saved = None
    if device.type == "cuda":
        saved = (torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32)
        torch.backends.cuda.matmul.allow_tf32 = bool(tf32)
        torch.backends.cudnn.allow_tf32 = bool(tf32)
    try:
        autocast = (torch.autocast(device_type=device.type, dtype=dtype) if dtype is not None
                    else contextlib.nullcontext())
        with torch.inference_mode(), autocast:
            yield
    finally:
        if saved is not None:
            torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32 = saved


@contextlib.contextmanager
def cpu_threads(most: int) -> Iterator[None]:
    """torch's CPU threads limited to ``most`` (at least 1) inside the block, restored after.

    ``describe`` runs the network beside a reader that decodes in threads of its own; a
    network that also takes every core makes its worker threads wait for cores the decoder
    holds (``engine.prefetch.cores_left``).
    """
    before = torch.get_num_threads()
    torch.set_num_threads(max(1, min(before, int(most))))
    try:
        yield
    finally:
        torch.set_num_threads(before)


def full_precision(device: torch.device):
    """Autocast off inside a ``compute`` block (aggregation stays float32 whatever the model ran in)."""
    return torch.autocast(device_type=device.type, enabled=False)


def check_rgb(rgb, who: str) -> np.ndarray:
    if not isinstance(rgb, np.ndarray) or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"{who}: expected an H x W x 3 RGB image, got shape {getattr(rgb, 'shape', None)}")
    return rgb


def resize(x: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """float (B, 3, h, w) resized to ``size``: box average when shrinking (as OpenCV's
    INTER_AREA, exact for integer factors), bicubic when enlarging (as INTER_CUBIC)."""
    if tuple(x.shape[-2:]) == tuple(size):
        return x
    if x.shape[-2] >= size[0] and x.shape[-1] >= size[1]:
        return F.interpolate(x, size=size, mode="area")
    return F.interpolate(x, size=size, mode="bicubic", align_corners=False)


def shrink_on_host(images: Sequence[np.ndarray], size: tuple[int, int]) -> Optional[np.ndarray]:
    """float32 (B, h, w, 3) block means of uint8 frames of one shape shrunk by whole factors to
    ``size`` (h, w); None when a factor is not a whole number (``resize`` handles those).

    For whole factors OpenCV's INTER_AREA on float32 and torch's "area" both take the plain
    mean of each block, so the network sees the same input to float rounding (1.8e-7 measured)
    on the CPU and on a GPU; on the CPU it is 9x cheaper than torch's pooling of a permuted
    float batch (0.7 against 6.5 ms per 1024x512 frame shrunk to 256x128, one thread, the
    2-core development machine; about a fifth of effnet-vlad's time per frame).
    """
    import cv2

    h, w = images[0].shape[:2]
    if h % size[0] or w % size[1] or h < size[0] or w < size[1]:
        return None
    out = np.empty((len(images), size[0], size[1], 3), np.float32)
    for k, rgb in enumerate(images):
        out[k] = cv2.resize(rgb.astype(np.float32), (size[1], size[0]), interpolation=cv2.INTER_AREA)
    return out


def upload(images: Sequence[np.ndarray], device: torch.device) -> torch.Tensor:
    """uint8 (B, h, w, 3) on ``device`` from frames of one shape.

    On CUDA the frames are stacked straight into page-locked memory: a copy from ordinary
    (pageable) memory waits for the work already queued on the GPU, a page-locked one does not,
    so the host can stack the next batch while the network runs on this one.
    """
    if images[0].dtype != np.uint8:   # not the usual frames: stacked as they are
        return torch.from_numpy(np.stack(images)).to(device)
    shape = (len(images),) + images[0].shape
    pinned = device.type == "cuda"
    raw = torch.empty(shape, dtype=torch.uint8, pin_memory=pinned)
    np.stack(images, out=raw.numpy())
    return raw.to(device, non_blocking=pinned)


def to_network_input(images: Sequence[np.ndarray], size: tuple[int, int], crop: tuple[int, int],
                     device: torch.device, who: str,
                     mean: Sequence[float] = IMAGENET_MEAN, std: Sequence[float] = IMAGENET_STD) -> torch.Tensor:
    """float32 (B, 3, crop_h, crop_w) on ``device``: each uint8 RGB frame resized to ``size``
    (h, w), centre-cropped to ``crop`` (h, w), scaled to [0, 1] and mean/std normalised.

    Only the uint8 bytes cross to the device; frames of one shape are resized as one batch
    (on the host where the device is the CPU and the factors are whole: ``shrink_on_host``).
    Arithmetic is float32 on every device (no autocast), so CPU and GPU inputs agree to ~1e-6.
    """
    for rgb in images:
        check_rgb(rgb, who)
    out = torch.empty((len(images), 3, crop[0], crop[1]), dtype=torch.float32, device=device)
    top = int(round((size[0] - crop[0]) / 2.0))   # centre crop, rounded as torchvision does
    left = int(round((size[1] - crop[1]) / 2.0))
    with full_precision(device):
        start = 0
        while start < len(images):
            stop = start + 1
            while stop < len(images) and images[stop].shape == images[start].shape:
                stop += 1
            shrunk = shrink_on_host(images[start:stop], size) if device.type == "cpu" else None
            if shrunk is not None:
                x = torch.from_numpy(shrunk).permute(0, 3, 1, 2).div_(255.0)
            else:
                x = upload(images[start:stop], device).permute(0, 3, 1, 2).float().div_(255.0)
                x = resize(x, size)
            x = x[:, :, top:top + crop[0], left:left + crop[1]]
            # Per channel with Python floats: a mean/std tensor copied to CUDA would wait for
            # the batches already queued there (a blocking copy synchronises the stream).
            for ch in range(3):
                out[start:stop, ch] = (x[:, ch] - float(mean[ch])) / float(std[ch])
            start = stop
    return out


def standardise(x: torch.Tensor) -> torch.Tensor:
    """Network input (B, 3, h, w) with each image's channels shifted to zero mean and divided
    by their spread (the standard deviation over the image; flat channels, under ``FLAT_STD``,
    are only shifted).

    Why: two visits of a place under another exposure or white balance (an auto-exposing
    camera, a cloud, another time of day) differ by a gain and an offset per channel, to
    first order, and the network's features change with them, where the place does not. The
    mean and spread of each channel are that gain and offset: dividing them out makes the
    input the same. No number is chosen (the floor only keeps a uniform frame finite).
    Measured (fifteenth round, `benchmarks/results/photometric.md`): on the second synthetic
    family, whose laps change exposure and white balance, each frame's best match lies within
    1 m of it in 77 -> 94 % of frames (a block lapped three times) and 30 -> 81 % (a return
    offset by a metre)."""
    mean = x.mean(dim=(2, 3), keepdim=True)
    std = x.std(dim=(2, 3), keepdim=True)
    return (x - mean) / torch.where(std < FLAT_STD, torch.ones_like(std), std)
