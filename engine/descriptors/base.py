"""Plain data for descriptors and the interface every descriptor model implements.

The .npz contract (DESIGN.md): ``stamps`` float64 (n,), ``frames`` int64 (n,),
``shifts`` int64 (n,), ``descriptors`` float32 (n, d) L2-normalised rows,
``meta`` a JSON string (descriptor name, parameters).
Added key (optional): ``columns`` float16 (n, W', F), per-column signatures of the
shifted frames for yaw-aligned verification (``engine.verify``). Files without it
still load (``columns`` is then None).
Added key (optional): ``colours`` float16 (n, 512), the colour histogram of each frame's
horizon band, evidence of the retired ``verified-rules`` method (no longer computed) for
revisits with a lateral offset; no map method reads it now. Files without it still load
(``colours`` is then None); colours of another shape are dropped with a note.

Loading checks what a file from anywhere may hold (``engine.npz_guard`` and ``load``): real
numbers only (complex, boolean or text arrays are refused, never cast), one row per frame,
stamps that never run backwards, no all-zero descriptor row; descriptor rows not of unit
length (integer descriptors, another tool's output) are normalised, and ``notes`` says so.
Added keys (optional, together): ``feat_offsets`` int64 (n + 1,), ``feat_uv`` float16 (N, 2),
``feat_desc`` uint8 (N, 128): the local features of every shifted frame
(``engine.features.FeatureTable``; frame i owns rows ``feat_offsets[i]:feat_offsets[i + 1]``,
uv are column/row fractions of the frame) for two-view geometry (``engine.sphere``).
Files without them still load (``features`` is then None).
"""

from __future__ import annotations

import itertools
import json
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator, Optional

import numpy as np

from ..errors import InputError
from ..features import FeatureTable
from ..progress import CancelToken, Progress, check, report


@dataclass
class Descriptors:
    stamps: np.ndarray    # float64 (n,)
    frames: np.ndarray    # int64 (n,) source frame index
    shifts: np.ndarray    # int64 (n,) columns rolled by the panorama shift (0 without shift)
    vectors: np.ndarray   # float32 (n, d), rows L2-normalised
    meta: dict = field(default_factory=dict)  # descriptor name, settings, source...
    columns: Optional[np.ndarray] = None  # float16 (n, W', F) column signatures, when computed
    colours: Optional[np.ndarray] = None  # float16 (n, 512) horizon-band colour histograms, when computed
    features: Optional[FeatureTable] = None  # local features of each shifted frame, when computed
    # Derived results kept in memory (retrieval, background statistics, geometry per frame
    # pair), so that re-mapping after a threshold change is cheap; never saved.
    cache: dict = field(default_factory=dict, repr=False, compare=False)
    # What loading had to mend (one line each, e.g. rows normalised), for the caller to
    # tell the user; never saved.
    notes: list = field(default_factory=list, repr=False, compare=False)

    def __len__(self) -> int:
        return int(self.vectors.shape[0])

    def optional_arrays(self) -> dict:
        """The added, optional .npz keys that are set (for writers of the file)."""
        extra = {"columns": self.columns, "colours": self.colours}
        out = {k: np.asarray(v, np.float16) for k, v in extra.items() if v is not None}
        if self.features is not None:
            out.update(self.features.to_arrays())
        return out

    def save(self, path: str | Path, vector_dtype=np.float32) -> None:
        """Write the .npz atomically. ``vector_dtype`` float16 halves a cache file; the
        contract's files (``panotopo describe``) keep float32."""
        from ..outputs import write_atomically  # random temp name, umask mode, atomic

        write_atomically(path, lambda f: np.savez(
            f,
            stamps=np.asarray(self.stamps, np.float64),
            frames=np.asarray(self.frames, np.int64),
            shifts=np.asarray(self.shifts, np.int64),
            descriptors=np.asarray(self.vectors, vector_dtype),
            meta=np.array(json.dumps(self.meta)),
            **self.optional_arrays(),
        ))

    @classmethod
    def load(cls, path: str | Path) -> "Descriptors":
        from ..npz_guard import check_archive, check_contents

        path = Path(path)
        check_archive(path)  # a zip bomb or a lying header is refused before loading
        try:
            with np.load(path, allow_pickle=False) as z:
                missing = {"stamps", "frames", "shifts", "descriptors", "meta"} - set(z.files)
                if missing:
                    raise InputError(f"{path}: not a panotopo descriptors file (missing {', '.join(sorted(missing))})")
                raw = {k: z[k] for k in ("stamps", "frames", "shifts", "descriptors", "columns", "colours")
                       if k in z.files}
                for key, arr in raw.items():
                    _check_kind(path, key, arr)
                d = cls(
                    stamps=raw["stamps"].astype(np.float64),
                    frames=raw["frames"].astype(np.int64),
                    shifts=raw["shifts"].astype(np.int64),
                    vectors=raw["descriptors"].astype(np.float32),
                    meta=json.loads(str(z["meta"])),
                    columns=raw["columns"].astype(np.float16) if "columns" in raw else None,
                    colours=raw["colours"].astype(np.float16) if "colours" in raw else None,
                )
                try:
                    d.features = FeatureTable.from_arrays({k: z[k] for k in z.files if k.startswith("feat_")},
                                                          frames=len(d.stamps))
                except InputError as exc:
                    raise InputError(f"{path}: {exc}") from None
        except InputError:
            raise
        except FileNotFoundError:
            raise InputError(f"{path}: no such file") from None
        except Exception as exc:  # zip/pickle/json errors all mean the same to a user
            raise InputError(f"{path}: cannot read descriptors file ({exc.__class__.__name__})") from None
        n = len(d.stamps)
        if d.vectors.ndim != 2 or not (len(d.frames) == len(d.shifts) == d.vectors.shape[0] == n):
            raise InputError(f"{path}: descriptors file has inconsistent array lengths")
        if d.columns is not None and (d.columns.ndim != 3 or d.columns.shape[0] != n):
            raise InputError(f"{path}: descriptors file has column signatures of the wrong shape")
        if d.colours is not None and (d.colours.ndim != 2 or d.colours.shape != (n, COLOUR_BINS)):
            # No map method reads colours any more (the retired verified-rules did): a file
            # whose colours panotopo could not have written still maps, without them.
            d.notes.append(f"{path}: ignored its 'colours' (shape {' x '.join(map(str, d.colours.shape))}, "
                           f"not {n} x {COLOUR_BINS}); no map method reads them")
            d.colours = None
        check_contents(d, path)
        d.notes.extend(_unit_rows(d, path, integer=raw["descriptors"].dtype.kind in "iu"))
        return d


