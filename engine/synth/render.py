"""Equirectangular rendering of a ``World`` by 2D ray casting (fully vectorised).

Conventions (pixel centres):
- column c looks at world bearing ``yaw + pi - 2*pi*c/W``: the left edge is heading - 180 deg
  (behind), the centre column c = W/2 is the robot's heading, columns increase to the
  robot's right (clockwise seen from above), as in any panorama viewer.
- row r looks at elevation ``pi/2 - pi*(r + 0.5)/H``: +90 deg at the top, -90 at the bottom.
- yaw is counter-clockwise from the world +x axis (radians).

A yaw rotation is exactly a circular column shift: the image is rendered in a frame that
depends only on the sub-column part of yaw, then rolled by the integer part. So
``render(yaw + 2*pi*k/W) == np.roll(render(yaw), k, axis=1)`` bit for bit (noise off).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .world import World

_QUANT = 2.0 ** 20      # yaw is quantised to 1/2**20 of a column so the split is exact


def _bilinear(tex: np.ndarray, level: np.ndarray, v: np.ndarray, u: np.ndarray,
              wrap: bool) -> np.ndarray:
    """Sample (L, h, w, 3) uint8 ``tex`` at float texel coords (v rows, u cols) -> (N, 3) float32."""
    _, h, w, _ = tex.shape
    u = u - 0.5
    v = v - 0.5
    u0 = np.floor(u)
    v0 = np.floor(v)
    fu = (u - u0).astype(np.float32)[:, None]
    fv = (v - v0).astype(np.float32)[:, None]
    u0 = u0.astype(np.int64)
    v0 = v0.astype(np.int64)
    if wrap:
        u0 %= w
        v0 %= h
        u1 = (u0 + 1) % w
        v1 = (v0 + 1) % h
    else:
        u1 = np.clip(u0 + 1, 0, w - 1)
        v1 = np.clip(v0 + 1, 0, h - 1)
        u0 = np.clip(u0, 0, w - 1)
        v0 = np.clip(v0, 0, h - 1)
    a = tex[level, v0, u0].astype(np.float32)
    b = tex[level, v0, u1].astype(np.float32)
    c = tex[level, v1, u0].astype(np.float32)
    d = tex[level, v1, u1].astype(np.float32)
    top = a + (b - a) * fu
    bottom = c + (d - c) * fu
    return (top + (bottom - top) * fv) * np.float32(1.0 / 255.0)


def _level(footprint_texels: np.ndarray, levels: int) -> np.ndarray:
    """Mip level for a pixel footprint measured in texels."""
    lvl = np.floor(np.log2(np.maximum(footprint_texels, 1.0)) + 0.5)
    return np.clip(lvl, 0, levels - 1).astype(np.int64)


def _cast_walls(world: World, x: float, y: float, dx: np.ndarray, dy: np.ndarray):
    """Nearest wall hit per ray: distance (inf if none), segment index, metres along segment."""
    ex = world.seg_b[:, 0] - world.seg_a[:, 0]
    ey = world.seg_b[:, 1] - world.seg_a[:, 1]
    ax = world.seg_a[:, 0] - x
    ay = world.seg_a[:, 1] - y
    denom = dx[:, None] * ey[None, :] - dy[:, None] * ex[None, :]          # cross(D, E)
    safe = np.where(np.abs(denom) < 1e-12, np.inf, denom)
    dist = (ax[None, :] * ey[None, :] - ay[None, :] * ex[None, :]) / safe  # cross(A-P, E)
    u = (ax[None, :] * dy[:, None] - ay[None, :] * dx[:, None]) / safe     # cross(A-P, D)
    ok = (dist > 1e-6) & (u >= 0.0) & (u <= 1.0)
    dist = np.where(ok, dist, np.inf)
    seg = np.argmin(dist, axis=1)
    rows = np.arange(dx.size)
    length = np.hypot(ex, ey)
    return dist[rows, seg], seg, u[rows, seg] * length[seg]


def _cast_people(world: World, x: float, y: float, t: float, dx: np.ndarray, dy: np.ndarray):
    """Nearest walker per ray: distance (inf if none), walker index, |offset| / radius."""
    ppl = world.people
    if len(ppl) == 0:
        inf = np.full(dx.size, np.inf)
        return inf, np.zeros(dx.size, np.int64), np.zeros(dx.size)
    pos = ppl.positions(t)
    vx = pos[:, 0] - x
    vy = pos[:, 1] - y
    b = dx[:, None] * vx[None, :] + dy[:, None] * vy[None, :]           # along the ray
    side = np.abs(dx[:, None] * vy[None, :] - dy[:, None] * vx[None, :])  # off the ray
    r = ppl.radius[None, :]
    hit_d = b - np.sqrt(np.maximum(r * r - side * side, 0.0))
    ok = (side < r) & (hit_d > 0.3)
    hit_d = np.where(ok, hit_d, np.inf)
    who = np.argmin(hit_d, axis=1)
    rows = np.arange(dx.size)
    return hit_d[rows, who], who, side[rows, who] / ppl.radius[who]


def _ground(world: World, gx: np.ndarray, gy: np.ndarray, foot_m: np.ndarray) -> np.ndarray:
    """Floor / street colour at world points (N,) with pixel footprint ``foot_m`` metres."""
    rho = world.floor_rho
    lvl = _level(foot_m * rho, world.floor_tiles.shape[1])
    col0 = _bilinear(world.floor_tiles[0], lvl, gy * rho, gx * rho, wrap=True)
    # Ground maps (material, shade) on the occupancy grid, bilinear via a 2-channel lookup.
    gi = (gy - world.ground_origin[1]) / world.ground_cell
    gj = (gx - world.ground_origin[0]) / world.ground_cell
    maps = np.stack([world.ground_material, world.ground_shade, world.ground_paint], -1)
    gm = _bilinear_float(maps, gi, gj)
    mat, shade, paint = gm[:, 0:1], gm[:, 1:2], gm[:, 2:3]
    if world.look == "outdoor":
        col1 = _bilinear(world.floor_tiles[1], lvl, gy * rho, gx * rho, wrap=True)
        col0 = col0 + (col1 - col0) * mat
        col0 = col0 + (np.float32(0.9) - col0) * paint
    return col0 * shade


def _bilinear_float(img: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Bilinear lookup in a small float image (h, w, c), clamped at the edges."""
    h, w, _ = img.shape
    u = np.clip(u - 0.5, 0, w - 1.001)
    v = np.clip(v - 0.5, 0, h - 1.001)
    u0 = u.astype(np.int64)
    v0 = v.astype(np.int64)
    fu = (u - u0)[:, None].astype(np.float32)
    fv = (v - v0)[:, None].astype(np.float32)
    top = img[v0, u0] + (img[v0, u0 + 1] - img[v0, u0]) * fu
    bot = img[v0 + 1, u0] + (img[v0 + 1, u0 + 1] - img[v0 + 1, u0]) * fu
    return top + (bot - top) * fv


