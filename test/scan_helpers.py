"""Test helpers: synthetic laser scans of a polygonal room."""
from __future__ import annotations

import numpy as np

# an irregular room (metres) with a pillar and a niche: no symmetry
ROOM = [
    [(-4.0, -3.0), (5.0, -3.0), (5.0, -1.0), (6.5, -1.0), (6.5, 1.5), (5.0, 1.5), (5.0, 4.0),
     (1.0, 4.0), (0.0, 2.5), (-2.5, 4.0), (-4.0, 4.0), (-4.0, -3.0)],
    [(2.0, 0.5), (2.6, 0.5), (2.6, 1.3), (2.0, 1.3), (2.0, 0.5)],
]


def segments(polys=ROOM) -> np.ndarray:
    out = []
    for poly in polys:
        p = np.asarray(poly, float)
        out.append(np.hstack((p[:-1], p[1:])))
    return np.vstack(out)


def raycast(pose, n_beams=360, fov=2 * np.pi, max_range=30.0, polys=ROOM):
    """
    Ranges (n_beams,) of a scanner at ``pose``.

    (x, y, yaw) in the room, counterclockwise from ``-fov/2``; ``inf`` where nothing is hit.
    Returns (ranges, angle_min, angle_increment).
    """
    segs = segments(polys)
    inc = fov / n_beams
    a_min = -fov / 2 if fov < 2 * np.pi else -np.pi
    ang = a_min + inc * np.arange(n_beams) + pose[2]
    d = np.column_stack((np.cos(ang), np.sin(ang)))                    # (B, 2)
    o = np.asarray(pose[:2], float)
    a = segs[:, :2] - o
    e = segs[:, 2:] - segs[:, :2]                                      # (S, 2)
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide='ignore', invalid='ignore'):
        t = (a[None, :, 0] * e[None, :, 1] - a[None, :, 1] * e[None, :, 0]) / den
        u = (a[None, :, 0] * d[:, None, 1] - a[None, :, 1] * d[:, None, 0]) / den
    hit = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    r = np.where(hit, t, np.inf).min(axis=1)
    r[r > max_range] = np.inf
    return r, a_min, inc


def room_scan(pose, n_beams=360, fov=2 * np.pi, noise=0.0, rng=None):
    """Points (N, 2) in the scanner frame, counterclockwise scan order."""
    r, a_min, inc = raycast(pose, n_beams, fov)
    if noise:
        r = r + (rng or np.random.default_rng(0)).normal(0.0, noise, r.shape)
    a = a_min + inc * np.arange(n_beams)
    ok = np.isfinite(r)
    return np.column_stack((r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])))


def pose_error(est, truth):
    e = np.asarray(est, float) - np.asarray(truth, float)
    e[2] = (e[2] + np.pi) % (2 * np.pi) - np.pi
    return float(np.hypot(e[0], e[1])), float(abs(e[2]))
