"""A simple 2.5D world for synthetic 360-degree recordings.

The world is a 2D floor plan (metres, x east, y north) of free space made of axis-aligned
corridors (indoor) or streets (outdoor). Its boundary becomes vertical wall segments, each
with its own procedural texture (doors, posters, windows, shop fronts...), deterministic from
the seed. Some segments reuse another segment's theme, so that places are recognisable but
place recognition is not trivially perfect. The floor, ceiling (indoor) and sky (outdoor) are
textures looked up in world coordinates, so a rotation of the camera only rotates the image.

Everything here is built once per world; ``render.py`` only samples it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import InputError

LOOKS = ("indoor", "outdoor")

CELL = 0.25          # occupancy grid cell (m); corridor half-widths are multiples of it
MIP_LEVELS = 5       # texture pyramid levels (same size, increasingly blurred) against moire


@dataclass(frozen=True)
class Corridor:
    """Free space around an axis-aligned centreline from (x0, y0) to (x1, y1)."""

    x0: float
    y0: float
    x1: float
    y1: float


@dataclass
class People:
    """Walkers: vertical cylinders going back and forth along straight lines."""

    p0: np.ndarray        # (P, 2) line start
    p1: np.ndarray        # (P, 2) line end
    speed: np.ndarray     # (P,) m/s
    phase: np.ndarray     # (P,) metres already walked at t = 0
    radius: np.ndarray    # (P,)
    height: np.ndarray    # (P,)
    colours: np.ndarray   # (P, 4, 3) float32 0..1: trousers, shirt, skin, hair

    def __len__(self) -> int:
        return int(self.p0.shape[0])

    def positions(self, t: float) -> np.ndarray:
        """(P, 2) positions at time ``t`` (ping-pong along each line)."""
        d = self.p1 - self.p0
        length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-6)
        s = np.mod(self.phase + self.speed * t, 2.0 * length)
        s = np.where(s > length, 2.0 * length - s, s)
        return self.p0 + d * (s / length)[:, None]


@dataclass
class World:
    seed: int
    look: str
    # Walls: segment A -> B with free space on the right of A->B (texture not mirrored).
    seg_a: np.ndarray          # (S, 2)
    seg_b: np.ndarray          # (S, 2)
    seg_height: np.ndarray     # (S,) metres
    seg_offset: np.ndarray     # (S,) first texel column of the segment in the atlas
    seg_shade: np.ndarray      # (S,) orientation-dependent brightness
    wall_rho: float            # texels per metre on walls
    wall_top: float            # height (m) of atlas row 0; z = 0 is the atlas bottom
    wall_atlas: np.ndarray     # (L, Ha, Wa, 3) uint8, level l blurred ~2**l texels
    floor_rho: float
    floor_tiles: np.ndarray    # (2, L, T, T, 3) uint8 periodic: material 0 and material 1
    ceiling_rho: float
    ceiling_tile: np.ndarray   # (L, T, T, 3) uint8 periodic (indoor only)
    sky: np.ndarray            # (Hs, Ws, 3) uint8: rows elevation 90..0, columns azimuth 0..360
    ground_origin: np.ndarray  # (2,) world xy of ground-map pixel (0, 0) corner
    ground_cell: float
    ground_material: np.ndarray  # (Gh, Gw) float32 0..1 weight of material 1
    ground_shade: np.ndarray   # (Gh, Gw) float32 brightness multiplier (dark near walls)
    ground_paint: np.ndarray   # (Gh, Gw) float32 0..1 white road marking
    camera_height: float
    ceiling_height: float      # indoor only; outdoor: inf
    haze: np.ndarray           # (3,) float32 colour of far distance
    haze_distance: float       # metres; inf: none
    people: People = field(default_factory=lambda: make_people([], 0, 0))
    lighting_drift: float = 0.0
    noise: float = 0.0
    walk_lines: list = field(default_factory=list)  # centrelines people may walk along

    @property
    def n_segments(self) -> int:
        return int(self.seg_a.shape[0])


# ---------------------------------------------------------------- floor plan -> walls

def _occupancy(corridors: list[Corridor], half_width: float) -> tuple[np.ndarray, np.ndarray]:
    """Boolean free-space grid (rows = y) and the world xy of its lower-left corner."""
    xs = [v for c in corridors for v in (c.x0, c.x1)]
    ys = [v for c in corridors for v in (c.y0, c.y1)]
    margin = half_width + 4 * CELL
    origin = np.array([min(xs) - margin, min(ys) - margin])
    nx = int(round((max(xs) + margin - origin[0]) / CELL))
    ny = int(round((max(ys) + margin - origin[1]) / CELL))
    free = np.zeros((ny, nx), dtype=bool)
    for c in corridors:
        if c.x0 != c.x1 and c.y0 != c.y1:
            raise ValueError("corridors must be axis-aligned")
        x0, x1 = sorted((c.x0, c.x1))
        y0, y1 = sorted((c.y0, c.y1))
        j0 = int(round((x0 - half_width - origin[0]) / CELL))
        j1 = int(round((x1 + half_width - origin[0]) / CELL))
        i0 = int(round((y0 - half_width - origin[1]) / CELL))
        i1 = int(round((y1 + half_width - origin[1]) / CELL))
        free[i0:i1, j0:j1] = True
    return free, origin


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) index pairs of the True runs of a 1D boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _boundary_walls(free: np.ndarray, origin: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Maximal straight walls (A, B) between free and solid cells, free side on the right."""
    walls = []
    ny, nx = free.shape
    # Vertical edges at x = origin + j * CELL between column j-1 and j.
    pad = np.pad(free, 1, constant_values=False)
    for j in range(nx + 1):
        left, right = pad[1:-1, j], pad[1:-1, j + 1]
        x = origin[0] + j * CELL
        for i0, i1 in _runs(right & ~left):    # free on the east: walk south (free on right)
            walls.append((np.array([x, origin[1] + i1 * CELL]), np.array([x, origin[1] + i0 * CELL])))
        for i0, i1 in _runs(left & ~right):    # free on the west: walk north
            walls.append((np.array([x, origin[1] + i0 * CELL]), np.array([x, origin[1] + i1 * CELL])))
    for i in range(ny + 1):
        below, above = pad[i, 1:-1], pad[i + 1, 1:-1]
        y = origin[1] + i * CELL
        for j0, j1 in _runs(above & ~below):   # free to the north: walk east
            walls.append((np.array([origin[0] + j0 * CELL, y]), np.array([origin[0] + j1 * CELL, y])))
        for j0, j1 in _runs(below & ~above):   # free to the south: walk west
            walls.append((np.array([origin[0] + j1 * CELL, y]), np.array([origin[0] + j0 * CELL, y])))
    return walls


