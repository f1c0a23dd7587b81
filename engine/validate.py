"""Checks of values that come from users and files: one clear line for each bad one.

Used by the CLI (arguments), the session loader (fields of a session file), the
pipeline (map parameters, descriptor options) and the readers (frame sizes). Each check
raises ``InputError`` naming the field or argument; the limits come from ``engine.limits``.
"""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path
from typing import Any, Optional

from . import limits
from .descriptors import efficientnet as effnet   # the model declares its choices (numpy only, no torch)
from .errors import InputError


# --- numbers ----------------------------------------------------------------------------

def number(value: Any, name: str, lo: Optional[float] = None, hi: Optional[float] = None,
           above: Optional[float] = None) -> float:
    """``value`` as a finite float within [lo, hi] (and > ``above``); else InputError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise InputError(f"{name}: expected a number, got {value!r}") from None
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"{name}: expected a finite number, got {value}")
    if above is not None and not value > above:
        raise InputError(f"{name}: must be above {above:g}, got {value:g}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        span = f"between {lo:g} and {hi:g}" if lo is not None and hi is not None else \
            (f"at least {lo:g}" if lo is not None else f"at most {hi:g}")
        raise InputError(f"{name}: must be {span}, got {value:g}")
    return value


def integer(value: Any, name: str, lo: Optional[int] = None, hi: Optional[int] = None) -> int:
    """``value`` as an int within [lo, hi] (a float with a fraction is refused)."""
    if isinstance(value, bool):
        raise InputError(f"{name}: expected an integer, got {value!r}")
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, int):
        try:
            value = int(str(value), 10)
        except (TypeError, ValueError):
            raise InputError(f"{name}: expected an integer, got {value!r}") from None
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        span = f"between {lo:,} and {hi:,}" if lo is not None and hi is not None else \
            (f"at least {lo:,}" if lo is not None else f"at most {hi:,}")
        raise InputError(f"{name}: must be {span}, got {value:,}")
    return value


def interval(value: Any, name: str = "--interval") -> float:
    """A sampling interval: 0 (every frame) or within the limits (seconds)."""
    v = number(value, name, lo=0.0, hi=limits.MAX_INTERVAL_S)
    if 0.0 < v < limits.MIN_INTERVAL_S:
        raise InputError(f"{name}: must be 0 (every frame) or at least {limits.MIN_INTERVAL_S} s, got {v:g}")
    return v


def cosine(value: Any, name: str) -> float:
    """A cosine-similarity threshold: finite and within [-1, 1]."""
    return number(value, name, lo=limits.MIN_COSINE, hi=limits.MAX_COSINE)


def map_params(params, name=lambda key: key) -> None:
    """Every field of a ``MapParams`` against its declared type and range
    (``engine.params.PARAMETERS``; None thresholds = the descriptor's defaults);
    ``name(field)`` is how a message names the field (an argument, a session field)."""
    problems = params.problems()
    if problems:
        key, what = problems[0]
        raise InputError(f"{name(key)}: {what}")


def dense_nodes(count: int, method: str) -> None:
    """Refuse, before allocating, a map whose (nodes x nodes) matrices would not fit."""
    if count > limits.MAX_DENSE_NODES:
        need = 5 * 4 * count * count / 2**30
        raise InputError(f"{count:,} nodes are too many for method '{method}' (it holds several "
                         f"{count:,} x {count:,} matrices, about {need:,.0f} GiB; limit "
                         f"{limits.MAX_DENSE_NODES:,} nodes): use --method ours or simple, a larger "
                         f"--interval or a higher --node-sim-th")


def poses_cover(poses, stamps, where: str = "poses") -> None:
    """Refuse ground truth that cannot place the map's nodes: fewer than two poses, or a
    time span that covers less than ``limits.MIN_POSES_COVERAGE`` of the node stamps (the
    positions of the others would be clamped to the ends: meaningless metrics; usually the
    poses are on another clock than the recording)."""
    import numpy as np

    if len(poses) < 2:
        raise InputError(f"{where}: {len(poses)} pose(s); at least two are needed to place the map's nodes")
    stamps = np.asarray(stamps, dtype=np.float64)
    if stamps.size == 0:
        return
    t0, t1 = float(poses.t[0]), float(poses.t[-1])
    slack = (t1 - t0) / max(len(poses) - 1, 1)   # one pose period at either end
    inside = float(np.mean((stamps >= t0 - slack) & (stamps <= t1 + slack)))
    if inside < limits.MIN_POSES_COVERAGE:
        raise InputError(f"{where}: the poses span {t0:.3f}..{t1:.3f} s but only {inside:.0%} of the map's "
                         f"nodes ({float(stamps.min()):.3f}..{float(stamps.max()):.3f} s) fall in it; "
                         f"are they on the recording's clock?")


# --- frames -----------------------------------------------------------------------------

def frame_size(width: int, height: int, where: str) -> None:
    """Refuse a frame size outside the limits (checked from headers, before decoding)."""
    if width > limits.MAX_FRAME_WIDTH or height > limits.MAX_FRAME_HEIGHT:
        raise InputError(f"{where}: frames of {width}x{height} are larger than panotopo accepts "
                         f"({limits.MAX_FRAME_WIDTH}x{limits.MAX_FRAME_HEIGHT}); scale the recording down")
    if width < limits.MIN_FRAME_WIDTH or height < limits.MIN_FRAME_HEIGHT:
        raise InputError(f"{where}: frames of {width}x{height} are too small for a panorama "
                         f"(at least {limits.MIN_FRAME_WIDTH}x{limits.MIN_FRAME_HEIGHT})")


def image_file_size(source) -> Optional[tuple[int, int]]:
    """(width, height) of an image (a path or a binary file) from its header only (Pillow
    reads lazily), or None when Pillow cannot tell (the decoder then says what is wrong).
    Pillow's own bomb check is off meanwhile: the caller compares the size with the limits."""
    try:
        from PIL import Image
    except ImportError:
        return None
    bomb_limit = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None
    try:
        with Image.open(source) as im:
            return int(im.size[0]), int(im.size[1])
    except Exception:  # not an image Pillow knows (or corrupt): leave it to the decoder
        return None
    finally:
        Image.MAX_IMAGE_PIXELS = bomb_limit


# --- descriptor options (command line and session files) -----------------------------------

def _device(value: Any, name: str) -> str:
    """auto, cpu, mps, cuda or cuda:N; a device that is not here is refused now."""
    text = str(value).strip().lower()
    base, _, index = text.partition(":")
    if base not in ("auto", "cpu", "cuda", "mps") or (index and (base != "cuda" or not index.isdigit())):
        raise InputError(f"{name}: unknown device {value!r} (use auto, cpu, cuda, cuda:N or mps)")
    if base in ("cuda", "mps"):
        import torch

        if base == "cuda" and not torch.cuda.is_available():
            raise InputError(f"{name}: '{text}' asked for, but CUDA is not available here; use --device cpu")
        if base == "mps" and not (getattr(torch.backends, "mps", None) and torch.backends.mps.is_available()):
            raise InputError(f"{name}: 'mps' asked for, but Apple MPS is not available here; use --device cpu")
    if base == "auto":
        import torch

        if torch.cuda.is_available():
            return "cuda"
        mps = getattr(torch.backends, "mps", None)
        return "mps" if mps is not None and mps.is_available() else "cpu"
    return text


def readable_file(value: Any, name: str) -> str:
    """A path the descriptor will READ: it must exist and be a regular file."""
    if not isinstance(value, str) or not value:
        raise InputError(f"{name}: expected a file path, got {value!r}")
    path = Path(value).expanduser()
    try:
        st = os.stat(path)
    except OSError:
        raise InputError(f"{name}: {value}: no such file") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{name}: {value}: not a regular file")
    return str(path)


def _vocabulary(value: Any, name: str) -> str:
    """anyloc-vlad's vocabulary: 'map', a domain name, or an existing .pt file."""
    if not isinstance(value, str) or not value:
        raise InputError(f"{name}: expected 'map', a domain name or a file, got {value!r}")
    if value == "map" or ("/" not in value and os.sep not in value and not value.endswith(".pt")):
        return value
    return readable_file(value, name)


def _str_choice(choices):
    def check(value: Any, name: str) -> str:
        if value not in choices:
            raise InputError(f"{name}: expected one of {', '.join(choices)}, got {value!r}")
        return value
    return check


def _int(lo, hi):
    return lambda value, name: integer(value, name, lo=lo, hi=hi)


def _bool(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise InputError(f"{name}: expected true or false, got {value!r}")
    return value


def _text(value: Any, name: str) -> str:
    if not isinstance(value, str) or not value or len(value) > 64:
        raise InputError(f"{name}: expected a short name, got {value!r}")
    return value


_INPUT_HEIGHT = _int(limits.MIN_INPUT_HEIGHT, limits.MAX_INPUT_HEIGHT)
_BATCH = _int(1, limits.MAX_BATCH_SIZE)
_ANYLOC_COMMON = {
    "backbone": _text, "weights": readable_file, "allow_download": _bool,
    "layer": _int(0, 64), "facet": _str_choice(("value", "key", "query", "token")),
    "input_height": _INPUT_HEIGHT, "batch_size": _BATCH, "device": _device,
    "pca_dim": _int(1, limits.MAX_PCA_DIM),
}
# The options each descriptor may be built with, and the check of each value. Nothing
# here names a path to WRITE to (anyloc-vlad's ``save_vocabulary`` is deliberately
# absent: a session file must never make panotopo write a file it names).
ALLOWED_OPTIONS: dict[str, dict] = {
    "effnet-vlad": {
        "input_height": _INPUT_HEIGHT, "batch_size": _BATCH, "device": _device,
        "vocabulary_size": _int(1, 1024), "stage": _str_choice(tuple(effnet.STAGES)),
        "layout": _str_choice(effnet.LAYOUTS), "sectors": _int(2, 16),
        "seed": _int(0, limits.MAX_SEED), "threads": _int(1, 1024),
        "phases": _int(1, 16),   # the model names the allowed values (1, 2, 4, 8, 16)
        "photometric": _str_choice(effnet.PHOTOMETRIC),
    },
    "anyloc-vlad": {**_ANYLOC_COMMON, "vocabulary": _vocabulary, "num_clusters": _int(1, 1024)},
    "anyloc-gem": {**_ANYLOC_COMMON, "gem_p": lambda v, n: number(v, n, above=0.0, hi=100.0)},
}
# Options the command line passes to every descriptor; those a descriptor has no use for
# are dropped when they hold their neutral value, refused otherwise.
_NEUTRAL = {"vocabulary": "map"}


def describe_options(descriptor: str, options: Any, name=lambda key: f"option '{key}'",
                     from_file: bool = False) -> dict:
    """The checked ``options`` of ``descriptor``; InputError naming the first bad one
    (``name(key)`` is how the message names an option: an argument, a session field).

    ``from_file``: the options come from a session file, which may not turn on
    downloads (only the user, on the command line or in the app, may).
    """
    if not isinstance(options, dict):
        raise InputError(f"{name('')}: expected a mapping, got {type(options).__name__}")
    allowed = ALLOWED_OPTIONS.get(descriptor)
    if allowed is None:
        return dict(options)  # unknown descriptor: the registry says so in its own words
    out = {}
    for key, value in options.items():
        name_ = name(key)
        if from_file and key == "allow_download":
            continue  # never from a file: the user turns downloads on each time
        if key not in allowed:
            if _NEUTRAL.get(key) == value:
                continue
            if key == "vocabulary":
                raise InputError(f"{name_}: {descriptor} builds its vocabulary from the recording; "
                                 f"a vocabulary file is for anyloc-vlad")
            raise InputError(f"{name_}: not an option of {descriptor} "
                             f"(allowed: {', '.join(sorted(allowed))})")
        if value is None:
            continue
        out[key] = allowed[key](value, name_)
    return out
