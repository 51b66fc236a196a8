"""raycast.cast_rays: exact grid traversal against analytic ranges (paper Table 1)."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy import ndimage
from ssm_localization.mapping.raycast import (beam_angles, cast_rays, OCCUPIED, OUTSIDE,
                                              RayCaster, SKIP_CAP, skip_table)

RES = 0.05


def _room(h=100, w=160):
    occ = np.zeros((h, w), bool)
    occ[0, :] = occ[-1, :] = True
    occ[:, 0] = occ[:, -1] = True
    return occ


def _analytic(u, v, th, h, w, res):
    """Distance from (u, v) (grid-frame metres) to the inner faces of a one-cell wall."""
    dx, dy = np.cos(th), np.sin(th)
    with np.errstate(divide='ignore', invalid='ignore'):
        tx = np.where(dx > 0, ((w - 1) * res - u) / dx, (res - u) / dx)
        ty = np.where(dy > 0, ((h - 1) * res - v) / dy, (res - v) / dy)
    tx = np.where(np.abs(dx) < 1e-15, np.inf, tx)
    ty = np.where(np.abs(dy) < 1e-15, np.inf, ty)
    return np.minimum(tx, ty)


@pytest.mark.parametrize('origin', [(0.0, 0.0, 0.0), (-1.0, 2.0, 0.3), (5.0, -3.0, -2.0)])
def test_rectangular_room_matches_analytic(origin):
    h, w = 100, 160
    occ = _room(h, w)
    rng = np.random.default_rng(1)
    u = rng.uniform(2, w - 2, 300) * RES
    v = rng.uniform(2, h - 2, 300) * RES
    c, s = math.cos(origin[2]), math.sin(origin[2])
    poses = np.column_stack((origin[0] + c * u - s * v, origin[1] + s * u + c * v,
                             rng.uniform(-math.pi, math.pi, 300)))
    ang = beam_angles(360)
    r = cast_rays(occ, RES, origin, poses, ang, 100.0)
    expect = _analytic(u[:, None], v[:, None], poses[:, 2:3] - origin[2] + ang[None, :], h, w,
                       RES)
    assert r.shape == (300, 360)
    assert np.abs(r - expect).max() < 1e-9  # exact traversal: far below one cell


def test_axis_aligned_and_diagonal_beams():
    occ = _room(50, 50)
    pose = np.array([[25.5 * RES, 25.5 * RES, 0.0]])  # centre of cell (25, 25)
    ang = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2, math.pi / 4])
    r = cast_rays(occ, RES, (0, 0, 0), pose, ang, 10.0)[0]
    assert r[:4] == pytest.approx([(49 - 25.5) * RES, (49 - 25.5) * RES, 24.5 * RES,
                                   24.5 * RES])
    assert r[4] == pytest.approx((49 - 25.5) * RES * math.sqrt(2))


def test_max_range_and_leaving_the_map_give_inf():
    occ = np.zeros((40, 40), bool)
    occ[:, 30] = True  # a wall at x in [1.5, 1.55)
    pose = np.array([[0.5, 1.0, 0.0]])
    r = cast_rays(occ, RES, (0, 0, 0), pose, np.array([0.0, math.pi]), 0.9)
    assert np.isinf(r).all()  # wall at 1.0 m > max_range; backwards leaves the map
    r = cast_rays(occ, RES, (0, 0, 0), pose, np.array([0.0]), 1.0)
    assert r[0, 0] == pytest.approx(1.0)  # exactly at max_range counts


def test_sensor_inside_obstacle_reads_zero_and_outside_map_enters():
    occ = np.zeros((20, 20), bool)
    occ[10, 10] = True
    inside = [[10.5 * RES, 10.5 * RES, 0.3]]
    assert cast_rays(occ, RES, (0, 0, 0), inside, np.array([0.0]), 5.0)[0, 0] == 0.0
    # from outside the grid the beam enters and hits the cell's left face at x = 0.5
    outside = [[-1.0, 10.5 * RES, 0.0]]
    assert cast_rays(occ, RES, (0, 0, 0), outside, np.array([0.0]), 5.0)[0, 0] == \
        pytest.approx(1.5)


def test_empty_inputs():
    occ = _room()
    assert cast_rays(occ, RES, (0, 0, 0), np.zeros((0, 3)), beam_angles(8), 5.0).shape == (0, 8)
    assert cast_rays(occ, RES, (0, 0, 0), [[1, 1, 0]], np.zeros(0), 5.0).shape == (1, 0)
    nan = cast_rays(occ, RES, (0, 0, 0), [[np.nan, 1, 0]], beam_angles(4), 5.0)
    assert np.isinf(nan).all()
    with pytest.raises(ValueError):
        cast_rays(np.zeros(5, bool), RES, (0, 0, 0), [[0, 0, 0]], beam_angles(4), 5.0)


def test_beam_angles_counterclockwise_from_minus_pi():
    a = beam_angles(4)
    assert a == pytest.approx([-math.pi, -math.pi / 2, 0.0, math.pi / 2])
    with pytest.raises(ValueError):
        beam_angles(0)


def test_fast_enough_for_500_poses_x_360_beams():
    rng = np.random.default_rng(0)
    occ = rng.random((400, 600)) < 0.01
    occ |= _room(400, 600)
    poses = np.column_stack((rng.uniform(0.5, 29.5, 500), rng.uniform(0.5, 19.5, 500),
                             rng.uniform(-3, 3, 500)))
    t0 = time.perf_counter()
    r = cast_rays(occ, RES, (0, 0, 0), poses, beam_angles(360), 20.0)
    assert time.perf_counter() - t0 < 3.0
    assert np.isfinite(r).mean() > 0.99


def _brute_force(occ, res, origin, poses, angles, max_range):
    """Independent reference: slab intersection of every ray with every occupied cell square."""
    rows, cols = np.nonzero(occ)
    ox, oy, oyaw = origin
    c, s = math.cos(oyaw), math.sin(oyaw)
    dx, dy = poses[:, 0] - ox, poses[:, 1] - oy
    gx = ((c * dx + s * dy) / res)[:, None, None]
    gy = ((-s * dx + c * dy) / res)[:, None, None]
    th = (poses[:, 2] - oyaw)[:, None, None] + angles[None, :, None]
    ux, uy = np.cos(th), np.sin(th)
    with np.errstate(divide='ignore', invalid='ignore'):
        ax, bx = (cols - gx) / ux, (cols + 1 - gx) / ux
        ay, by = (rows - gy) / uy, (rows + 1 - gy) / uy
    # rays parallel to an axis: inside the slab or not
    inx = (gx >= cols) & (gx <= cols + 1)
    iny = (gy >= rows) & (gy <= rows + 1)
    lo_x = np.where(ux == 0, np.where(inx, -np.inf, np.inf), np.minimum(ax, bx))
    hi_x = np.where(ux == 0, np.where(inx, np.inf, -np.inf), np.maximum(ax, bx))
    lo_y = np.where(uy == 0, np.where(iny, -np.inf, np.inf), np.minimum(ay, by))
    hi_y = np.where(uy == 0, np.where(iny, np.inf, -np.inf), np.maximum(ay, by))
    t_in = np.maximum(np.maximum(lo_x, lo_y), 0.0)
    t_out = np.minimum(hi_x, hi_y)
    t = np.where(t_in <= t_out, t_in, np.inf).min(axis=2) * res
    return np.where(t <= max_range, t, np.inf)


@pytest.mark.parametrize('seed', range(6))
def test_random_grids_match_brute_force(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(15, 60, 2)
    occ = rng.random((h, w)) < (0.005, 0.02, 0.08)[seed % 3]
    origin = (rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-3, 3))
    c, s = math.cos(origin[2]), math.sin(origin[2])
    u, v = rng.uniform(-0.5, w * RES + 0.5, 40), rng.uniform(-0.5, h * RES + 0.5, 40)
    poses = np.column_stack((origin[0] + c * u - s * v, origin[1] + s * u + c * v,
                             rng.uniform(-math.pi, math.pi, 40)))
    angles = np.concatenate((beam_angles(72), [0.0, math.pi / 2]))
    max_range = float(rng.uniform(0.5, 4.0))
    expect = _brute_force(occ, RES, origin, poses, angles, max_range)
    got = RayCaster(occ, RES, origin).cast(poses, angles, max_range)
    plain = RayCaster(occ, RES, origin, accelerate=False).cast(poses, angles, max_range)
    assert np.array_equal(np.isinf(plain), np.isinf(expect))
    assert np.abs(plain[np.isfinite(expect)] - expect[np.isfinite(expect)]).max(initial=0.0) < 1e-9
    assert np.array_equal(np.isinf(got), np.isinf(expect))
    fin = np.isfinite(expect)
    assert np.abs(got[fin] - expect[fin]).max(initial=0.0) < 1e-9


@pytest.mark.parametrize('seed', range(4))
def test_plain_python_tail_gives_the_same_ranges_as_the_vectorized_loop(seed):
    """Rays finished one by one (``tail_rays``) must read exactly what the numpy loop reads."""
    rng = np.random.default_rng(100 + seed)
    h, w = rng.integers(80, 200, 2)
    occ = rng.random((h, w)) < (0.002, 0.01, 0.03, 0.0005)[seed]
    occ |= _room(h, w)
    origin = (rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-3, 3))
    c, s = math.cos(origin[2]), math.sin(origin[2])
    u, v = rng.uniform(0, w * RES, 30), rng.uniform(0, h * RES, 30)
    poses = np.column_stack((origin[0] + c * u - s * v, origin[1] + s * u + c * v,
                             rng.uniform(-math.pi, math.pi, 30)))
    angles = np.concatenate((beam_angles(90), [0.0, math.pi / 2, math.pi / 4]))
    vectorized, scalar, mixed = (RayCaster(occ, RES, origin) for _ in range(3))
    vectorized.tail_rays, scalar.tail_rays, mixed.tail_rays = 0, 10 ** 9, 200
    a = vectorized.cast(poses, angles, 12.0)
    assert np.isfinite(a).mean() > 0.9
    for caster in (scalar, mixed):
        b = caster.cast(poses, angles, 12.0)
        assert np.array_equal(np.isinf(a), np.isinf(b))
        assert np.array_equal(a[np.isfinite(a)], b[np.isfinite(b)])


def test_cell_codes_are_exact_squared_distances_clamped():
    """The caster's codes: occupied, outside, or scipy's squared distance (cells^2) clamped."""
    rng = np.random.default_rng(5)
    occ = rng.random((700, 650)) < 0.0004           # far apart: distances beyond the clamp
    occ[300:310, 20:400] = True
    caster = RayCaster(occ, RES, (0.0, 0.0, 0.0))
    code = caster._code.reshape(702, 652)
    padded = np.zeros((702, 652), bool)
    padded[1:-1, 1:-1] = occ
    k = np.rint(ndimage.distance_transform_edt(~padded) ** 2)
    inner = code[1:-1, 1:-1]
    assert (inner[occ] == OCCUPIED).all()
    assert np.array_equal(inner[~occ], np.minimum(k[1:-1, 1:-1][~occ], SKIP_CAP))
    assert (code[0] == OUTSIDE).all() and (code[:, -1] == OUTSIDE).all()
    # the jumps are those of the float32 distance transform they replace
    edt = np.sqrt(np.arange(SKIP_CAP + 1.0)).astype(np.float32)
    expect = np.maximum(edt - np.float32(math.sqrt(2.0) + 1e-3), 0)
    assert np.array_equal(skip_table()[:SKIP_CAP + 1], expect)
    assert caster._code.dtype == np.uint16 and caster._code.nbytes == 702 * 652 * 2


def test_jumps_do_not_change_ranges_on_an_open_map():
    """Beams across open space longer than the clamp: the same ranges as without jumps."""
    occ = _room(900, 900)
    occ[450, 450] = True
    rng = np.random.default_rng(2)
    poses = np.column_stack((rng.uniform(2, 43, 50), rng.uniform(2, 43, 50),
                             rng.uniform(-math.pi, math.pi, 50)))
    ang = beam_angles(90)
    fast = cast_rays(occ, RES, (0, 0, 0), poses, ang, 100.0)
    plain = RayCaster(occ, RES, (0, 0, 0), accelerate=False).cast(poses, ang, 100.0)
    assert np.abs(fast - plain).max() < 1e-9


@pytest.mark.parametrize('tail_rays', [0, 10 ** 9])
def test_a_ray_along_a_cell_boundary_ends(within_seconds, tail_rays):
    """
    From a cell corner at 180 degrees, ``y0 + vy t`` rounds back onto the boundary after a jump.

    Its next crossing then lay behind the ray, which stepped back to it and jumped again for
    ever when a wall three cells off its path stopped the jumps (found ray-casting the search's
    leaves on the 30 M-cell office: 0.1 m search cells over 0.05 m map cells, a beam at -pi).
    """
    occ = _room(64, 64)
    occ[35, 40:44] = True                 # three cells above the ray's row
    corners = [(50, 32), (50, 20), (30, 44), (12, 33)]
    poses = np.array([(c * RES, r * RES, yaw) for c, r in corners
                      for yaw in (0.0, math.pi / 2, math.pi, -math.pi / 2)])
    angles = np.array([-math.pi, -math.pi / 2, 0.0, math.pi / 2, math.pi])
    caster = RayCaster(occ, RES, (0.0, 0.0, 0.0))
    caster.tail_rays = tail_rays
    got = caster.cast(poses, angles, 30.0)
    expect = _brute_force(occ, RES, (0.0, 0.0, 0.0), poses, angles, 30.0)
    assert np.abs(got - expect).max() < 1e-9
    assert got[0, 0] == pytest.approx(2.45)           # from (2.5, 1.6) to the wall's face at 0.05
