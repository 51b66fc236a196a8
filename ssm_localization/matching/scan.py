"""
Scan geometry for spectral scan matching (paper section II.A).

ranges -> points (``ranges_to_points``), spatially even downsampling to a point budget
(``downsample_even``), tangents (eq. 1 ``tangents``, and the robust PCA form
``robust_tangents``), PCA normals for ICP (``local_normals``). The per-scan features built from
them live in ``features.py``.
"""
from __future__ import annotations

import math

import numpy as np

from . import kernels


#: longest plausible reading, metres: finite readings beyond it (1e30, say) are garbage, dropped
#: like NaN rather than taken for points thousands of kilometres away
MAX_RANGE = 1000.0
#: scans of more beams are thinned to every k-th beam, the fewest k that leave at most this many
#: (as AMCL's ``max_beams``): the matching works on a few hundred spatially even points anyway,
#: and the cost of the rest (the ray check, the refinement on every endpoint) grows with the
#: beams. Real 2-D lasers give 360-4000 beams; a 10^6-beam message took 6.9 s and 1.2 GB.
MAX_BEAMS = 16384
#: a full turn and a little rounding: an ``angle_min`` beyond it either way is taken for a mistake
#: (degrees for radians, an unset field: REP 103 angles lie within [-pi, pi] or [0, 2 pi]), and
#: so are beams spanning more than it
MAX_ANGLE = 2.0 * math.pi + 1e-3


def sensor_range(range_max: float) -> float:
    """Return a scan's ``range_max`` as the sensor's range (not positive or NaN: unlimited)."""
    return float(range_max) if range_max == range_max and range_max > 0 else math.inf


def scan_geometry_problem(beams: int, angle_min: float, angle_increment: float,
                          range_min: float, range_max: float) -> str | None:
    """
    Return why a LaserScan's fields make no scan (a short reason), or None when they do.

    Checks the fields, not the readings: non-finite angles, an increment of 0 (more than one
    beam), beams spanning more than a full turn, an ``angle_min`` beyond a full turn
    (:data:`MAX_ANGLE`), NaN range limits. A ``range_max`` of 0 or less means no limit
    (:func:`sensor_range`; drivers leave it unset).
    """
    if not math.isfinite(angle_min) or not math.isfinite(angle_increment):
        return f'non-finite angle_min/angle_increment ({angle_min}, {angle_increment})'
    if angle_increment == 0.0 and beams > 1:
        return 'angle_increment is 0'
    if abs(angle_increment) * (beams - 1) > MAX_ANGLE:
        return (f'{beams} beams x angle_increment {angle_increment:g} rad span more than a '
                'full turn')
    if abs(angle_min) > MAX_ANGLE:
        return f'angle_min {angle_min:g} rad lies beyond a full turn (degrees for radians?)'
    if math.isnan(range_min) or math.isnan(range_max):
        return 'range_min/range_max is NaN'
    return None


