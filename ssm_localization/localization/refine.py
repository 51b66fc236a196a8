"""
Pose refinement against the map itself (beyond the paper).

The paper stops at the RANSAC pose relative to a node's virtual scan, so its accuracy is bounded
by the virtual scan's sampling. Here the winning hypotheses are refined by Gauss-Newton on the
signed distance of the scan endpoints to the map's wall surface (``verify.py`` then checks them
by ray casting).

Where the wall surface lies inside the occupied cells depends on how the map was made: at the
boundary of the occupied cells for scans ray-cast on the same grid (the paper's Table 1 simulation
stops at the first occupied cell's boundary), about half a cell deeper for real scans on maps
built from real scans (beams end anywhere inside a wall cell). ``refine_poses`` can estimate that
offset from the scan itself (``estimate_depth``): one more unknown, the same for every point, with
a weak prior, observable whenever walls are seen from more than one side. Guessing it wrong would
cost about half a cell of accuracy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..transforms import Pose2, rotation, wrap_angle

#: lattice points per cell side of the precomputed signed distance
SUBDIVISION = 2


@dataclass(frozen=True, eq=False)
class SurfaceModel:
    """
    Signed distance to the boundary of occupied cells, shifted by ``depth`` metres.

    The exact distance is precomputed on a lattice of half-cell spacing (``lattice``, float32, in
    cells): the closest point of a union of lattice-aligned boxes to a lattice point is itself a
    lattice point, so two Euclidean distance transforms give it exactly. Between lattice points it
    is interpolated bilinearly (exact along straight axis-aligned walls, within a few hundredths of
    a cell near corners), which makes a query four table look-ups per point.
    """

    origin: Pose2
    resolution: float
    lattice: np.ndarray         # (2H + 1, 2W + 1) float32 signed distance in cells
    depth: float                # metres behind the occupied-cell boundary where the surface lies

    @classmethod
    def from_occupancy(cls, occupied: np.ndarray, resolution: float, origin: Pose2,
                       surface_depth_cells: float = 0.5) -> 'SurfaceModel':
        occupied = np.asarray(occupied, dtype=bool)
        if not occupied.any():
            raise ValueError('map has no occupied cells: nothing to refine against')
        fine = np.repeat(np.repeat(occupied, SUBDIVISION, axis=0), SUBDIVISION, axis=1)
        # a lattice point touches the occupied (free) region when one of its 4 sub-cells does
        occ_v = _touches(fine)
        free_v = _touches(~fine)
        outside = ndimage.distance_transform_edt(~occ_v)
        inside = (ndimage.distance_transform_edt(~free_v) if free_v.any()
                  else np.full(occ_v.shape, float(max(occ_v.shape))))
        sdf = np.where(occ_v & free_v, 0.0, np.where(occ_v, -inside, outside)) / SUBDIVISION
        return cls(origin=tuple(float(v) for v in origin), resolution=float(resolution),
                   lattice=sdf.astype(np.float32),
                   depth=float(surface_depth_cells) * float(resolution))

    def signed_distance(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Signed distance (m) of map-frame points to the wall surface, its gradient, validity.

        Positive in free space, negative inside walls; points off the grid are invalid.
        """
        ox, oy, oyaw = self.origin
        rot = rotation(oyaw)
        scale = SUBDIVISION / self.resolution
        g = (np.asarray(pts, float).reshape(-1, 2) - (ox, oy)) @ rot * scale
        h, w = self.lattice.shape
        j0 = np.floor(g[:, 0]).astype(np.int64)
        i0 = np.floor(g[:, 1]).astype(np.int64)
        valid = (j0 >= 0) & (j0 < w - 1) & (i0 >= 0) & (i0 < h - 1)
        s = np.zeros(len(g))
        grad = np.zeros((len(g), 2))
        if not valid.any():
            return s, grad, valid
        i, j = i0[valid], j0[valid]
        fx, fy = g[valid, 0] - j, g[valid, 1] - i
        flat = self.lattice.ravel()
        k = i * w + j
        a, b, c, d = flat[k], flat[k + 1], flat[k + w], flat[k + w + 1]
        bottom = a + fx * (b - a)
        top = c + fx * (d - c)
        s[valid] = (bottom + fy * (top - bottom)) * self.resolution + self.depth
        dcol = (b - a) + fy * ((d - c) - (b - a))
        drow = top - bottom
        grad[valid] = np.column_stack((dcol, drow)) * SUBDIVISION @ rot.T
        return s, grad, valid

    def explained(self, pts: np.ndarray, offset=0.0, sigma: float = 0.05) -> np.ndarray:
        """
        Return the fraction of a scan explained: ``mean exp(-r^2 / 2 sigma^2)`` over its points.

        ``pts`` (..., N, 2) map-frame points; ``offset`` (...) metres added to their signed
        distances (the wall surface estimated deeper); points off the grid explain nothing.
        """
        pts = np.asarray(pts, float)
        shape = pts.shape[:-1]
        r, _, valid = self.signed_distance(pts)
        r = r.reshape(shape) + np.asarray(offset, float)[..., None]
        e = np.where(valid.reshape(shape), np.exp(-0.5 * (r / sigma) ** 2), 0.0)
        return e.mean(axis=-1) if shape[-1] else np.zeros(shape[:-1])


def _touches(mask: np.ndarray) -> np.ndarray:
    """(H + 1, W + 1) lattice points with at least one of their four cells in ``mask``."""
    pad = np.pad(mask, 1, constant_values=False)
    return pad[:-1, :-1] | pad[:-1, 1:] | pad[1:, :-1] | pad[1:, 1:]