def _split_walls(walls, rng: np.random.Generator, lo: float, hi: float):
    """Cut long walls into pieces of lo..hi metres, each of which gets its own texture."""
    pieces = []
    for a, b in walls:
        length = float(np.hypot(*(b - a)))
        cuts = [0.0]
        while length - cuts[-1] > hi:
            cuts.append(cuts[-1] + float(rng.uniform(lo, hi)))
        if length - cuts[-1] < lo * 0.5 and len(cuts) > 1:
            cuts.pop()
        cuts.append(length)
        d = (b - a) / length
        for s0, s1 in zip(cuts[:-1], cuts[1:]):
            pieces.append((a + d * s0, a + d * s1))
    return pieces


# ---------------------------------------------------------------- procedural textures

def _smooth_noise(rng: np.random.Generator, h: int, w: int, scale: float) -> np.ndarray:
    """Periodic smooth noise in [-1, 1] with features about ``scale`` pixels wide."""
    spec = np.fft.rfft2(rng.standard_normal((h, w)))
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    spec *= np.exp(-((fx ** 2 + fy ** 2) * (scale ** 2) * 2.0))
    n = np.fft.irfft2(spec, s=(h, w))
    n -= n.mean()
    return (n / (np.abs(n).max() + 1e-9)).astype(np.float32)


