"""Ray-cast renderer of the second world family: one ray per panorama column.

Column ``c`` of a W-column panorama looks at world angle ``yaw - (c + 0.5 - W/2) * 2 pi / W``
(the project's convention: centre column = heading, columns increase clockwise). Each
column's ray is intersected with every wall segment at once (numpy, W x n); the nearest hit
gives the wall distance D. A row at elevation phi then sees the wall at height
``cam_h + D tan(phi)`` when that lies between the floor and the wall top, else the floor
(below) or the ceiling/sky (above), each at its own distance. Things (people, boxes) are a
second, nearer layer of short segments. All lookups become one ``cv2.remap`` into the tile
atlas; the blur level is chosen per pixel from the pixel's footprint on the surface, so far
and grazing surfaces do not alias. The result is the robot-frame panorama before any camera
effect (``camera.py`` adds those).
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from .textures import LEVELS, MARGIN, TILE_H, TILE_W
from .world import World

_ROW = TILE_H + 2 * MARGIN


@lru_cache(maxsize=8)
def _angles(width: int) -> tuple[np.ndarray, np.ndarray]:
    """Column offsets (clockwise from the heading) and row elevations of a 2:1 panorama."""
    height = width // 2
    off = (np.arange(width) + 0.5 - width / 2) * (2 * np.pi / width)
    phi = np.pi / 2 - (np.arange(height) + 0.5) * (np.pi / height)
    return off, phi


def cast(segs: np.ndarray, px: float, py: float, dx: np.ndarray, dy: np.ndarray):
    """Nearest hit of rays (px, py) + t (dx, dy) on segments: (t, segment index, s along it)."""
    if len(segs) == 0:
        n = dx.size
        return np.full(n, np.inf), np.zeros(n, int), np.zeros(n)
    ax, ay = segs[:, 0] - px, segs[:, 1] - py
    ex, ey = segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1]
    denom = dx[:, None] * ey[None] - dy[:, None] * ex[None]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / denom
        t = (ax * ey - ay * ex)[None] * inv
        s = (ax[None] * dy[:, None] - ay[None] * dx[:, None]) * inv
    t = np.where((t > 1e-4) & (s >= 0) & (s <= 1) & np.isfinite(t), t, np.inf)
    idx = np.argmin(t, axis=1)
    rows = np.arange(dx.size)
    return t[rows, idx], idx, s[rows, idx]


def _things_segments(world: World, lap: int, px: float, py: float):
    """Segments of the things present in ``lap``: (segs, owner, u0 along the owner)."""
    th = world.things
    if th.size.size == 0:
        return np.zeros((0, 4)), np.zeros(0, int), np.zeros(0)
    lap = min(lap, th.pos.shape[0] - 1)
    segs, owner, u0 = [], [], []
    for k in np.flatnonzero(~np.isnan(th.pos[lap, :, 0])):
        c = th.pos[lap, k]
        if th.person[k]:
            v = c - (px, py)
            perp = np.array([-v[1], v[0]]) / max(np.hypot(*v), 1e-6) * th.size[k] / 2
            segs.append(np.r_[c + perp, c - perp])
            owner.append(k)
            u0.append(0.0)
        else:
            h = th.size[k] / 2
            a = th.angle[k]
            rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            corners = (rot @ np.array([[-h, -h], [h, -h], [h, h], [-h, h]]).T).T + c
            for i in range(4):
                segs.append(np.r_[corners[i], corners[(i + 1) % 4]])
                owner.append(k)
                u0.append(float(i))
    return np.array(segs).reshape(-1, 4), np.array(owner, int), np.array(u0)


def _person_mask(u: np.ndarray, h: np.ndarray, width: np.ndarray, height: np.ndarray) -> np.ndarray:
    """A standing person's outline on a billboard: head, shoulders/torso, two legs."""
    x = (u - 0.5) * width
    head = x ** 2 + (h - (height - 0.12)) ** 2 < 0.115 ** 2
    torso = (h > 0.85) & (h < height - 0.22) & (np.abs(x) < width / 2 * 0.9)
    legs = (h <= 0.85) & (np.abs(x) < width / 2 * 0.6) & (np.abs(x) > 0.025)
    return head | torso | legs


