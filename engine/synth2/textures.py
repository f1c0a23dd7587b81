"""Texture tiles of the second synthetic world family: crops of real photographs.

The crops live in ``resources/textures/synth2`` (sources and licences in its README). A world
gets an ``Atlas``: every tile at ``TILE_W`` x ``TILE_H`` pixels with a wrapped margin (so
bilinear sampling across a tile's edge reads the tile's other side, as a repeating wall
does), stacked vertically, and the whole stack repeated at ``LEVELS`` blur levels (a cheap
mip-map: far or grazing surfaces sample a blurred level instead of aliasing).
Variety comes from the seed: each base crop yields variants (a sub-crop, a mirror, a colour
cast), so that distinct places look distinct while every surface stays a photograph.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError

TEXTURE_DIR = Path(__file__).resolve().parents[2] / "resources" / "textures" / "synth2"
TILE_W, TILE_H = 256, 128
MARGIN = 2
# Blur sigma (in texels) of each mip level; level k stands for a footprint of about 2**k texels.
LEVEL_SIGMAS = (0.0, 1.0, 2.0, 4.0)
LEVELS = len(LEVEL_SIGMAS)

# Which crops serve which surface (names of files in TEXTURE_DIR without ".jpg").
OUTDOOR_WALLS = ("station_brick", "station_hall", "glass_front", "trees", "bank_stairs",
                 "forest_a", "forest_b", "rock")
INDOOR_WALLS = ("station_brick", "station_hall", "glass_front", "rock", "canopy", "bank_stairs")
FLOORS = {"outdoor": "asphalt", "indoor": "pavement", "path": "dirt_path"}
CEILING = "canopy"
SKY = "sky"
OBJECTS = ("person", "bin")


@lru_cache(maxsize=32)
def load_crop(name: str) -> np.ndarray:
    """One shipped crop as RGB uint8 (read-only, cached); a missing file is an InputError."""
    path = TEXTURE_DIR / f"{name}.jpg"
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise InputError(f"texture crop {path} is missing or unreadable")
    rgb = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    rgb.setflags(write=False)
    return rgb


def _variant(img: np.ndarray, rng: np.random.Generator, strength: float) -> np.ndarray:
    """A sub-crop (70-100 % of each side), maybe mirrored, with a +-10 % colour cast and gain."""
    h, w = img.shape[:2]
    if strength > 0:
        fw, fh = rng.uniform(0.7, 1.0), rng.uniform(0.8, 1.0)
        x0 = int(rng.uniform(0, 1 - fw) * w)
        y0 = int(rng.uniform(0, 1 - fh) * h)
        img = img[y0:y0 + int(fh * h), x0:x0 + int(fw * w)]
        if rng.random() < 0.5:
            img = img[:, ::-1]
    tile = cv2.resize(np.ascontiguousarray(img), (TILE_W, TILE_H), interpolation=cv2.INTER_AREA)
    if strength > 0:
        cast = rng.uniform(1 - 0.1 * strength, 1 + 0.1 * strength, 3) * rng.uniform(0.8, 1.15)
        tile = np.clip(tile.astype(np.float32) * cast, 0, 255).astype(np.uint8)
    return tile


@dataclass
class Atlas:
    """Tiles stacked vertically with margins, repeated at every blur level."""
    image: np.ndarray            # (LEVELS * n * (TILE_H + 2 MARGIN), TILE_W + 2 MARGIN, 3) uint8
    names: list                  # per tile: "<crop>#<variant>"

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def level_rows(self) -> int:
        return self.n * (TILE_H + 2 * MARGIN)


def build_atlas(tiles: list[np.ndarray], names: list[str]) -> Atlas:
    """Stack ``tiles`` (each TILE_H x TILE_W x 3 uint8) into an Atlas with blur levels."""
    padded = [np.pad(t, ((MARGIN, MARGIN), (MARGIN, MARGIN), (0, 0)), mode="wrap") for t in tiles]
    levels = []
    for sigma in LEVEL_SIGMAS:
        if sigma == 0:
            levels.extend(padded)
        else:
            # Blur each tile as a repeating pattern (wrap), then keep the padded window.
            # Blur each tile as a repeating pattern: wrap-pad by the kernel's reach (3 sigma).
            pad = int(np.ceil(3 * sigma)) + MARGIN
            for t in tiles:
                big = np.pad(t, ((pad, pad), (pad, pad), (0, 0)), mode="wrap")
                big = cv2.GaussianBlur(big, (0, 0), sigma)
                levels.append(big[pad - MARGIN:pad + TILE_H + MARGIN, pad - MARGIN:pad + TILE_W + MARGIN])
    return Atlas(np.ascontiguousarray(np.concatenate(levels, 0)), list(names))


class TileSet:
    """Collects tiles for one world and hands out their atlas indices."""

    def __init__(self) -> None:
        self.tiles: list[np.ndarray] = []
        self.names: list[str] = []
        self._cache: dict[str, np.ndarray] = {}

    def crop(self, name: str) -> np.ndarray:
        if name not in self._cache:
            self._cache[name] = load_crop(name)
        return self._cache[name]

    def add(self, tile: np.ndarray, name: str) -> int:
        self.tiles.append(tile)
        self.names.append(name)
        return len(self.tiles) - 1

    def add_crop(self, name: str, rng: np.random.Generator, strength: float = 1.0) -> int:
        return self.add(_variant(self.crop(name), rng, strength), f"{name}#{len(self.tiles)}")

    def add_seamless(self, name: str, rng: np.random.Generator) -> int:
        """A crop mirrored into a 2 x 2 block: repeats without visible tile edges (floors)."""
        img = self.crop(name)
        block = np.concatenate([img, img[:, ::-1]], 1)
        block = np.concatenate([block, block[::-1]], 0)
        return self.add(_variant(block, rng, 0.0), f"{name}#seamless")

    def palette(self, crops: tuple, rng: np.random.Generator, variants: int) -> np.ndarray:
        """Tile ids of ``variants`` variants of every crop in ``crops`` (the first one plain)."""
        ids = []
        for name in crops:
            for v in range(variants):
                ids.append(self.add_crop(name, rng, 0.0 if v == 0 else 1.0))
        return np.asarray(ids, np.int64)

    def atlas(self) -> Atlas:
        return build_atlas(self.tiles, self.names)
