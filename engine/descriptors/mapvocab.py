"""Pooling a recording's local features into one row per frame, with a map vocabulary
built from the recording itself, in bounded host memory.

Local features are made batch by batch on the model's device. With a fixed vocabulary
each batch is pooled there at once and only its rows reach the host. With a map
vocabulary (k-means on the recording's own features) the first frames' features are
buffered on the host as float16 until the recording ends or the buffer reaches
``budget_bytes``; the vocabulary is then clustered from a seeded sample of the buffer
(``vlad_torch.kmeans_on``: float64, on the GPU where the features were made on CUDA), the
buffer is pooled and freed, and every later batch is pooled as it comes. Pooled rows wait on
the device for ``BATCHES_AHEAD`` batches (or ``ROWS_ON_DEVICE_BYTES``): a copy to the host
waits for the device, and one wait per few batches lets the host stack the next frames while
the network runs; it also bounds how far the host runs ahead (page-locked input per batch).

Host memory for local features is therefore at most ``budget_bytes`` plus one batch
(default 1 GiB: ~38,000 frames of the default effnet-vlad at 128 px, 28 kB each; ~680 frames
of AnyLoc ViT-G/14 at 224 x 448, 1.5 MB each). A recording longer than that gets its
vocabulary from the frames within the budget (its first part) instead of all of them.
"""

from __future__ import annotations

from typing import Callable, Iterable, Optional

import numpy as np
import torch

from ..progress import CancelToken, check
from .vlad_torch import as_centers

BUDGET_BYTES = 1 << 30
ROWS_ON_DEVICE_BYTES = 64 << 20
BATCHES_AHEAD = 4

Pool = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def sample_rows(parts: list[np.ndarray], max_rows: int, seed: int) -> np.ndarray:
    """float32 rows of all ``parts`` (each (..., C)), or a seeded uniform sample of ``max_rows``."""
    flat = [p.reshape(-1, p.shape[-1]) for p in parts]
    total = sum(f.shape[0] for f in flat)
    if total <= max_rows:
        return np.concatenate(flat).astype(np.float32)
    pick = np.sort(np.random.default_rng(seed).choice(total, max_rows, replace=False))
    starts = np.cumsum([0] + [f.shape[0] for f in flat])
    out = []
    for i, f in enumerate(flat):   # index part by part: never concatenates the whole buffer
        lo, hi = np.searchsorted(pick, [starts[i], starts[i + 1]])
        out.append(f[pick[lo:hi] - starts[i]])
    return np.concatenate(out).astype(np.float32)


def pool_recording(batches: Iterable[torch.Tensor], pool: Pool, device: torch.device,
                   centers: Optional[np.ndarray] = None,
                   build: Optional[Callable[[list[np.ndarray]], np.ndarray]] = None,
                   budget_bytes: Optional[int] = None,
                   cancel: Optional[CancelToken] = None) -> tuple[np.ndarray, Optional[np.ndarray]]:
    """(rows float32 (n, d), centres used) from ``batches`` of unit local features (B, N, C).

    ``centers`` given: each batch is pooled on ``device`` as it comes. Otherwise
    ``build(buffered float16 parts) -> centres`` makes the map vocabulary once the
    recording ends or the buffer exceeds ``budget_bytes`` (default ``BUDGET_BYTES``).
    """
    budget = BUDGET_BYTES if budget_bytes is None else int(budget_bytes)
    rows: list[np.ndarray] = []
    pending: list[torch.Tensor] = []   # pooled rows not yet copied to the host
    buffer: list[np.ndarray] = []
    held = 0
    c = None if centers is None else as_centers(centers, device)

    def keep(pooled: torch.Tensor) -> None:
        pending.append(pooled)
        if (len(pending) >= BATCHES_AHEAD
                or sum(p.numel() * p.element_size() for p in pending) >= ROWS_ON_DEVICE_BYTES):
            drain()

    def drain() -> None:
        if pending:
            rows.append(torch.cat(pending).cpu().numpy())
            pending.clear()

    def flush() -> None:
        nonlocal c, held, centers
        centers = build(buffer)
        c = as_centers(centers, device)
        for part in buffer:
            check(cancel)
            with torch.inference_mode():
                keep(pool(torch.from_numpy(part).to(device).float(), c))
        buffer.clear()
        held = 0

    for feats in batches:
        if c is not None:
            with torch.inference_mode():
                keep(pool(feats, c))
            continue
        part = feats.to(torch.float16).cpu().numpy()
        buffer.append(part)
        held += part.nbytes
        if held > budget:
            flush()
    if c is None and buffer:
        flush()
    drain()
    out = np.concatenate(rows).astype(np.float32) if rows else None
    return out, centers