def render_view(world: World, x: float, y: float, yaw: float, lap: int, width: int,
                cam_h: float) -> np.ndarray:
    """The robot-frame panorama (height x width x 3 float32, 0..255) at pose (x, y, yaw)."""
    off, phi = _angles(width)
    height = phi.size
    ang = yaw - off
    dx, dy = np.cos(ang), np.sin(ang)
    tan = np.tan(phi)[:, None]
    cosphi = np.cos(phi)[:, None]
    pix = 2 * np.pi / width

    D, si, s = cast(world.segs, x, y, dx, dy)
    seg = world.segs[si]
    e = seg[:, 2:] - seg[:, :2]
    elen = np.hypot(e[:, 0], e[:, 1])
    edir = e / elen[:, None]
    hit = np.stack([x + D * dx, y + D * dy], 1)
    u_local = ((hit - world.origin[si]) * edir).sum(1)
    chunk = np.floor(u_local / world.tile_w).astype(np.int64)
    tile = world.wall_tile(world.key[si], chunk, si)
    top = world.wall_height(world.key[si], chunk)
    u_frac = u_local / world.tile_w - chunk
    inc = np.abs(dx * edir[:, 1] - dy * edir[:, 0])          # sin(ray, wall) = cos(incidence)
    nrm = np.stack([-edir[:, 1], edir[:, 0]], 1)
    facing = np.where(((np.stack([dx, dy], 1) * nrm).sum(1) > 0)[:, None], -nrm, nrm)
    if world.indoor:
        wall_shade = (0.8 + 0.2 * np.abs(facing @ world.sun)) / (1.0 + 0.02 * D)
    else:
        wall_shade = 0.72 + 0.38 * np.clip(facing @ world.sun, 0, 1)

    hgt = cam_h + D[None] * tan                                # (H, W) height seen on the wall
    mx = np.empty((height, width), np.float32)
    my = np.empty((height, width), np.float32)
    level = np.zeros((height, width), np.float32)
    shade = np.ones((height, width), np.float32)

    wv = 1.0 - np.mod(hgt / world.tile_h, 1.0)
    mx[:] = (MARGIN + u_frac * TILE_W)[None]
    my[:] = tile[None] * _ROW + MARGIN + wv * (TILE_H - 1)
    fp = (D[None] / cosphi) * pix / np.maximum(inc, 0.25)[None]
    level[:] = np.log2(np.maximum(fp / (world.tile_w / TILE_W), 1e-6))
    shade[:] = wall_shade[None]

    # Floor and ceiling: the point where the pixel's ray meets the plane.
    below = hgt < 0
    above = hgt > top[None]
    sinphi = np.abs(np.sin(phi))[:, None]
    for mask, plane_h, tid, sh in ((below, cam_h, world.floor_tile, 0.85),
                                   (above, world.ceiling_h - cam_h, world.ceiling_tile, 0.95)):
        if mask is above and not world.indoor:
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            dist = plane_h / np.abs(tan)
        fx = x + dist * dx[None]
        fy = y + dist * dy[None]
        fs = world.floor_size
        pmx = MARGIN + np.mod(fx / fs, 1.0) * TILE_W
        pmy = tid * _ROW + MARGIN + np.mod(fy / (fs / 2), 1.0) * (TILE_H - 1)
        pfp = dist / cosphi * pix / np.sqrt(np.maximum(sinphi, 0.05))
        mx = np.where(mask, pmx, mx)
        my = np.where(mask, pmy, my)
        level = np.where(mask, np.log2(np.maximum(pfp / (fs / TILE_W), 1e-6)), level)
        shade = np.where(mask, sh, shade)
    if not world.indoor:
        # Sky: fixed in the world (azimuth), from the horizon up.
        su = np.mod(ang / (2 * np.pi), 1.0)
        sv = np.clip(1.0 - phi / (np.pi / 2), 0, 1)[:, None]
        mx = np.where(above, (MARGIN + su * TILE_W)[None], mx)
        my = np.where(above, world.sky_tile * _ROW + MARGIN + sv * (TILE_H - 1), my)
        level = np.where(above, 0.0, level)
        shade = np.where(above, 1.0, shade)

    # Things: nearer than the wall, up to their height.
    tsegs, owner, u0 = _things_segments(world, lap, x, y)
    if len(tsegs):
        Dt, ti, ts = cast(tsegs, x, y, dx, dy)
        k = owner[ti]
        th = world.things
        near = Dt < D
        ht = cam_h + Dt[None] * tan
        u = ts
        seen = near[None] & (ht >= 0) & (ht <= th.height[k][None])
        person = th.person[k]
        if person.any():
            outline = _person_mask(u[None], ht, th.size[k][None], th.height[k][None])
            seen &= ~person[None] | outline
        tmx = (MARGIN + np.clip(u, 0, 1) * (TILE_W - 1))[None]
        tmy = th.tile[k][None] * _ROW + MARGIN + (1.0 - np.clip(ht / th.height[k][None], 0, 1)) * (TILE_H - 1)
        tfp = Dt[None] / cosphi * pix / (th.size[k][None] / TILE_W)
        mx = np.where(seen, tmx, mx)
        my = np.where(seen, tmy, my)
        level = np.where(seen, np.log2(np.maximum(tfp, 1e-6)), level)
        shade = np.where(seen, 0.95, shade)

    lv = np.clip(np.rint(level), 0, LEVELS - 1)
    my = my + lv.astype(np.float32) * world.atlas.level_rows
    img = cv2.remap(world.atlas.image, mx.astype(np.float32), my.astype(np.float32),
                    cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return img.astype(np.float32) * shade[..., None].astype(np.float32)
