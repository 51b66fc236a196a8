"""mapping/specks.py: which occupied cells are specks."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from ssm_localization.mapping.specks import speck_mask


def test_components_of_a_few_cells_are_specks_and_walls_are_not():
    occ = np.zeros((20, 30), bool)
    occ[2, 2:28] = True                      # a wall: 26 cells
    occ[10, 10] = True                       # a lone cell
    occ[12, 15] = occ[13, 16] = True         # two cells touching at a corner: one component
    occ[15:18, 20:23] = True                 # a block of 9 cells
    specks = speck_mask(occ, 5.0)
    assert specks[10, 10] and specks[12, 15] and specks[13, 16]
    assert not specks[2].any() and not specks[15:18, 20:23].any()
    assert specks.sum() == 3 and not (specks & ~occ).any()
    assert speck_mask(occ, 9.0)[15:18, 20:23].all()
    assert speck_mask(occ, 0.6) is None and speck_mask(np.zeros((4, 4), bool), 5.0) is None
    assert speck_mask(occ[:5], 5.0) is None                                  # only the wall


@pytest.mark.parametrize('tile', [7, 16, 1024])
def test_the_specks_are_those_of_scipys_labels_of_the_whole_grid(tile):
    """On random grids, tile by tile: the cells of the 8-connected labels of at most N cells."""
    rng = np.random.default_rng(3)
    for density in (0.05, 0.2, 0.4):
        occ = rng.random((60, 75)) < density
        labels, _ = ndimage.label(occ, structure=np.ones((3, 3), bool))
        sizes = np.bincount(labels.ravel())
        for n in (1, 3, 7):
            expect = occ & (sizes[labels] <= n)
            got = speck_mask(occ, float(n), tile=tile)
            got = np.zeros_like(occ) if got is None else got
            assert np.array_equal(got, expect), (density, n)
