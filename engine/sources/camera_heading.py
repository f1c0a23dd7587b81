"""The camera's own heading per frame (GoPro CORI), checked against the pictures.

``FrameSource.headings`` feeds the panorama shift: every frame is rolled so that one direction
of the world comes to column 0. A wrong heading there misaligns every view of a place, so a
track is used only when the pictures agree with it. CORI (``engine.sources.gpmf``) gives the
camera's orientation relative to the start as quaternions; their yaw about the camera's z
axis is the heading up to a sign and to which axis is vertical, which GoPro's documentation
does not pin down for every camera. So ``checked_headings``:

1. takes pairs of nearby key frames (cheap to decode) across which the CORI yaw changes by
   at least ``MIN_TURN_DEG``, up to ``PAIRS`` of them, the largest turns first;
2. measures how far each pair's picture turned: the circular cross-correlation of the
   column profiles of the horizon band (rows 30-70 %), as ``engine.shift.relative_yaw`` does;
3. keeps the sign for which at least ``MIN_AGREEING`` of the pairs agree within
   ``AGREE_DEG`` (a camera turned clockwise by t moves the picture t towards lower columns),
   and refuses the track (None, with a note saying why) when neither sign does, or when the
   camera never turned enough to tell.

Headings come out as ``FrameSource.headings`` wants them: degrees clockwise from the start
orientation, one per frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

MIN_TURN_DEG = 15.0
PAIRS = 12
AGREE_DEG = 10.0
MIN_AGREEING = 0.75
PROFILE_WIDTH = 360
MAX_PAIR_GAP = 3        # pairs of key frames at most this many key frames apart


class CameraHeadings:
    """``FrameSource.headings`` for video readers (``self.path``): the camera's own heading per
    frame (a GoPro's CORI track) where the pictures agree with it (``checked_headings``);
    None otherwise. Read once."""

    def headings(self) -> Optional[np.ndarray]:
        """The camera's own heading per frame (a GoPro's CORI track), where the pictures agree
        with it (``engine.sources.camera_heading``); None otherwise. Read once."""
        if getattr(self, "_headings", None) is None:
            headings, note = checked_headings(self, self.path)
            self._headings = (headings,)
            self.heading_note = note
        return self._headings[0]


def picture_turn(a: np.ndarray, b: np.ndarray) -> float:
    """Degrees (-180, 180] the content of panorama ``a`` appears displaced in ``b``, positive
    towards increasing columns (``engine.shift.relative_yaw``'s convention)."""
    import cv2

    def profile(rgb: np.ndarray) -> np.ndarray:
        h = rgb.shape[0]
        band = rgb[int(0.3 * h):int(0.7 * h)].astype(np.float32)
        band = cv2.resize(band, (PROFILE_WIDTH, band.shape[0]), interpolation=cv2.INTER_AREA)
        grad = np.abs(np.diff(band, axis=1, append=band[:, :1]))
        cols = np.concatenate([band.mean(axis=0).T, grad.mean(axis=0).T])     # (6, width)
        cols -= cols.mean(axis=1, keepdims=True)
        return cols / (np.linalg.norm(cols, axis=1, keepdims=True) + 1e-9)

    pa, pb = profile(a), profile(b)
    corr = np.fft.irfft(np.conj(np.fft.rfft(pa, axis=1)) * np.fft.rfft(pb, axis=1), n=PROFILE_WIDTH, axis=1).sum(0)
    d = int(np.argmax(corr))
    deg = d * 360.0 / PROFILE_WIDTH
    return deg - 360.0 if deg > 180.0 else deg


def _wrap(deg: np.ndarray) -> np.ndarray:
    return (np.asarray(deg, dtype=np.float64) + 180.0) % 360.0 - 180.0


def checked_headings(source, path: Path) -> tuple[Optional[np.ndarray], str]:
    """(headings in degrees clockwise per frame of ``source``, a note) from the GPMF CORI track
    of the video at ``path`` when the pictures agree with it (module doc); (None, why) else."""
    from . import gpmf

    try:
        telemetry = gpmf.read_telemetry(Path(path))
    except Exception as err:   # a damaged telemetry track must not stop the pictures being read
        return None, f"GPMF telemetry unreadable ({err})"
    if telemetry is None or telemetry.cori_t.size == 0:
        return None, ""
    stamps = source.stamps()
    yaw = gpmf.headings_at(telemetry, stamps)
    yaw_deg = np.degrees(np.unwrap(yaw))
    keys = _key_frames(source)
    pairs = [(int(keys[i]), int(keys[i + g])) for g in range(1, MAX_PAIR_GAP + 1) for i in range(len(keys) - g)]
    turns = [(abs(yaw_deg[j] - yaw_deg[i]), i, j) for i, j in pairs]
    turns = sorted((t for t in turns if t[0] >= MIN_TURN_DEG), reverse=True)[:PAIRS]
    if len(turns) < 3:
        return None, "GPMF CORI: the camera did not turn enough to check its heading against the pictures"
    frames: dict[int, np.ndarray] = {}
    seen, cori = [], []
    for _, i, j in turns:
        for k in (i, j):
            if k not in frames:
                frames[k] = _small(source, k)
        seen.append(picture_turn(frames[i], frames[j]))
        cori.append(yaw_deg[j] - yaw_deg[i])
    seen, cori = np.asarray(seen), np.asarray(cori)
    for sign in (1.0, -1.0):
        # headings h = sign * yaw (clockwise); the picture moves by -(h_j - h_i)
        agree = np.abs(_wrap(seen + sign * cori)) <= AGREE_DEG
        if agree.mean() >= MIN_AGREEING:
            headings = _wrap(sign * yaw_deg)
            way = "clockwise" if sign > 0 else "counter-clockwise"
            return headings, (f"GPMF CORI yaw ({way} about the camera's z axis), checked against the pictures: "
                              f"{int(agree.sum())} of {len(agree)} turns agree within {AGREE_DEG:g} degrees")
    return None, (f"GPMF CORI: its turns do not match the pictures' ({len(seen)} pairs of key frames), "
                  f"so the image decides the shift")


def _key_frames(source) -> np.ndarray:
    sampler = getattr(source, "sampler", None)
    if sampler is not None:
        return np.flatnonzero(sampler.index.key)
    n = source.frame_count
    return np.arange(0, n, max(1, n // 100))


def _small(source, index: int, width: int = 512) -> np.ndarray:
    sampler = getattr(source, "sampler", None)
    if sampler is not None:
        return sampler.frame_at(index, max_width=width).rgb
    rgb = source.frame_at(index).rgb
    if rgb.shape[1] > width:
        import cv2

        rgb = cv2.resize(rgb, (width, width // 2), interpolation=cv2.INTER_AREA)
    return rgb