@dataclass(frozen=True)
class RefineResult:
    pose: Pose2                 # refined laser pose in the map frame
    covariance: np.ndarray      # (3, 3) of (x, y, yaw)
    iterations: int
    depth: float = 0.0          # wall surface behind the occupied-cell boundary, metres
    explained: float = 0.0      # mean of exp(-r^2 / 2 sigma^2): the fraction of the scan explained


def refine_pose(surface: SurfaceModel, points: np.ndarray, pose: Pose2, **kwargs) -> RefineResult:
    """Refine one laser pose on the wall surface (see :func:`refine_poses`)."""
    return refine_poses(surface, points, np.array([pose], float), **kwargs)[0]


def refine_poses(surface: SurfaceModel, points: np.ndarray, poses: np.ndarray, *,
                 iterations: int = 12, huber: float = 0.1,
                 truncate: tuple[float, float] = (0.3, 0.1), min_sigma: float = 0.005,
                 estimate_depth: bool = False, depth_prior: float = 0.25,
                 score_sigma: float = 0.05) -> list[RefineResult]:
    """
    Gauss-Newton on ``sum rho(sdf(R p + t) + delta)`` for several laser poses at once (batched).

    The truncation radius shrinks from ``truncate[0]`` to ``truncate[1]`` so clutter and unmapped
    objects drop out; Huber weights soften the rest. The covariance is ``sigma^2 (J^T W J)^-1``
    (the pose block). All hypotheses share one signed-distance look-up per iteration, which is what
    makes refining many hypotheses affordable.
    ``estimate_depth``: ``delta``, the wall surface's offset behind the surface model's own depth,
    is a fourth unknown per pose, starting at 0, with a Gaussian prior of ``depth_prior`` cells
    and kept within the occupied cell; otherwise it stays 0. ``explained`` in each result is
    ``mean exp(-r^2 / 2 score_sigma^2)`` over all points at the final pose.
    """
    pts = np.asarray(points, float).reshape(-1, 2)
    x = np.array(poses, float).reshape(-1, 3)
    n_h, n_p = len(x), len(pts)
    dim = 4 if estimate_depth else 3
    res = surface.resolution
    lo, hi = -surface.depth, res - surface.depth           # the surface stays inside its cell
    delta = np.zeros(n_h)
    prior = (1.0 / (depth_prior * res)) ** 2 if estimate_depth else 0.0
    jtj = np.tile(np.eye(dim), (n_h, 1, 1))
    sigma2 = np.full(n_h, min_sigma ** 2)
    active = np.ones(n_h, dtype=bool)
    done_iters = np.zeros(n_h, dtype=int)
    for it in range(1, iterations + 1):
        if n_p < 3 or not active.any():
            break
        trunc = truncate[0] + (truncate[1] - truncate[0]) * min(
            1.0, (it - 1) / max(iterations // 2, 1))
        world, rel = _transform(x, pts)
        r, g, valid = surface.signed_distance(world.reshape(-1, 2))
        r = r.reshape(n_h, n_p) + delta[:, None]
        g, valid = g.reshape(n_h, n_p, 2), valid.reshape(n_h, n_p)
        use = valid & (np.abs(r) < trunc)
        absr = np.abs(r)
        wts = np.where(use, np.where(absr <= huber, 1.0, huber / np.maximum(absr, 1e-12)), 0.0)
        cols = [g, (g[..., 1] * rel[..., 0] - g[..., 0] * rel[..., 1])[..., None]]
        if estimate_depth:
            cols.append(np.ones((n_h, n_p, 1)))
        jac = np.concatenate(cols, axis=2)
        a = np.einsum('hn,hni,hnj->hij', wts, jac, jac)
        b = np.einsum('hn,hni,hn->hi', wts, jac, r)
        if estimate_depth:      # prior on delta, in units of the current residual variance
            a[:, 3, 3] += prior * sigma2
            b[:, 3] += prior * sigma2 * delta
        enough = use.sum(axis=1) >= 3
        step = np.zeros((n_h, dim))
        ok = active & enough
        if ok.any():
            step[ok] = -np.linalg.solve(a[ok] + 1e-9 * np.eye(dim), b[ok][..., None])[..., 0]
            jtj[ok] = a[ok]
            sigma2[ok] = np.maximum(np.sum(wts[ok] * r[ok] ** 2, axis=1)
                                    / np.maximum(use[ok].sum(axis=1) - dim, 1), min_sigma ** 2)
        x += step[:, :3]
        x[:, 2] = wrap_angle(x[:, 2])
        if estimate_depth:
            delta = np.clip(delta + step[:, 3], lo, hi)
        done_iters[ok] = it
        active &= enough & ((np.hypot(step[:, 0], step[:, 1]) >= 1e-5)
                            | (np.abs(step[:, 2]) >= 1e-6))
    explained = surface.explained(_transform(x, pts)[0], delta, score_sigma)
    out = []
    for k in range(n_h):
        try:
            cov = sigma2[k] * np.linalg.inv(jtj[k])[:3, :3]
        except np.linalg.LinAlgError:
            cov = np.diag([1e3, 1e3, 1e3])
        out.append(RefineResult(
            pose=(float(x[k, 0]), float(x[k, 1]), float(x[k, 2])), covariance=cov,
            iterations=int(done_iters[k]), depth=float(surface.depth + delta[k]),
            explained=float(explained[k])))
    return out


def _transform(poses: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, N, 2) points moved by each pose, and the rotated points (relative to each origin)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    rel = np.stack((c[:, None] * pts[:, 0] - s[:, None] * pts[:, 1],
                    s[:, None] * pts[:, 0] + c[:, None] * pts[:, 1]), axis=2)
    return rel + poses[:, None, :2], rel