class _Canvas:
    """A wall texture in metres: u along the wall, z up from the floor."""

    def __init__(self, length: float, height: float, rho: float, colour):
        self.rho = rho
        self.h = max(1, int(round(height * rho)))
        self.w = max(1, int(round(length * rho)))
        self.img = np.empty((self.h, self.w, 3), np.float32)
        self.img[:] = colour

    def box(self, u0: float, u1: float, z0: float, z1: float):
        """Slice (rows, cols) of the rectangle u0..u1, z0..z1 (clipped)."""
        c0 = int(np.clip(round(u0 * self.rho), 0, self.w))
        c1 = int(np.clip(round(u1 * self.rho), 0, self.w))
        r0 = int(np.clip(round(self.h - z1 * self.rho), 0, self.h))
        r1 = int(np.clip(round(self.h - z0 * self.rho), 0, self.h))
        return slice(r0, r1), slice(c0, c1)

    def rect(self, u0, u1, z0, z1, colour) -> np.ndarray:
        rs, cs = self.box(u0, u1, z0, z1)
        self.img[rs, cs] = colour
        return self.img[rs, cs]

    def framed(self, u0, u1, z0, z1, colour, frame_colour, frame=0.05) -> np.ndarray:
        self.rect(u0 - frame, u1 + frame, z0 - frame, z1 + frame, frame_colour)
        return self.rect(u0, u1, z0, z1, colour)


def _vivid(rng: np.random.Generator) -> np.ndarray:
    """A saturated colour (HSV with random hue)."""
    hsv = np.uint8([[[rng.integers(0, 180), rng.integers(150, 256), rng.integers(140, 256)]]])
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0].astype(np.float32) / 255.0


