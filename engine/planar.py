"""Planar poses (x, y, heading in radians; rows of an (..., 3) array) and point-set fits.

The algebra of SE(2) the pose graph and its metric factors share: one pose seen from another,
a relative pose applied, steps composed with their covariance, a path dead-reckoned, and the
rigid motion or scale that maps one planar point set onto another.
"""

from __future__ import annotations

from typing import Optional

import numpy as np


def relative(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Pose q seen from pose p."""
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    dx, dy = q[..., 0] - p[..., 0], q[..., 1] - p[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, q[..., 2] - p[..., 2]], axis=-1)


def apply(p: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """The pose ``rel`` (seen from ``p``) in ``p``'s frame: the inverse of ``relative``."""
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    return np.stack([p[..., 0] + c * rel[..., 0] - s * rel[..., 1],
                     p[..., 1] + s * rel[..., 0] + c * rel[..., 1], p[..., 2] + rel[..., 2]], axis=-1)


def compose(dx, dy, dt, sxy, st):
    """One relative pose and its covariance (in the end's frame) for steps applied in order."""
    x = y = th = 0.0
    cov = np.zeros((3, 3))
    for i in range(dx.size):
        c, s = np.cos(dt[i]), np.sin(dt[i])
        # Adjoint of the inverse step: how the pose so far looks from the new end.
        px, py = dx[i], dy[i]
        ad = np.array([[c, s, s * px - c * py], [-s, c, c * px + s * py], [0.0, 0.0, 1.0]])
        cov = ad @ cov @ ad.T + np.diag([sxy[i] ** 2, sxy[i] ** 2, st[i] ** 2])
        ct, sn = np.cos(th), np.sin(th)
        x, y, th = x + ct * px - sn * py, y + sn * px + ct * py, th + dt[i]
    return (x, y, th), cov


def chains(chain_starts, m: int) -> list[tuple[int, int]]:
    """(first, end) of every chain of ``m`` nodes, from the first node of each."""
    bounds = [int(s) for s in chain_starts] + [m]
    return list(zip(bounds[:-1], bounds[1:]))


def dead_reckoning(dx, dy, dt, m: int, chain_starts) -> np.ndarray:
    """(m, 3) poses summed along each chain of steps from its first node (at the origin)."""
    poses = np.zeros((m, 3))
    for s, e in chains(chain_starts, m):
        th = np.concatenate([[0.0], np.cumsum(dt[s:e - 1])])
        wx = np.cos(th[:-1]) * dx[s:e - 1] - np.sin(th[:-1]) * dy[s:e - 1]
        wy = np.sin(th[:-1]) * dx[s:e - 1] + np.cos(th[:-1]) * dy[s:e - 1]
        poses[s:e, 0] = np.concatenate([[0.0], np.cumsum(wx)])
        poses[s:e, 1] = np.concatenate([[0.0], np.cumsum(wy)])
        poses[s:e, 2] = th
    return poses


def rigid_fit(p: np.ndarray, q: np.ndarray):
    """(turn, rotation, shift) of the rigid motion that maps points ``p`` onto ``q`` best."""
    pc, qc = p - p.mean(axis=0), q - q.mean(axis=0)
    turn = float(np.arctan2(np.sum(pc[:, 0] * qc[:, 1] - pc[:, 1] * qc[:, 0]),
                            np.sum(pc[:, 0] * qc[:, 0] + pc[:, 1] * qc[:, 1]))) if p.shape[0] > 1 else 0.0
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    return turn, rot, q.mean(axis=0) - rot @ p.mean(axis=0)


def similarity_scale(p: np.ndarray, q: np.ndarray) -> Optional[float]:
    """The scale of the similarity that maps points ``p`` onto ``q`` best (least squares in
    ``q``), or None when ``p`` spans less than one unit."""
    if p.shape[0] < 2:
        return None
    pc = (p[:, 0] - p[:, 0].mean()) + 1j * (p[:, 1] - p[:, 1].mean())
    qc = (q[:, 0] - q[:, 0].mean()) + 1j * (q[:, 1] - q[:, 1].mean())
    spread = float(np.sum(np.abs(pc) ** 2))
    if spread < 1.0 or np.ptp(p[:, 0]) ** 2 + np.ptp(p[:, 1]) ** 2 < 1.0:
        return None
    return float(np.abs(np.sum(np.conj(pc) * qc)) / spread)
