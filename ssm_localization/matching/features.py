"""
The per-scan features the matcher precomputes once (paper section II.A-B).

``ScanFeatures`` holds plain numpy arrays (npz-friendly, no pickles: ``to_arrays`` /
``from_arrays``, as a map index stores them); ``prepare_scan`` builds them from a scan's points.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cached_property
import math

import numpy as np
from scipy.spatial import cKDTree

from . import kernels
from .descriptors import shape_context
from .pairwise import angle_table, distance_table
from .scan import (as_points, downsample_even, length_weights, local_normals, pair_offsets,
                   robust_tangents, sweep_direction, tangents)
from ..config.matcher import MatcherConfig


@dataclass(frozen=True, eq=False)
class ScanFeatures:
    """
    What the matcher needs of one scan; plain numpy arrays (npz-friendly, no pickle).

    ``points (N, 2)`` the downsampled points (scan frame), ``tangents (N, 2)`` (eq. 1),
    ``descriptors (N, D)`` (rotation-invariant local descriptors, ``descriptors.py``),
    ``source_index (N,)`` indices into the caller's point array; for the ICP refinement a denser
    set ``fine_points (P, 2)`` with PCA ``fine_normals (P, 2)`` and ``fine_weights (P,)``. The
    pairwise tables of eq. 2 (``dist``, ``angle``) are rebuilt lazily on first use and cached
    (not stored).
    """

    points: np.ndarray
    tangents: np.ndarray
    descriptors: np.ndarray
    source_index: np.ndarray
    fine_points: np.ndarray
    fine_normals: np.ndarray
    fine_weights: np.ndarray

    def __len__(self) -> int:
        return len(self.points)

    @property
    def normals(self) -> np.ndarray:
        """Left normals of the tangents (towards the sensor for a counterclockwise sweep)."""
        return np.column_stack((-self.tangents[:, 1], self.tangents[:, 0]))

    @cached_property
    def is_degenerate(self) -> bool:
        """Fewer than 3 points or (nearly) collinear points: the pose is not observable."""
        if len(self.points) < 3:
            return True
        c = self.points - self.points.mean(axis=0)
        s = np.linalg.svd(c, compute_uv=False)
        return bool(s[1] < 1e-3 * max(s[0], 1e-12) or s[1] / math.sqrt(len(c)) < 1e-3)

    @cached_property
    def dist(self) -> np.ndarray:
        """``d_ij`` of eq. 2, (N, N) float32."""
        return distance_table(self.points)

    @cached_property
    def angle(self) -> np.ndarray:
        """``theta_ij = arccos(u_i . u_j)`` of eq. 2, (N, N) float32."""
        return angle_table(self.tangents)

    @cached_property
    def fine_tree(self) -> cKDTree:
        """k-d tree over ``fine_points`` for ICP, built on first use."""
        return cKDTree(self.fine_points)

    def to_arrays(self, prefix: str = '') -> dict[str, np.ndarray]:
        """Return the stored fields as ``{prefix + name: array}`` (for ``np.savez``)."""
        return {prefix + f.name: np.asarray(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_arrays(cls, arrays, prefix: str = '') -> 'ScanFeatures':
        """Inverse of ``to_arrays``; ``arrays`` is any mapping (e.g. an ``np.load`` result)."""
        try:
            vals = {f.name: np.asarray(arrays[prefix + f.name]) for f in fields(cls)}
        except KeyError as exc:
            raise ValueError(f'ScanFeatures: missing array {exc}') from None
        n = len(vals['points'])
        nf = len(vals['fine_points'])
        if vals['points'].shape != (n, 2) or vals['tangents'].shape != (n, 2) \
                or len(vals['descriptors']) != n or vals['source_index'].shape != (n,) \
                or vals['fine_points'].shape != (nf, 2) or vals['fine_normals'].shape != (nf, 2) \
                or vals['fine_weights'].shape != (nf,):
            raise ValueError('ScanFeatures: inconsistent array shapes')
        for name in ('points', 'tangents', 'fine_points', 'fine_normals', 'fine_weights'):
            vals[name] = vals[name].astype(float)
        vals['source_index'] = vals['source_index'].astype(np.int64)
        return cls(**vals)


def prepare_scan(points_xy, config: MatcherConfig | None = None, *,
                 fine: bool = True) -> ScanFeatures:
    """
    Prepare one scan: downsample, tangents (eq. 1) and descriptors.

    Points in scan order, metres, sensor at the origin.

    Non-finite points are dropped; fewer than 3 points give features with ``is_degenerate``
    (the matcher then returns an empty result). Three spatially even subsets are taken: the
    matching points (``config.max_points``), a context set (``config.context_spacing``) for
    tangents and descriptors, and the denser ICP set (``config.icp_max_points``). With ``fine``
    False the ICP set is left empty (the scan is only voted with or matched without ICP: the
    map index's nodes, ``mapping/index.py``).
    """
    config = config or MatcherConfig()
    p = as_points(points_xy)
    src = np.flatnonzero(np.isfinite(p).all(axis=1))
    p = p[src]
    keep = downsample_even(p, config.max_points, config.min_spacing)
    pts = p[keep]
    src = src[keep]
    ctx = p[downsample_even(p, 4 * config.max_points, config.context_spacing)]
    # the numpy forms of the tangents and the descriptors share the (N, C) offsets; the
    # compiled loops (kernels.py) take them pair by pair and need no such arrays
    offsets = None if kernels.neighbourhood_moments is not None else pair_offsets(pts, ctx)
    if config.tangent_method == 'eq1':
        u = tangents(pts, config.gap, sweep_direction(p))
    else:
        # oriented geometrically (counterclockwise about the sensor): no scan order involved,
        # so interleaved outliers or a clockwise scanner cannot flip it
        u = robust_tangents(pts, ctx, config.tangent_radius, 1.0, offsets)
    cw = length_weights(ctx, config.context_spacing, config.length_cap) \
        if config.length_cap > 0 else None
    desc = shape_context(pts, u, config.desc_radius, config.desc_radial_bins,
                         config.desc_angular_bins, context=ctx, offsets=offsets, weights=cw)
    if fine:
        dense = p[downsample_even(p, config.icp_max_points, config.icp_min_spacing)]
        fn, fw = local_normals(dense, config.normal_radius)
    else:
        dense, fn, fw = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    return ScanFeatures(points=pts, tangents=u, descriptors=desc, source_index=src,
                        fine_points=dense, fine_normals=fn, fine_weights=fw)