def _render_base(world: World, x: float, y: float, frac: float, t: float,
                 width: int, height: int) -> np.ndarray:
    """H x W x 3 float32 image whose column j looks at bearing 2*pi*(frac - j)/W + pi."""
    theta = 2.0 * np.pi * (frac - np.arange(width)) / width + np.pi
    dx, dy = np.cos(theta), np.sin(theta)
    el = np.pi / 2 - np.pi * (np.arange(height) + 0.5) / height
    tan_el = np.tan(el)
    dtheta = 2.0 * np.pi / width
    hc = world.camera_height

    img = np.empty((height, width, 3), np.float32)
    depth = np.full((height, width), np.inf)            # horizontal distance of what is seen

    wall_d, seg, along = _cast_walls(world, x, y, dx, dy)
    z = hc + wall_d[None, :] * tan_el[:, None]           # height where each ray meets its wall
    seg_h = world.seg_height[seg][None, :]
    is_wall = np.isfinite(wall_d)[None, :] & (z >= 0.0) & (z <= seg_h)

    # Walls.
    rr, cc = np.nonzero(is_wall)
    if rr.size:
        rho = world.wall_rho
        d = wall_d[cc]
        cos_el = np.cos(el[rr])
        foot = d * dtheta / cos_el ** 2                  # vertical footprint grows off-horizon
        lvl = _level(foot * rho, world.wall_atlas.shape[0])
        s = seg[cc]
        u = world.seg_offset[s] + np.clip(along[cc] * rho, 0.5, None)
        v = (world.wall_top - z[rr, cc]) * rho
        col = _bilinear(world.wall_atlas, lvl, v, u, wrap=False)
        zz = z[rr, cc]
        shade = world.seg_shade[s]
        if world.look == "indoor":
            # Soft darkening in the floor and ceiling corners, and a little with distance.
            shade = shade * (1 - 0.25 * np.exp(-zz / 0.25)) * (1 - 0.15 * np.exp(-(world.ceiling_height - zz) / 0.3))
            shade = shade / np.sqrt(1 + (d / 30.0) ** 2)
        img[rr, cc] = col * shade[:, None].astype(np.float32)
        depth[rr, cc] = d

    # Floor (below the horizon where no wall is closer).
    below = (~is_wall) & (tan_el[:, None] < 0)
    rr, cc = np.nonzero(below)
    if rr.size:
        fd = hc / -tan_el[rr]
        gx = x + fd * dx[cc]
        gy = y + fd * dy[cc]
        foot = np.maximum(fd * dtheta, fd * fd / hc * (np.pi / height))
        col = _ground(world, gx, gy, foot)
        if world.look == "indoor":
            col = col / np.sqrt(1 + (fd / 30.0) ** 2)[:, None].astype(np.float32)
        img[rr, cc] = col
        depth[rr, cc] = fd

    # Above the walls: ceiling indoors, sky outdoors.
    above = (~is_wall) & (tan_el[:, None] >= 0)
    rr, cc = np.nonzero(above)
    if rr.size:
        if np.isfinite(world.ceiling_height):
            cd = (world.ceiling_height - hc) / np.maximum(tan_el[rr], 1e-6)
            gx = x + cd * dx[cc]
            gy = y + cd * dy[cc]
            rho = world.ceiling_rho
            foot = np.maximum(cd * dtheta, cd * cd / (world.ceiling_height - hc) * (np.pi / height))
            lvl = _level(foot * rho, world.ceiling_tile.shape[0])
            col = _bilinear(world.ceiling_tile, lvl, gy * rho, gx * rho, wrap=True)
            img[rr, cc] = col / np.sqrt(1 + (cd / 30.0) ** 2)[:, None].astype(np.float32)
            depth[rr, cc] = cd
        else:
            hs, ws, _ = world.sky.shape
            sv = (1.0 - el[rr] / (np.pi / 2)) * hs
            su = np.mod(theta[cc], 2 * np.pi) / (2 * np.pi) * ws
            sky = world.sky[None]
            img[rr, cc] = _bilinear(sky, np.zeros(rr.size, np.int64), sv, su, wrap=True)

    # Haze: far things fade towards a pale colour (outdoors).
    if np.isfinite(world.haze_distance):
        fog = (1.0 - np.exp(-np.where(np.isfinite(depth), depth, 0.0) / world.haze_distance))
        img += (world.haze[None, None, :] - img) * fog[..., None].astype(np.float32)

    _draw_people(world, img, depth, x, y, t, dx, dy, tan_el)
    return img


