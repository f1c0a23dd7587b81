"""Checks of a descriptors .npz before and after loading it: it is a file from anywhere.

* ``check_archive`` (before loading): every member's uncompressed size as declared in
  the zip directory, and their sum, must stay under ``limits.MAX_NPZ_*`` (a 37 GiB zip
  bomb died of MemoryError, issue 16); every ``.npy`` member's header must not announce
  more data than the member holds (numpy allocates the announced shape first).
* ``check_contents`` (after loading): ``meta`` is a JSON object whose known keys have
  their types (``frame_width`` an integer...), and stamps and descriptors are finite
  (NaN descriptors made a one-node map, silently); no frame is described twice and the
  stamps never run backwards (rows are a recording in order: equal stamps are allowed).
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np

from . import limits
from .errors import InputError


def _npy_header(member) -> tuple[tuple, np.dtype]:
    fmt = np.lib.format
    version = fmt.read_magic(member)
    if version == (1, 0):
        shape, _, dtype = fmt.read_array_header_1_0(member)
    elif version == (2, 0):
        shape, _, dtype = fmt.read_array_header_2_0(member)
    else:
        shape, _, dtype = fmt._read_array_header(member, version)
    return shape, dtype


def check_archive(path: Path) -> None:
    """Refuse a .npz whose members would unpack to more than the limits, before loading."""
    try:
        archive = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile, ValueError):
        return  # not a zip: np.load gives its own answer
    with archive:
        total = 0
        for info in archive.infolist():
            if info.file_size > limits.MAX_NPZ_MEMBER_BYTES:
                raise InputError(f"{path}: member {info.filename} would unpack to {info.file_size / 2**30:.1f} GiB "
                                 f"(limit {limits.MAX_NPZ_MEMBER_BYTES / 2**30:g} GiB); not a descriptors file "
                                 f"panotopo wrote")
            total += info.file_size
            if not info.filename.endswith(".npy"):
                continue
            try:
                with archive.open(info) as member:
                    shape, dtype = _npy_header(member)
            except Exception:
                raise InputError(f"{path}: member {info.filename} is not a valid array") from None
            need = math.prod(shape) * dtype.itemsize
            if need > info.file_size:
                raise InputError(f"{path}: member {info.filename} announces {need:,} bytes of data "
                                 f"but holds {info.file_size:,}")
        if total > limits.MAX_NPZ_TOTAL_BYTES:
            raise InputError(f"{path}: would unpack to {total / 2**30:.1f} GiB "
                             f"(limit {limits.MAX_NPZ_TOTAL_BYTES / 2**30:g} GiB)")


# meta key -> (check, what it should be)
_META_TYPES = {
    "descriptor": (lambda v: isinstance(v, str), "a descriptor name"),
    "interval": (lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0,
                 "a number of seconds"),
    "shift": (lambda v: isinstance(v, bool), "true or false"),
    "frame_width": (lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0, "an integer >= 0"),
    "source": (lambda v: isinstance(v, str), "a path"),
    "topic": (lambda v: v is None or isinstance(v, str), "a topic or null"),
    "defaults": (lambda v: isinstance(v, dict) and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and -1.0 <= x <= 1.0 for x in v.values()),
        "thresholds between -1 and 1"),
    "skipped_frames": (lambda v: isinstance(v, list) and all(isinstance(x, int) for x in v), "frame numbers"),
}


def check_contents(descs, path: Path) -> None:
    """Refuse a loaded descriptors file whose meta or numbers make no sense."""
    meta = descs.meta
    if not isinstance(meta, dict):
        raise InputError(f"{path}: 'meta' must be a JSON object, got {type(meta).__name__}")
    for key, (ok, what) in _META_TYPES.items():
        if key in meta and not ok(meta[key]):
            raise InputError(f"{path}: meta '{key}' must be {what}, got {meta[key]!r:.60}")
    for name, values in (("stamps", descs.stamps), ("descriptors", descs.vectors)):
        finite = np.isfinite(values)
        if not finite.all():
            row = int(np.argwhere(~finite)[0][0])
            raise InputError(f"{path}: {name} of row {row} are not finite numbers (NaN or infinity)")
    if descs.frames.size and int(descs.frames.min()) < 0:
        raise InputError(f"{path}: frame numbers must be >= 0")
    order = np.argsort(descs.frames, kind="stable")
    same = np.flatnonzero(np.diff(descs.frames[order]) == 0)
    if same.size:
        i, j = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        raise InputError(f"{path}: frame {int(descs.frames[i])} is described twice (rows {i} and {j}); "
                         f"each row must be its own frame")
    back = np.flatnonzero(np.diff(descs.stamps) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise InputError(f"{path}: stamps run backwards at row {k} ({descs.stamps[k]:.6g} s after "
                         f"{descs.stamps[k - 1]:.6g} s); rows must be in recording order")
