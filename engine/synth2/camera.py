"""The camera of a synthetic recording: mounting, exposure, seam, blur, JPEG.

One ``Camera`` per recording, drawn from the seed (``Camera.draw``): a height of 0.5-1.8 m
(from a small ground robot to a helmet), a mounting tilt and roll of up to 4 degrees (so the
horizon waves once around the panorama, and turns with the robot), exposure drifting slowly
(+-15 %) and jumping by up to +-25 % at each lap, white balance drifting +-6 % per channel and
jumping at laps, horizontal motion blur from turning during a 1/60-1/10 s exposure, a
stitching seam (the two lenses' halves differ by up to 7 % per channel in gain and one pixel row,
at a column fixed in the camera), sensor noise and JPEG compression at quality 55-90.
``Camera.plain`` has none of these, for tests of the geometry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np


@dataclass(frozen=True)
class Camera:
    height: float = 1.2
    tilt_deg: float = 0.0          # forward pitch of the mount
    roll_deg: float = 0.0
    exposure_s: float = 0.0        # shutter time: turning blurs over it
    drift: float = 0.0             # relative amplitude of slow exposure drift
    drift_period: float = 90.0     # seconds
    wb_drift: tuple = (0.0, 0.0, 0.0)
    lap_gain: tuple = (1.0,)       # exposure factor per lap
    lap_wb: tuple = ((1.0, 1.0, 1.0),)
    seam_col: float = 0.0          # fraction of the width where the back lens starts
    seam_gain: tuple = (1.0, 1.0, 1.0)
    seam_rows: int = 0
    noise: float = 0.0             # standard deviation in 0..255 units
    jpeg_quality: int = 0          # 0: no compression
    phase: float = field(default=0.0)

    @classmethod
    def plain(cls, height: float = 1.2) -> "Camera":
        return cls(height=height)

    @classmethod
    def draw(cls, rng: np.random.Generator, laps: int, indoor: bool) -> "Camera":
        lap_gain = tuple(float(g) for g in np.r_[1.0, np.exp(rng.uniform(-0.25, 0.25, laps - 1))])
        lap_wb = tuple((1.0, 1.0, 1.0) if lap == 0 else
                       tuple(float(v) for v in np.exp(rng.uniform(-0.06, 0.06, 3))) for lap in range(laps))
        return cls(
            height=float(rng.uniform(0.5, 1.8)),
            tilt_deg=float(rng.uniform(-4, 4)), roll_deg=float(rng.uniform(-4, 4)),
            exposure_s=float(rng.uniform(1 / 30, 1 / 10) if indoor else rng.uniform(1 / 60, 1 / 20)),
            drift=float(rng.uniform(0.05, 0.15)), drift_period=float(rng.uniform(60, 150)),
            wb_drift=tuple(float(v) for v in rng.uniform(0.0, 0.06, 3)),
            lap_gain=lap_gain, lap_wb=lap_wb,
            seam_col=float(rng.uniform(0, 0.5)),
            seam_gain=tuple(float(v) for v in rng.uniform(0.93, 1.07, 3)),
            seam_rows=int(rng.integers(0, 2)) or 1,
            noise=float(rng.uniform(1.0, 3.0)), jpeg_quality=int(rng.integers(55, 91)),
            phase=float(rng.uniform(0, 2 * np.pi)))


@lru_cache(maxsize=8)
def _mount_maps(width: int, tilt_deg: float, roll_deg: float):
    """cv2.remap maps from the camera image to the robot-frame panorama (tilted mount)."""
    height = width // 2
    c = (np.arange(width) + 0.5 - width / 2) * (2 * np.pi / width)     # clockwise from heading
    phi = np.pi / 2 - (np.arange(height) + 0.5) * (np.pi / height)
    C, P = np.meshgrid(c, phi)
    # Robot frame: x forward, y left, z up; the camera direction of each output pixel.
    v = np.stack([np.cos(P) * np.cos(-C), np.cos(P) * np.sin(-C), np.sin(P)], -1)
    t, r = np.radians(tilt_deg), np.radians(roll_deg)
    pitch = np.array([[np.cos(t), 0, np.sin(t)], [0, 1, 0], [-np.sin(t), 0, np.cos(t)]])
    roll = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    w = v @ (pitch @ roll).T
    cc = -np.arctan2(w[..., 1], w[..., 0])
    pp = np.arcsin(np.clip(w[..., 2], -1, 1))
    mx = np.mod(cc * width / (2 * np.pi) + width / 2 - 0.5, width)
    my = np.clip((np.pi / 2 - pp) * height / np.pi - 0.5, 0, height - 1)
    return mx.astype(np.float32), my.astype(np.float32)


def apply_camera(cam: Camera, img: np.ndarray, t: float, lap: int, yaw_rate: float,
                 frame_seed) -> np.ndarray:
    """Camera effects on a robot-frame panorama (float32 0..255) -> the recorded uint8 frame."""
    h, w = img.shape[:2]
    if cam.tilt_deg or cam.roll_deg:
        mx, my = _mount_maps(w, cam.tilt_deg, cam.roll_deg)
        img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    blur = abs(yaw_rate) * cam.exposure_s * w / (2 * np.pi)          # columns swept while exposed
    n = int(round(blur))
    if n >= 1:
        img = sum(np.roll(img, k - n // 2, axis=1) for k in range(n + 1)) / (n + 1)
    lap = min(lap, len(cam.lap_gain) - 1)
    slow = 2 * np.pi * t / cam.drift_period + cam.phase
    gain = cam.lap_gain[lap] * np.exp(cam.drift * np.sin(slow))
    wb = np.array(cam.lap_wb[lap]) * np.exp(np.array(cam.wb_drift) * np.sin(slow * np.array([0.7, 1.0, 1.3]) + 1.0))
    img = img * (gain * wb).astype(np.float32)
    if cam.seam_rows or cam.seam_gain != (1.0, 1.0, 1.0):
        a = int(round(cam.seam_col * w))
        back = slice(a, a + w // 2)
        half = np.roll(img, cam.seam_rows, axis=0)[:, back] * np.array(cam.seam_gain, np.float32)
        img = img.copy()
        img[:, back] = half
    if cam.noise:
        img = img + np.random.default_rng(frame_seed).normal(0, cam.noise, img.shape).astype(np.float32)
    out = np.clip(img + 0.5, 0, 255).astype(np.uint8)
    if cam.jpeg_quality:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, cam.jpeg_quality])
        out = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    return out
