"""bench/campus.py: maps stitched apart on one grid, each site's transform into it."""
from __future__ import annotations

import math

from helpers import shared_data
import numpy as np
import pytest
from ssm_localization import OccupancyMap
from ssm_localization.bench.campus import _pack, campus_map, RESOLUTION, site_queries, stitch
from ssm_localization.transforms import apply


def _map(h: int, w: int, origin, seed: int) -> OccupancyMap:
    rng = np.random.default_rng(seed)
    d = np.where(rng.random((h, w)) < 0.1, 100, 0).astype(np.int8)
    return OccupancyMap(d, RESOLUTION, origin)


def test_packing_keeps_blocks_apart_and_inside():
    sizes = [(40, 70), (90, 20), (30, 30), (10, 120), (55, 55)]
    places, height, width = _pack(sizes, 12, 3)
    boxes = [(r, c, r + h, c + w) for (r, c), (h, w) in zip(places, sizes)]
    for i, (r0, c0, r1, c1) in enumerate(boxes):
        assert r0 >= 3 and c0 >= 3 and r1 <= height - 3 and c1 <= width - 3
        for q0, d0, q1, d1 in boxes[i + 1:]:
            apart_rows = r1 + 12 <= q0 or q1 + 12 <= r0
            apart_cols = c1 + 12 <= d0 or d1 + 12 <= c0
            assert apart_rows or apart_cols


def test_stitched_cells_and_transforms_agree():
    """Each site's cell centres, carried by its transform, are the campus cells it was put in."""
    maps = [('a', _map(40, 60, (-3.0, 2.5, 0.0), 1), True, 20.0),
            ('b', _map(70, 30, (1.05, -4.4, 0.0), 2), False, 0.0)]
    campus = stitch(maps, 2.0, 0.5)
    for (name, grid, _, yaw), site in zip(maps, campus.sites):
        assert site.name == name
        r0, c0, h, w = site.cells
        assert np.array_equal(campus.grid.data[r0:r0 + h, c0:c0 + w], grid.data)
        rows, cols = np.nonzero(grid.data == 100)
        centres = grid.cell_to_world(rows, cols)          # the (turned) building's frame
        turned_back = apply((0.0, 0.0, -math.radians(yaw)), centres)
        there = apply(site.transform, turned_back)
        cr, cc = campus.grid.world_to_cell(there)
        assert np.array_equal(cr, rows + r0) and np.array_equal(cc, cols + c0)
    with pytest.raises(ValueError, match='unturned'):
        stitch([('c', OccupancyMap(np.zeros((4, 4), np.int8), 0.1), True, 0.0)], 1.0, 1.0)


@pytest.mark.slow
def test_campus_queries_land_on_their_buildings_walls(tmp_path):
    """The ground truth carried into the campus puts each building's scans on its walls."""
    data = shared_data()
    campus = campus_map(data, tmp_path)
    assert 25e6 <= campus.grid.data.size <= 30e6
    again = campus_map(data, tmp_path)                  # from the cache
    assert again.sites == campus.sites
    occ = campus.grid.occupied_mask()
    for site in campus.sites:
        q = site_queries(data, site, 5, 1)
        fits = []
        for scan, truth in zip(q.scans, q.truth):
            r = np.asarray(scan.ranges)
            a = scan.angle_min + scan.angle_increment * np.arange(len(r))
            ok = np.isfinite(r) & (r < 15.0)
            pts = apply(truth, np.column_stack((r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok]))))
            rows, cols = campus.grid.world_to_cell(pts)
            near = np.zeros(len(pts), bool)
            for dr in (-2, -1, 0, 1, 2):
                for dc in (-2, -1, 0, 1, 2):
                    rr = np.clip(rows + dr, 0, occ.shape[0] - 1)
                    cc = np.clip(cols + dc, 0, occ.shape[1] - 1)
                    near |= occ[rr, cc]
            fits.append(near.mean())
        assert np.median(fits) > 0.9, site.name
