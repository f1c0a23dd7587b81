"""Descriptor cache on disk: describing is the slow part, so do it once per input and settings.

A key is the sha1 of the input file's identity (absolute path, size, mtime_ns),
the sampling (interval, topic) and the descriptor settings (shift flag included).
A cache file that cannot be read is removed and treated as a miss, never an error.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path
from typing import Optional

import numpy as np

from .base import Descriptors
from .vlad import l2_normalize

# Vectors this long are stored as float16 (half the disk; cosine changes by ~1e-3).
FLOAT16_FROM_DIM = 16384


def default_root() -> Path:
    env = os.environ.get("PANOTOPO_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "panotopo" / "descriptors"


def _file_identity(path: Path) -> dict:
    """Absolute path, size and mtime; for a directory (ROS2 bag, image folder) its files too."""
    path = Path(path).resolve()
    st = path.stat()
    ident = {"path": str(path), "size": st.st_size, "mtime_ns": st.st_mtime_ns}
    if path.is_dir():
        ident["files"] = sorted(
            (str(p.relative_to(path)), p.stat().st_size, p.stat().st_mtime_ns)
            for p in path.rglob("*") if p.is_file()
        )
    return ident


def cache_key(path: str | Path, sampling: dict, settings: dict) -> str:
    """sha1 hex key of (input file identity, sampling, descriptor settings incl. the shift flag)."""
    blob = json.dumps(
        {"input": _file_identity(Path(path)), "sampling": sampling, "settings": settings},
        sort_keys=True,
        default=str,
    )
    return hashlib.sha1(blob.encode("utf-8")).hexdigest()


class DescriptorCache:
    def __init__(self, root: Optional[Path] = None) -> None:
        self.root = Path(root) if root is not None else default_root()

    def path_for(self, key: str) -> Path:
        return self.root / f"{key}.npz"

    def load(self, key: str) -> Optional[Descriptors]:
        """The cached descriptors for ``key``, or None (a corrupt file is removed)."""
        path = self.path_for(key)
        if not path.is_file():
            return None
        try:
            descs = Descriptors.load(path)
        except Exception:  # unreadable or half-written: a miss, and make room for a good copy
            path.unlink(missing_ok=True)
            return None
        descs.vectors = l2_normalize(descs.vectors.astype(np.float32)).astype(np.float32)
        return descs

    def store(self, key: str, descs: Descriptors) -> Path:
        """Write ``descs`` under ``key`` (atomically); long vectors go to disk as float16."""
        self.root.mkdir(parents=True, exist_ok=True)
        long = descs.vectors.ndim == 2 and descs.vectors.shape[1] >= FLOAT16_FROM_DIM
        path = self.path_for(key)
        descs.save(path, vector_dtype=np.float16 if long else np.float32)
        return path

    def clear(self) -> None:
        """Remove every cached file."""
        if self.root.is_dir():
            shutil.rmtree(self.root, ignore_errors=True)

