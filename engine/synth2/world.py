"""A world of the second family: traced walls, photo tiles, floor/ceiling/sky, moving things.

``build_world(spec, seed, trajectory)`` turns a route's plan into arrays the renderer casts
rays against. Facades: along every wall the tile changes every ``tile_w`` metres, chosen by a
hash of the wall's key and the tile's index (so a long street is a sequence of different
photographed fronts, and look-alike zones repeat the same sequence). Outdoors each tile-wide
facade also gets its own height (3.5-11.5 m: one to three storeys of the 4 m tall tile).
Things (people, bins/boxes) stand beside the route and move, appear or vanish between laps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .paths import Trajectory
from .plan import mix
from .routes import RouteSpec
from .textures import (CEILING, FLOORS, INDOOR_WALLS, OUTDOOR_WALLS, SKY, Atlas, TileSet)


@dataclass
class Things:
    pos: np.ndarray          # (laps, k, 2) metres; NaN where the thing is absent in that lap
    size: np.ndarray         # (k,) width in metres
    height: np.ndarray       # (k,) metres
    tile: np.ndarray         # (k,) atlas tile
    person: np.ndarray       # (k,) bool: a billboard facing the camera with a person's outline
    angle: np.ndarray        # (k,) orientation of a box (radians)


@dataclass
class World:
    layout: str
    indoor: bool
    segs: np.ndarray         # (n, 4)
    key: np.ndarray          # (n,) facade keys
    origin: np.ndarray       # (n, 2)
    palette: np.ndarray      # tile ids for walls
    tile_w: float            # metres of wall per tile
    tile_h: float            # metres of wall height per tile (indoors: the room height)
    ceiling_h: float         # indoors: room height
    floor_tile: int
    floor_size: float        # metres per floor tile (width; height is half)
    ceiling_tile: int
    sky_tile: int
    atlas: Atlas
    things: Things
    sun: np.ndarray          # (2,) unit vector: walls facing it are brighter
    seg_tile: Optional[np.ndarray] = None   # (n,) a fixed tile per wall (-1: the facade palette)

    def wall_tile(self, key: np.ndarray, chunk: np.ndarray, seg: np.ndarray) -> np.ndarray:
        tile = self.palette[mix(key, chunk) % len(self.palette)]
        if self.seg_tile is None:
            return tile
        fixed = self.seg_tile[seg]
        return np.where(fixed >= 0, fixed, tile)

    def wall_height(self, key: np.ndarray, chunk: np.ndarray) -> np.ndarray:
        if self.indoor:
            return np.full(np.shape(key), self.ceiling_h)
        return 3.5 + (mix(key, chunk, 7) % 1000) / 1000.0 * 8.0


def _things(spec: RouteSpec, tr: Trajectory, rng: np.random.Generator, tiles: TileSet,
            indoor: bool) -> Things:
    """People and bins/boxes 1-2 m beside the route, moved or removed between laps."""
    laps = int(tr.lap.max()) + 1
    path = np.stack([tr.x, tr.y], 1)
    person_tile = tiles.add_crop("person", rng, 0.0)
    box_tiles = [tiles.add_crop("bin", rng, 0.0), tiles.add_crop("bin", rng, 1.0),
                 tiles.add_crop("station_hall", rng, 1.0)]
    k_want = int(rng.integers(6, 11))
    pos, size, height, tile, person, angle = [], [], [], [], [], []
    tries = 0
    while len(size) < k_want and tries < 200:
        tries += 1
        i = int(rng.integers(len(path)))
        j = min(i + 1, len(path) - 1)
        d = path[j] - path[max(i - 1, 0)]
        if np.hypot(*d) < 1e-6:
            continue
        nrm = np.array([-d[1], d[0]]) / np.hypot(*d)
        lap_pos = np.full((laps, 2), np.nan)
        for lap in range(laps):
            if lap > 0 and rng.random() < 0.3:
                continue                          # gone in this lap
            side = rng.choice([-1.0, 1.0])
            p = path[i] + nrm * side * rng.uniform(1.0, 2.0) + rng.normal(0, 0.6, 2) * (lap > 0)
            if not spec.plan.free_at(p[None], 0.4)[0]:
                continue
            if np.hypot(*(path - p).T).min() < 0.7:
                continue                          # never on the robot's own path
            lap_pos[lap] = p
        if np.isnan(lap_pos).all():
            continue
        is_person = rng.random() < 0.6
        pos.append(lap_pos)
        person.append(is_person)
        size.append(rng.uniform(0.45, 0.6) if is_person else rng.uniform(0.5, 0.9))
        height.append(rng.uniform(1.6, 1.85) if is_person else rng.uniform(0.6, 1.1))
        tile.append(person_tile if is_person else box_tiles[int(rng.integers(len(box_tiles)))])
        angle.append(rng.uniform(0, np.pi))
    if not size:
        return Things(np.zeros((laps, 0, 2)), *(np.zeros(0) for _ in range(2)), np.zeros(0, int),
                      np.zeros(0, bool), np.zeros(0))
    return Things(np.stack(pos, 1), np.array(size), np.array(height), np.array(tile),
                  np.array(person), np.array(angle))


def build_world(spec: RouteSpec, seed: int, tr: Trajectory) -> World:
    """The world of ``spec`` for ``seed`` (textures, heights and things all from the seed)."""
    rng = np.random.default_rng([int(seed), 3])
    indoor = spec.plan.indoor
    walls = spec.plan.trace(int(rng.integers(1 << 30)))
    tiles = TileSet()
    crops = INDOOR_WALLS if indoor else OUTDOOR_WALLS
    palette = tiles.palette(crops, rng, variants=4)
    floor_name = FLOORS["path"] if spec.path_kind == "path" else FLOORS["indoor" if indoor else "outdoor"]
    floor_tile = tiles.add_seamless(floor_name, rng)
    ceiling_tile = tiles.add_seamless(CEILING, rng)
    sky_tile = tiles.add_crop(SKY, rng, 0.0)
    things = _things(spec, tr, rng, tiles, indoor)
    ceiling_h = float(rng.uniform(2.5, 3.2))
    sun_ang = rng.uniform(0, 2 * np.pi)
    return World(
        layout=spec.plan.name, indoor=indoor, segs=walls.segs, key=walls.key, origin=walls.origin,
        palette=palette, tile_w=3.0 if indoor else 6.0, tile_h=ceiling_h if indoor else 4.0,
        ceiling_h=ceiling_h, floor_tile=floor_tile, floor_size=3.0 if indoor else 4.0,
        ceiling_tile=ceiling_tile, sky_tile=sky_tile, atlas=tiles.atlas(), things=things,
        sun=np.array([np.cos(sun_ang), np.sin(sun_ang)]))