# The width of the optional 'colours' arrays of older files: a Lab histogram, 8 bins per
# channel (the .npz contract's (n, 512)).
COLOUR_BINS = 512
# A row is taken as L2-normalised when its length is within this of 1: float16 caches and
# other tools' rounding stay well inside it; a row outside it was never normalised.
UNIT_NORM_TOLERANCE = 1e-3
# The numeric kinds each array of the file may hold (numpy dtype kinds): real numbers for
# all; integers are whole numbers (read as floats) or, for descriptors, directions that
# are normalised when read. Complex numbers, booleans, text and dates are refused.
_KINDS = {"stamps": "fiu", "frames": "iu", "shifts": "iu", "descriptors": "fiu", "columns": "fiu",
          "colours": "fiu"}


def _check_kind(path: Path, key: str, arr: np.ndarray) -> None:
    """Refuse an array whose numbers are not of a kind ``key`` may hold (a cast would
    silently drop the imaginary part of complex numbers, or turn text into an error)."""
    if arr.dtype.kind == "f" and _KINDS[key] == "iu" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
        return  # whole numbers written as floats (another tool's file): read as they are
    if arr.dtype.kind not in _KINDS[key]:
        kind = {"c": "complex numbers", "b": "true/false values", "U": "text", "S": "bytes",
                "M": "dates", "m": "time spans", "f": "fractional numbers"}.get(arr.dtype.kind, str(arr.dtype))
        wanted = "whole numbers" if _KINDS[key] == "iu" else "real numbers"
        raise InputError(f"{path}: '{key}' holds {kind} ({arr.dtype}); it must hold {wanted}")


def _unit_rows(d: "Descriptors", path: Path, integer: bool) -> list[str]:
    """L2-normalise the descriptor rows that are not (cosine similarity is the contract's
    measure: a row's direction is what it says); the notes saying so, none when every row
    already was. A zero row has no direction: refused."""
    if d.vectors.size == 0:
        return []
    norms = np.linalg.norm(d.vectors, axis=1)
    if not np.all(np.isfinite(norms)):  # finite values whose squares overflow float32
        norms = np.linalg.norm(d.vectors.astype(np.float64), axis=1)
    zero = np.flatnonzero(norms == 0)
    if zero.size:
        raise InputError(f"{path}: descriptor row {int(zero[0])} is all zeros (no direction to compare); "
                         f"{zero.size} such row(s)")
    off = np.abs(norms - 1.0) > UNIT_NORM_TOLERANCE
    if not off.any():
        return []
    d.vectors[off] = (d.vectors[off].astype(np.float64) / norms[off, None]).astype(np.float32)
    what = "integers" if integer else "not of unit length"
    return [f"{path}: {int(off.sum())} of {len(norms)} descriptor rows were {what}; normalised them to "
            f"unit length (the similarity is the cosine of the rows' directions)"]


def in_batches(images: Iterable[np.ndarray], batch_size: int, count: int, progress: Optional[Progress],
               cancel: Optional[CancelToken], stage: str) -> Iterator[list[np.ndarray]]:
    """``images`` in lists of ``batch_size`` (the last may be shorter): cancel checked before
    each list, progress ``stage`` reported once the caller has used it."""
    done = 0
    batch: list[np.ndarray] = []
    report(progress, 0, count, stage)
    for rgb in itertools.chain(images, [None]):
        if rgb is not None:
            batch.append(rgb)
        if not batch or (rgb is not None and len(batch) < batch_size):
            continue
        check(cancel)
        yield batch
        done += len(batch)
        batch = []
        report(progress, done, max(count, done), stage)


class DescriptorModel(ABC):
    """A visual place recognition descriptor.

    ``defaults`` holds the calibrated map parameters for this descriptor
    (at least ``node_sim_th`` and ``loop_sim_th``), used when the user sets none.
    """

    name: str = ""
    defaults: dict = {}

    @abstractmethod
    def describe(
        self,
        images: Iterable[np.ndarray],
        count: int,
        progress: Optional[Progress] = None,
        cancel: Optional[CancelToken] = None,
    ) -> np.ndarray:
        """Describe ``count`` RGB panoramas (already shifted); returns float32 (count, d), L2-normalised rows.

        ``images`` is a one-pass iterator. Models with a map-specific vocabulary
        build it from these same images (keeping local features as needed).
        """

    def settings(self) -> dict:
        """Everything that changes the output (for the cache key and the .npz meta)."""
        return {"name": self.name}

    def input_columns(self) -> int:
        """Columns the network resizes each panorama to before any crop (0: unknown).

        Frames wider than this are shrunk before describing (``engine.pipeline.working_copy``),
        never below it, so a wide network input is not fed an upsampled frame."""
        return 0