def thinned(ranges: np.ndarray, angle_increment: float) -> tuple[np.ndarray, float]:
    """Return ``ranges`` and their increment thinned to at most :data:`MAX_BEAMS` beams."""
    step = -(-len(ranges) // MAX_BEAMS)
    if step <= 1:
        return ranges, angle_increment
    return ranges[::step], angle_increment * step


def ranges_to_points(ranges, angle_min: float, angle_increment: float, range_min: float = 0.0,
                     range_max: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """
    Convert LaserScan ranges to ``(points (N, 2), index (N,))`` in the laser frame.

    Beam ``b`` is at ``angle_min + b * angle_increment`` (negative increments allowed). Drops
    NaN, +-inf, non-positive readings, readings beyond :data:`MAX_RANGE` and readings outside
    ``[range_min, range_max]`` (a ``range_max`` of 0 or less: no limit). Points are
    returned in counterclockwise sweep order (increasing beam angle, i.e. reversed for a negative
    increment) so that tangents (eq. 1) have the same orientation for every scanner; ``index``
    holds the beam index of each point in ``ranges``.
    """
    r = np.asarray(ranges, dtype=float)
    if r.ndim != 1:
        raise ValueError(f'ranges: expected a 1-D array, got shape {r.shape}')
    if not (math.isfinite(angle_min) and math.isfinite(angle_increment)):
        raise ValueError('angle_min / angle_increment must be finite')
    if angle_increment == 0.0 and r.size > 1:
        raise ValueError('angle_increment must not be 0')
    idx = np.arange(r.size)
    with np.errstate(invalid='ignore'):
        ok = (np.isfinite(r) & (r > 0.0) & (r >= range_min) & (r <= sensor_range(range_max))
              & (r <= MAX_RANGE))
    idx = idx[ok]
    if angle_increment < 0.0:
        idx = idx[::-1]
    a = angle_min + angle_increment * idx
    rr = r[idx]
    pts = np.column_stack((rr * np.cos(a), rr * np.sin(a)))
    return pts, idx


def sweep_direction(points: np.ndarray) -> float:
    """
    +1 if the points sweep counterclockwise about the origin in array order, else -1.

    Majority vote over consecutive points less than 0.2 rad apart in bearing, so jumps and
    outliers interleaved in scan order do not flip it.
    """
    if len(points) < 2:
        return 1.0
    a, b = points[:-1], points[1:]
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    dot = (a * b).sum(axis=1)
    da = np.arctan2(cross, dot)
    small = np.abs(da) < 0.2
    votes = np.sign(da[small]).sum() if small.any() else np.sign(da).sum()
    return 1.0 if votes >= 0.0 else -1.0


def _voxel_select(points: np.ndarray, cell: float) -> np.ndarray:
    """
    Return one point per occupied square cell of side ``cell``.

    The point nearest the cell's centroid is kept; ascending indices (scan order kept).
    Compiled when numba is there (``kernels.voxel_select``: the same indices, a quarter of the
    time); this numpy form otherwise.
    """
    if kernels.voxel_select is not None:
        return kernels.voxel_select(np.ascontiguousarray(points, dtype=np.float64), float(cell))
    key = np.floor(points / cell).astype(np.int64)
    key -= key.min(axis=0)
    code = key[:, 0] * (int(key[:, 1].max()) + 1) + key[:, 1]
    _, inv = np.unique(code, return_inverse=True)
    inv = inv.ravel()
    cnt = np.bincount(inv)
    cx = np.bincount(inv, points[:, 0]) / cnt
    cy = np.bincount(inv, points[:, 1]) / cnt
    d = (points[:, 0] - cx[inv]) ** 2 + (points[:, 1] - cy[inv]) ** 2
    order = np.lexsort((d, inv))
    first = np.ones(len(order), dtype=bool)
    first[1:] = inv[order[1:]] != inv[order[:-1]]
    return np.sort(order[first])


def downsample_even(points: np.ndarray, budget: int, min_spacing: float = 0.0) -> np.ndarray:
    """
    Return indices (ascending: scan order kept) of at most ``budget`` spatially even points.

    Voxel-grid selection (one point per cell, nearest the cell centroid) with cell side
    ``min_spacing``, grown until at most ``budget`` cells are occupied. Unlike a walk along the
    scan, it is not fooled by outliers interleaved in scan order or by range noise.
    """
    n = len(points)
    budget = max(int(budget), 1)
    if n == 0 or (n <= budget and min_spacing <= 0.0):
        return np.arange(n)
    ext = float(np.ptp(points, axis=0).max())
    if ext <= 0.0:
        return np.arange(min(n, 1))
    # first guess: polyline length (chords of every 3rd point, jumps capped) / budget
    steps = np.linalg.norm(np.diff(points[::3], axis=0), axis=1)
    length = float(np.minimum(steps, 0.5).sum())
    cell = max(min_spacing, 0.9 * length / budget, ext * 1e-4)
    sel = _voxel_select(points, cell)
    for _ in range(12):
        if len(sel) <= budget:
            return sel
        cell *= 1.03 * len(sel) / budget
        sel = _voxel_select(points, cell)
    return sel[np.round(np.linspace(0, len(sel) - 1, budget)).astype(int)]


def tangents(points: np.ndarray, gap: float, direction: float = 1.0) -> np.ndarray:
    """
    Return unit tangents ``u_i = (p_{i+1} - p_{i-1}) / ||.||`` (eq. 1), shape (N, 2).

    A neighbour farther than ``gap`` (a jump to another surface) is replaced by the point itself
    (one-sided difference), as are the missing neighbours at the scan ends. A point isolated on
    both sides gets the sweep direction ``(-y, x)/|p|``. ``direction=-1`` flips all tangents (for
    clockwise sweeps) so that they always follow the counterclockwise sweep.
    """
    p = np.asarray(points, dtype=float)
    n = len(p)
    if n == 0:
        return np.zeros((0, 2))
    nxt = np.vstack((p[1:], p[-1:]))
    prv = np.vstack((p[:1], p[:-1]))
    jn = np.linalg.norm(nxt - p, axis=1) > gap
    jp = np.linalg.norm(p - prv, axis=1) > gap
    nxt[jn] = p[jn]
    prv[jp] = p[jp]
    u = nxt - prv
    norm = np.linalg.norm(u, axis=1)
    bad = norm < 1e-9
    if bad.any():
        sweep = np.column_stack((-p[bad, 1], p[bad, 0]))
        sn = np.linalg.norm(sweep, axis=1)
        sweep[sn < 1e-12] = (1.0, 0.0)
        u[bad] = sweep
        norm[bad] = np.linalg.norm(u[bad], axis=1)
    return direction * u / norm[:, None]


def principal_axes(cxx, cxy, cyy) -> tuple[np.ndarray, np.ndarray]:
    """
    PCA of N 2x2 covariances ``[[cxx, cxy], [cxy, cyy]]`` (batched ``numpy.linalg.eigh``).

    Eigenvalues (N, 2) ascending and the unit principal direction (N, 2), of arbitrary sign.
    """
    cov = np.stack((np.stack((cxx, cxy), axis=-1), np.stack((cxy, cyy), axis=-1)), axis=-2)
    evals, evecs = np.linalg.eigh(cov)
    return evals, np.ascontiguousarray(evecs[..., 1])


def local_normals(points: np.ndarray, radius: float, half_window: int = 4,
                  max_radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """
    Return unit normals (N, 2) by PCA of the neighbours within ``radius``, and weights (N,).

    Neighbours are taken among the ``half_window`` points on each side (scan order) that lie
    within ``radius`` -- grown to 3x the distance to the nearest scan neighbour, at most
    ``max_radius``, where the scan is sparse -- so normals do not bridge gaps. The weight
    ``1 - 3 l_min / l_max`` clipped to
    [0, 1] (1 on a straight wall, 0 at corners or for isolated points) lets ICP ignore
    ill-defined normals.
    """
    p = np.asarray(points, dtype=float)
    n = len(p)
    if n == 0:
        return np.zeros((0, 2)), np.zeros(0)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1) if n > 1 else np.zeros(0)
    near = np.minimum(np.r_[step, np.inf], np.r_[np.inf, step]) if n > 1 else np.zeros(n)
    rad = np.clip(3.0 * near, radius, max(max_radius, radius))
    sxx = np.zeros(n)
    sxy = np.zeros(n)
    syy = np.zeros(n)
    sx = np.zeros(n)
    sy = np.zeros(n)
    cnt = np.zeros(n)
    for k in range(-half_window, half_window + 1):
        lo, hi = max(0, -k), min(n, n - k)       # i in [lo, hi) has neighbour i + k
        if hi <= lo:
            continue
        q = p[lo + k:hi + k]
        ok = np.linalg.norm(q - p[lo:hi], axis=1) <= rad[lo:hi]
        x = np.where(ok, q[:, 0] - p[lo:hi, 0], 0.0)
        y = np.where(ok, q[:, 1] - p[lo:hi, 1], 0.0)
        cnt[lo:hi] += ok
        sx[lo:hi] += x
        sy[lo:hi] += y
        sxx[lo:hi] += x * x
        sxy[lo:hi] += x * y
        syy[lo:hi] += y * y
    mx, my = sx / cnt, sy / cnt
    cxx = sxx / cnt - mx * mx
    cxy = sxy / cnt - mx * my
    cyy = syy / cnt - my * my
    evals, line = principal_axes(cxx, cxy, cyy)
    lmin, lmax = np.maximum(evals[:, 0], 0.0), evals[:, 1]
    normals = np.column_stack((-line[:, 1], line[:, 0]))
    ratio = lmin / np.where(lmax > 0.0, lmax, 1.0)
    w = np.where((cnt >= 3) & (lmax > 0.0), np.clip(1.0 - 3.0 * ratio, 0.0, 1.0), 0.0)
    return normals, w


def length_weights(points: np.ndarray, spacing: float, cap: float) -> np.ndarray:
    """
    Scan length each point stands for.

    The distance to its nearer scan-order neighbour, clipped to ``[spacing, cap]`` (so isolated
    points and jumps count at most ``cap``).
    """
    n = len(points)
    if n < 2:
        return np.full(n, spacing)
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    near = np.minimum(np.r_[step, np.inf], np.r_[np.inf, step])
    return np.clip(near, spacing, max(cap, spacing))


def pair_offsets(points: np.ndarray, context: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(dx, dy)`` = ``context - points`` for every pair, each (N, C)."""
    return (context[None, :, 0] - points[:, None, 0], context[None, :, 1] - points[:, None, 1])


def robust_tangents(points: np.ndarray, context: np.ndarray, radius: float,
                    direction: float = 1.0, offsets=None, min_neighbours: int = 4,
                    max_radius: float = 1.0) -> np.ndarray:
    """
    Return unit tangents (N, 2) at ``points``: PCA of the ``context`` points within ``radius``.

    The noise- and outlier-robust form of eq. 1 used by default: the principal direction of the
    neighbourhood, oriented like ``p_{i+1} - p_{i-1}`` would be for a counterclockwise sweep
    (``cross(p_i, u_i) >= 0``; flipped for ``direction=-1``). Needs the sensor at the origin of
    the points' frame, as scans are. The neighbourhood grows beyond ``radius`` to hold
    ``min_neighbours`` points (up to ``max_radius``): sparse walls seen at grazing angles.
    Points with fewer than 2 neighbours get the sweep direction.
    ``offsets`` may pass precomputed ``(dx, dy)`` = context - points, each (N, C).
    """
    p = np.asarray(points, dtype=float)
    n = len(p)
    if n == 0:
        return np.zeros((0, 2))
    context = np.asarray(context, dtype=float).reshape(-1, 2)
    # radius grown to the min_neighbours-th nearest context point (sparse, grazing walls)
    kk = min(min_neighbours, len(context)) - 1
    if kernels.neighbourhood_moments is not None and len(context) > 0:
        # one compiled pass, the offsets taken pair by pair, the same sums (kernels.py)
        sums = np.empty((n, 6))
        kernels.neighbourhood_moments(np.ascontiguousarray(p), np.ascontiguousarray(context),
                                      kk, radius * radius, max_radius * max_radius, sums)
        cnt, sx, sy, sxx, sxy, syy = sums.T
    else:
        dx, dy = pair_offsets(p, context) if offsets is None else offsets
        d2 = dx * dx + dy * dy
        r2 = np.full(n, radius * radius)
        if kk >= 1:
            kth = np.partition(d2, kk, axis=1)[:, kk]
            r2 = np.clip(kth * 1.0001, radius * radius, max_radius * max_radius)
        m = (d2 <= r2[:, None]).astype(float)
        cnt = m.sum(axis=1)
        sx, sy = (m * dx).sum(axis=1), (m * dy).sum(axis=1)
        sxx, sxy, syy = (m * dx * dx).sum(axis=1), (m * dx * dy).sum(axis=1), \
            (m * dy * dy).sum(axis=1)
    c = np.maximum(cnt, 1.0)
    mx = sx / c
    my = sy / c
    cxx = sxx / c - mx * mx
    cxy = sxy / c - mx * my
    cyy = syy / c - my * my
    u = principal_axes(cxx, cxy, cyy)[1]
    sweep = np.column_stack((-p[:, 1], p[:, 0]))
    bad = (cnt < 2) | ((cxx + cyy) <= 0.0)
    sn = np.linalg.norm(sweep, axis=1)
    sweep = np.where(sn[:, None] > 1e-12, sweep / np.maximum(sn, 1e-12)[:, None], (1.0, 0.0))
    u[bad] = sweep[bad]
    flip = (p[:, 0] * u[:, 1] - p[:, 1] * u[:, 0]) * direction < 0.0
    u[flip] *= -1.0
    return u


def as_points(points_xy, name: str = 'points') -> np.ndarray:
    """Validate an (N, 2) array-like; raises ``ValueError`` naming ``name`` otherwise."""
    p = np.asarray(points_xy, dtype=float)
    if p.size == 0:
        return np.zeros((0, 2))
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f'{name}: expected an (N, 2) array, got shape {p.shape}')
    return p
