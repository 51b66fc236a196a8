"""mapping/distance.py: lean distance transforms against scipy's, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from ssm_localization.mapping.distance import (clamped_squared_distance, distances_from,
                                               feature_transform)


def _targets(seed: int):
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 260, 2))
    t = rng.random((h, w)) < rng.choice([0.0005, 0.01, 0.3])
    t[rng.integers(h), rng.integers(w)] = True
    return t


@pytest.mark.parametrize('seed', range(12))
def test_feature_transform_and_distances_are_scipys(seed):
    t = _targets(seed)
    dist, feat = ndimage.distance_transform_edt(~t, return_indices=True)
    ft = feature_transform(t)
    assert ft.dtype == np.int32 and np.array_equal(ft, feat)
    assert np.array_equal(distances_from(ft), dist)       # bit for bit


@pytest.mark.parametrize('seed', range(6))
def test_clamped_squared_distance_is_exact_up_to_the_limit(seed):
    t = _targets(seed)
    exact = np.rint(ndimage.distance_transform_edt(~t) ** 2).astype(np.int64)
    for limit in (0, 1, 6, 40, 300):
        for block in (5, 64, 1024):       # blocks smaller and larger than the halo
            got = clamped_squared_distance(t, limit, np.int32, block)
            assert np.array_equal(got, np.minimum(exact, limit * limit)), (limit, block)


def test_clamped_squared_distance_without_targets_and_bad_limits():
    assert (clamped_squared_distance(np.zeros((30, 40), bool), 7, np.uint8, 16) == 49).all()
    with pytest.raises(ValueError, match='cannot hold'):
        clamped_squared_distance(np.ones((3, 3), bool), 16, np.uint8)
    with pytest.raises(ValueError, match='>= 0'):
        clamped_squared_distance(np.ones((3, 3), bool), -1)