def _poster_content(rng: np.random.Generator, patch: np.ndarray) -> None:
    """Fill a poster area with one of a few structured designs (in place)."""
    h, w = patch.shape[:2]
    if h < 2 or w < 2:
        return
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    c1, c2, c3 = _vivid(rng), _vivid(rng), _vivid(rng)
    kind = rng.integers(0, 5)
    if kind == 0:      # stripes at an angle
        a = rng.uniform(0, np.pi)
        period = rng.uniform(3, 8)
        m = (np.sin((xx * np.cos(a) + yy * np.sin(a)) * 2 * np.pi / period) > 0)[..., None]
        patch[:] = np.where(m, c1, c2)
    elif kind == 1:    # big circles on a background
        patch[:] = c1
        for _ in range(rng.integers(1, 4)):
            cy, cx, r = rng.uniform(0, h), rng.uniform(0, w), rng.uniform(0.15, 0.45) * min(h, w)
            patch[(yy - cy) ** 2 + (xx - cx) ** 2 < r * r] = (c2 if rng.random() < 0.5 else c3)
    elif kind == 2:    # colour blocks
        patch[:] = c1
        patch[: h // 2, : w // 2] = c2
        patch[h // 2:, w // 2:] = c3
    elif kind == 3:    # title band + text lines
        patch[:] = np.float32([0.93, 0.92, 0.88])
        patch[: max(1, h // 4)] = c1
        for r in range(h // 4 + 2, h - 1, 3):
            end = int(w * rng.uniform(0.4, 0.9))
            patch[r, 1:end] = 0.2
    else:              # smooth colour blobs
        n = _smooth_noise(rng, h, w, max(2.0, min(h, w) / 3))[..., None]
        patch[:] = np.where(n > 0.1, c1, np.where(n < -0.2, c3, c2))


def _indoor_wall(rng: np.random.Generator, length: float, height: float, rho: float) -> np.ndarray:
    paints = np.float32([[0.86, 0.83, 0.76], [0.80, 0.82, 0.80], [0.78, 0.84, 0.80],
                         [0.78, 0.81, 0.86], [0.88, 0.86, 0.84], [0.90, 0.80, 0.66]])
    cv = _Canvas(length, height, rho, paints[rng.integers(len(paints))])
    rows = np.linspace(0.0, 1.0, cv.h, dtype=np.float32)[:, None, None]
    cv.img *= 0.97 + 0.06 * rows                       # slightly lighter towards the floor
    if rng.random() < 0.4:                             # wainscot: lower part another colour
        cv.rect(0, length, 0, rng.uniform(0.8, 1.1), paints[rng.integers(len(paints))] * 0.85)
    cv.rect(0, length, 0, 0.1, np.float32([0.25, 0.22, 0.2]))   # skirting board
    u = rng.uniform(0.2, 1.0)
    while u < length - 0.5:
        kind = rng.choice(["door", "poster", "window", "board", "extinguisher", "gap"],
                          p=[0.22, 0.33, 0.15, 0.1, 0.05, 0.15])
        if kind == "door" and u + 1.0 < length:
            wood = np.float32([0.55, 0.36, 0.2]) * rng.uniform(0.7, 1.2)
            col = wood if rng.random() < 0.6 else _vivid(rng) * 0.7
            cv.framed(u, u + 0.9, 0.0, 2.05, col, np.float32([0.35, 0.33, 0.32]), 0.06)
            if rng.random() < 0.5:                     # glass panel
                cv.rect(u + 0.3, u + 0.6, 1.3, 1.8, np.float32([0.55, 0.65, 0.7]))
            cv.rect(u + 0.75, u + 0.82, 0.95, 1.05, np.float32([0.8, 0.8, 0.75]))
            u += 0.9 + 0.12
        elif kind == "poster":
            w, h = rng.uniform(0.4, 1.0), rng.uniform(0.5, 1.0)
            zc = rng.uniform(1.2, 1.6)
            if u + w < length:
                patch = cv.framed(u, u + w, zc - h / 2, zc + h / 2, 0.0,
                                  np.float32([0.15, 0.15, 0.15]), 0.02)
                _poster_content(rng, patch)
            u += w
        elif kind == "window":
            w = rng.uniform(1.0, 2.0)
            if u + w < length:
                glass = cv.framed(u, u + w, 0.9, 2.1, np.float32([0.62, 0.74, 0.82]),
                                  np.float32([0.92, 0.92, 0.92]), 0.06)
                g = np.linspace(1.15, 0.8, glass.shape[0], dtype=np.float32)[:, None, None]
                glass *= g
                cv.rect(u + w / 2 - 0.03, u + w / 2 + 0.03, 0.9, 2.1, np.float32([0.92, 0.92, 0.92]))
            u += w
        elif kind == "board":
            w = rng.uniform(0.8, 1.6)
            if u + w < length:
                cork = cv.framed(u, u + w, 1.0, 1.8, np.float32([0.7, 0.55, 0.35]),
                                 np.float32([0.5, 0.4, 0.3]), 0.03)
                for _ in range(rng.integers(2, 6)):     # pinned sheets
                    ph, pw = cork.shape[0], cork.shape[1]
                    r0, c0 = rng.integers(0, max(1, ph - 6)), rng.integers(0, max(1, pw - 5))
                    cork[r0:r0 + 7, c0:c0 + 5] = np.float32([0.95, 0.95, 0.9]) if rng.random() < 0.7 else _vivid(rng)
            u += w
        elif kind == "extinguisher":
            cv.rect(u, u + 0.18, 0.3, 0.85, np.float32([0.75, 0.08, 0.06]))
            u += 0.18
        u += rng.uniform(0.3, 1.5)
    return np.clip(cv.img, 0, 1)


def _facade(rng: np.random.Generator, length: float, height: float, rho: float) -> np.ndarray:
    walls = np.float32([[0.62, 0.32, 0.24], [0.72, 0.70, 0.66], [0.85, 0.80, 0.68],
                        [0.55, 0.56, 0.58], [0.80, 0.66, 0.50], [0.70, 0.76, 0.78],
                        [0.90, 0.88, 0.84]])
    base = walls[rng.integers(len(walls))]
    cv = _Canvas(length, height, rho, base)
    grain = _smooth_noise(rng, cv.h, cv.w, 1.5)[..., None]
    cv.img *= 1.0 + 0.05 * grain
    storey = rng.uniform(2.8, 3.4)
    win_w, win_h = rng.uniform(0.8, 1.6), rng.uniform(1.2, 1.8)
    pitch = win_w + rng.uniform(0.8, 2.0)
    glass = np.float32([0.32, 0.40, 0.48]) * rng.uniform(0.8, 1.2)
    frame = np.float32([0.92, 0.92, 0.9]) if rng.random() < 0.6 else base * 0.6
    n_win = max(1, int((length - 0.6) // pitch))
    start = (length - n_win * pitch + (pitch - win_w)) / 2
    z = storey
    while z + win_h + 0.6 < height:                    # upper storeys: a window grid
        zw = z + 0.9
        for k in range(n_win):
            u = start + k * pitch
            g = cv.framed(u, u + win_w, zw, zw + win_h, glass, frame, 0.07)
            g *= np.linspace(1.35, 0.85, max(1, g.shape[0]), dtype=np.float32)[:, None, None]
        cv.rect(0, length, z - 0.08, z + 0.08, base * 0.8)   # storey ledge
        z += storey
    cv.rect(0, length, height - 0.35, height, base * 0.7)      # cornice
    # Ground floor: shop windows with a coloured sign, or a plain wall with a door.
    if rng.random() < 0.6:
        sign = _vivid(rng)
        cv.rect(0.2, length - 0.2, 2.55, 3.05, sign)
        rs, cs = cv.box(0.5, length - 0.5, 2.68, 2.92)
        cv.img[rs, cs][:, ::3] = 0.95                  # "letters"
        u = 0.4
        while u + 1.2 < length - 0.3:
            w = min(rng.uniform(1.5, 3.5), length - 0.3 - u)
            cv.framed(u, u + w, 0.4, 2.4, np.float32([0.25, 0.3, 0.33]), np.float32([0.2, 0.2, 0.22]), 0.06)
            if rng.random() < 0.5:
                cv.rect(u + 0.2, u + w - 0.2, 0.6, 1.6, _vivid(rng) * 0.6)   # goods on display
            u += w + rng.uniform(0.3, 1.0)
    else:
        u = rng.uniform(0.5, max(0.6, length - 1.5))
        cv.framed(u, u + 1.1, 0.0, 2.3, np.float32([0.3, 0.2, 0.12]), base * 0.55, 0.1)
    cv.rect(0, length, 0, 0.35, base * 0.55)           # plinth
    return np.clip(cv.img, 0, 1)


def _mip(tex: np.ndarray, wrap: bool) -> np.ndarray:
    """(L, h, w, 3) uint8 pyramid of the same size; level l is blurred over ~2**l texels."""
    levels = [tex]
    for lvl in range(1, MIP_LEVELS):
        sigma = 0.6 * 2 ** (lvl - 1)
        pad = int(3 * sigma) + 1
        src = np.pad(tex, ((pad, pad), (pad, pad), (0, 0)), mode="wrap" if wrap else "edge")
        blurred = cv2.GaussianBlur(src, (0, 0), sigma)[pad:-pad, pad:-pad]
        levels.append(blurred)
    return np.stack(levels).astype(np.uint8)


def _to_u8(img: np.ndarray) -> np.ndarray:
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)


def _floor_tile(rng: np.random.Generator, look: str, material: int, t: int, rho: float) -> np.ndarray:
    """A periodic t x t floor texture (material 0: main surface, 1: sidewalk outdoors)."""
    yy, xx = np.mgrid[0:t, 0:t].astype(np.float32) / rho    # metres
    n_fine = _smooth_noise(rng, t, t, 0.7)[..., None]
    n_big = _smooth_noise(rng, t, t, t / 6)[..., None]
    if look == "indoor":
        sq = 0.5
        colour = [np.float32([0.62, 0.6, 0.55]), np.float32([0.55, 0.58, 0.6]),
                  np.float32([0.66, 0.56, 0.46])][rng.integers(3)]
        per = rng.uniform(0.9, 1.1, size=(int(round(t / rho / sq)),) * 2 + (1,)).astype(np.float32)
        img = colour * per[(yy / sq).astype(int) % per.shape[0], (xx / sq).astype(int) % per.shape[1]]
        img = img * (1 + 0.04 * n_fine + 0.05 * n_big)
        grout = (np.mod(xx, sq) < 0.02) | (np.mod(yy, sq) < 0.02)
        img[grout] *= 0.7
    elif material == 0:   # asphalt
        img = np.float32([0.33, 0.33, 0.34]) * (1 + 0.12 * n_fine + 0.08 * n_big)
    else:                 # paving stones
        bw, bh = 0.4, 0.2
        row = np.floor(yy / bh)
        xs = xx + (np.mod(row, 2) * bw / 2)
        per = rng.uniform(0.85, 1.1, size=(64, 64, 1)).astype(np.float32)
        img = np.float32([0.66, 0.62, 0.56]) * per[row.astype(int) % 64, (xs / bw).astype(int) % 64]
        img = img * (1 + 0.06 * n_fine)
        joint = (np.mod(xs, bw) < 0.02) | (np.mod(yy, bh) < 0.02)
        img[joint] *= 0.72
    return _to_u8(img)


def _ceiling_tile(t: int, rho: float) -> np.ndarray:
    """Periodic suspended ceiling: 0.6 m panels, a light panel in every 4 x 2."""
    yy, xx = np.mgrid[0:t, 0:t].astype(np.float32) / rho
    p = 0.6
    img = np.empty((t, t, 3), np.float32)
    img[:] = np.float32([0.86, 0.86, 0.84])
    light = (np.mod(np.floor(xx / p), 4) == 1) & (np.mod(np.floor(yy / p), 2) == 0)
    img[light] = np.float32([1.0, 1.0, 0.97])
    grid = (np.mod(xx, p) < 0.025) | (np.mod(yy, p) < 0.025)
    img[grid] = np.float32([0.6, 0.6, 0.6])
    return _to_u8(img)


def _sky(rng: np.random.Generator, hs: int = 96, ws: int = 512) -> np.ndarray:
    el = np.linspace(1.0, 0.0, hs, dtype=np.float32)[:, None, None]  # 1 at zenith
    zenith, horizon = np.float32([0.30, 0.50, 0.82]), np.float32([0.78, 0.86, 0.93])
    img = horizon + (zenith - horizon) * np.sqrt(el)
    # Clouds: large soft shapes with some detail, flattened towards the horizon.
    clouds = _smooth_noise(rng, hs, ws, 14.0) + 0.35 * _smooth_noise(rng, hs, ws, 4.0)
    cover = np.clip((clouds - 0.15) * 1.8, 0, 1)[..., None] * (0.3 + 0.7 * el)
    img = img * (1 - cover) + np.float32([0.97, 0.97, 0.98]) * cover
    return _to_u8(img)


# ---------------------------------------------------------------- the world

def make_people(walk_lines: list, count: int, seed: int) -> People:
    """``count`` walkers on random ``walk_lines`` ((x0, y0, x1, y1, lateral_half_width))."""
    rng = np.random.default_rng([seed, 7])
    p0 = np.zeros((count, 2))
    p1 = np.zeros((count, 2))
    for k in range(count):
        x0, y0, x1, y1, half = walk_lines[int(rng.integers(len(walk_lines)))]
        d = np.array([x1 - x0, y1 - y0], float)
        n = np.array([-d[1], d[0]]) / max(np.hypot(*d), 1e-9)
        off = n * rng.uniform(-half, half)
        p0[k] = np.array([x0, y0]) + off
        p1[k] = np.array([x1, y1]) + off
    skin = np.float32([[0.93, 0.76, 0.62], [0.76, 0.57, 0.42], [0.45, 0.32, 0.24]])
    colours = np.zeros((count, 4, 3), np.float32)
    for k in range(count):
        colours[k, 0] = [np.float32([0.15, 0.18, 0.3]), np.float32([0.2, 0.2, 0.2]),
                         np.float32([0.5, 0.45, 0.35])][rng.integers(3)]
        colours[k, 1] = _vivid(rng) * rng.uniform(0.5, 1.0)
        colours[k, 2] = skin[rng.integers(3)]
        colours[k, 3] = np.float32([0.12, 0.09, 0.06]) * rng.uniform(0.8, 3.0)
    d = p1 - p0
    length = np.hypot(d[:, 0], d[:, 1]) if count else np.zeros(0)
    return People(p0=p0, p1=p1, speed=rng.uniform(0.7, 1.4, count),
                  phase=rng.uniform(0, 2, count) * length, radius=rng.uniform(0.2, 0.27, count),
                  height=rng.uniform(1.55, 1.9, count), colours=colours)


LIGHT_ANGLE = 0.8    # radians from +x: where the light comes from (the sun outdoors)


def wall_shade(seg_a: np.ndarray, seg_b: np.ndarray, look: str,
               light_angle: float = LIGHT_ANGLE) -> np.ndarray:
    """Per-wall brightness (S,): walls facing the light at ``light_angle`` are brighter.

    ``build_world`` uses the default angle; another day of the same world
    (``engine.synth.sessions``) turns the light to relight the same walls."""
    lengths = np.hypot(*(seg_b - seg_a).T)
    d = seg_b - seg_a
    normal = np.stack([d[:, 1], -d[:, 0]], 1) / lengths[:, None]   # points into free space
    light = np.array([np.cos(light_angle), np.sin(light_angle)])
    facing = normal @ light
    if look == "indoor":
        return 0.88 + 0.12 * facing
    return 0.72 + 0.28 * np.clip(facing, 0, 1) + 0.05 * facing


def build_world(corridors: list[Corridor], look: str, seed: int, *,
                people: int = 0, lighting_drift: float = 0.0, noise: float = 0.0) -> World:
    """The world whose free space is the union of ``corridors`` (deterministic from ``seed``)."""
    if look not in LOOKS:
        raise InputError(f"unknown look {look!r}; choose one of {', '.join(LOOKS)}")
    rng = np.random.default_rng([seed, 1 if look == "indoor" else 2])
    indoor = look == "indoor"
    half = 1.25 if indoor else 5.0
    free, origin = _occupancy(corridors, half)
    walls = _boundary_walls(free, origin)
    pieces = _split_walls(walls, rng, *((2.5, 7.0) if indoor else (5.0, 14.0)))
    n = len(pieces)
    seg_a = np.array([p[0] for p in pieces])
    seg_b = np.array([p[1] for p in pieces])
    lengths = np.hypot(*(seg_b - seg_a).T)

    rho = 32.0 if indoor else 14.0
    ceiling_height = 2.7
    heights = np.full(n, ceiling_height) if indoor else rng.uniform(6.0, 16.0, n)
    wall_top = float(heights.max())
    # Themes: about a quarter of the segments repeat an earlier segment's theme.
    theme = np.arange(n)
    repeat = rng.random(n) < 0.25
    theme[repeat] = rng.integers(0, n, repeat.sum())
    theme_seed = rng.integers(0, 2 ** 31, n)
    atlas_h = int(round(wall_top * rho))
    columns = []
    offsets = np.zeros(n)
    pos = 0
    for k in range(n):
        trng = np.random.default_rng([int(theme_seed[theme[k]]), int(seed)])
        make = _indoor_wall if indoor else _facade
        tex = make(trng, float(lengths[k]), float(heights[k]), rho)
        full = np.zeros((atlas_h, tex.shape[1], 3), np.float32)
        full[atlas_h - tex.shape[0]:] = tex                     # bottom-aligned: z = 0 at bottom
        columns.append(full)
        columns.append(full[:, -1:].copy())                    # one guard column against bleeding
        offsets[k] = pos
        pos += tex.shape[1] + 1
    atlas = _mip(_to_u8(np.concatenate(columns, axis=1)), wrap=False)

    shade = wall_shade(seg_a, seg_b, look)

    floor_rho, t = (32.0, 128) if indoor else (24.0, 192)
    tiles = np.stack([_mip(_floor_tile(rng, look, m, t, floor_rho), wrap=True) for m in (0, 1)])
    ceiling = _mip(_ceiling_tile(144, 40.0), wrap=True)

    # Ground maps on the occupancy grid: sidewalks near buildings, darker floor near walls.
    dist = cv2.distanceTransform(free.astype(np.uint8), cv2.DIST_L2, 5) * CELL
    paint = np.zeros_like(dist, np.float32)
    if indoor:
        material = np.zeros_like(dist, np.float32)
        gshade = 1.0 - 0.3 * np.exp(-dist / 0.35)
    else:
        material = (dist < 2.5).astype(np.float32)
        gshade = 1.0 - 0.35 * np.exp(-dist / 0.6)
        kerb = (dist >= 2.5) & (dist < 2.5 + CELL)
        gshade = np.where(kerb, 0.75, gshade)
        # Lane edge lines 0.7 m off the kerb (away from the robot, which drives mid-street).
        paint = (np.abs(dist - 3.3) < 0.15).astype(np.float32) * 0.8
    walk = []
    for c in corridors:
        walk.append((c.x0, c.y0, c.x1, c.y1, 0.7 if indoor else 3.5))
    world = World(
        seed=seed, look=look, seg_a=seg_a, seg_b=seg_b, seg_height=heights, seg_offset=offsets,
        seg_shade=shade.astype(np.float32), wall_rho=rho, wall_top=wall_top, wall_atlas=atlas,
        floor_rho=floor_rho, floor_tiles=tiles, ceiling_rho=40.0, ceiling_tile=ceiling,
        sky=_sky(rng), ground_origin=origin, ground_cell=CELL,
        ground_material=material.astype(np.float32), ground_shade=gshade.astype(np.float32),
        ground_paint=paint,
        camera_height=1.2, ceiling_height=ceiling_height if indoor else np.inf,
        haze=np.float32([0.8, 0.85, 0.9]), haze_distance=np.inf if indoor else 120.0,
        lighting_drift=lighting_drift, noise=noise, walk_lines=walk,
    )
    world.people = make_people(walk, people, seed)
    return world