def _draw_people(world, img, depth, x, y, t, dx, dy, tan_el) -> None:
    pd, who, off = _cast_people(world, x, y, t, dx, dy)
    if not np.isfinite(pd).any():
        return
    ppl = world.people
    z = world.camera_height + pd[None, :] * tan_el[:, None]
    hp = ppl.height[who][None, :]
    head = z > hp - 0.25
    inside = (z >= 0) & (z <= hp) & (pd[None, :] < depth) & (~head | (off[None, :] < 0.6))
    rr, cc = np.nonzero(inside)
    if rr.size == 0:
        return
    zz = z[rr, cc]
    w = who[cc]
    frac = zz / ppl.height[w]
    part = np.where(frac < 0.47, 0, np.where(zz < ppl.height[w] - 0.25, 1, np.where(zz < ppl.height[w] - 0.07, 2, 3)))
    col = ppl.colours[w, part]
    # Round shading across the cylinder, feet darker.
    lam = np.sqrt(np.clip(1.0 - off[cc] ** 2, 0, 1))
    col = col * (0.55 + 0.45 * lam)[:, None].astype(np.float32)
    img[rr, cc] = col


def _lighting(world: World, t: float) -> np.ndarray:
    """Slow global gain and colour drift at time ``t`` (3,) float32."""
    a = world.lighting_drift
    if a == 0.0:
        return np.ones(3, np.float32)
    rng = np.random.default_rng([world.seed, 11])
    phase = rng.uniform(0, 2 * np.pi, 4)
    gain = 1.0 + 0.35 * a * np.sin(2 * np.pi * t / 70.0 + phase[0])
    tint = 1.0 + 0.12 * a * np.sin(2 * np.pi * t / 110.0 + phase[1:])
    return (gain * tint).astype(np.float32)


def render(world: World, x: float, y: float, yaw: float, t: float = 0.0,
           width: int = 512, height: int = 256) -> np.ndarray:
    """The equirectangular view (height x width x 3 uint8, width == 2 * height) at pose (x, y, yaw)."""
    if width != 2 * height or height < 2:
        raise InputError(f"panorama size must be 2:1 (width = 2 x height), got {width}x{height}")
    s = np.round(float(yaw) * width / (2.0 * np.pi) * _QUANT) / _QUANT
    k = int(np.floor(s))
    img = _render_base(world, float(x), float(y), s - k, float(t), width, height)
    img *= _lighting(world, t)
    out = np.roll(img, k % width, axis=1)
    if world.noise > 0:
        rng = np.random.default_rng([world.seed, 13, int(round(t * 1000))])
        out = out + rng.normal(0.0, world.noise, out.shape).astype(np.float32)
    return (np.clip(out, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
