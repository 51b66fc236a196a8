"""bench/places.py: the real maps of `bench localize` built coarser, thick-walled or specked."""
from __future__ import annotations

import numpy as np
import pytest
from ssm_localization.bench.places import MAP_RESOLUTION, MapVariant
from ssm_localization.mapping.map_io import OccupancyMap


def _room() -> OccupancyMap:
    d = np.full((40, 60), -1, np.int8)
    d[5:35, 5:55] = 0
    d[5, 5:55] = d[34, 5:55] = 100
    d[5:35, 5] = d[5:35, 54] = 100
    return OccupancyMap(d, 0.05, (1.0, -2.0, 0.0))


def test_the_default_variant_is_the_map_as_built():
    room = _room()
    assert MapVariant().resolution == MAP_RESOLUTION == 0.05
    assert MapVariant().degrade(room) is room
    assert str(MapVariant()) == '0.05 m cells'


def test_grown_walls_are_a_cell_thicker_on_each_side_per_cell_grown():
    room = _room()
    for cells in (1, 2):
        grown = MapVariant(dilate=cells).degrade(room)
        assert grown.resolution == room.resolution and grown.origin == room.origin
        occ = grown.data >= 65
        assert occ[5 - cells:6 + cells, 20].all() and not occ[6 + cells, 20]
        assert (grown.data[room.data >= 65] == 100).all()          # nothing taken away
    assert 'walls grown by 1 cells' in str(MapVariant(dilate=1))


def test_specks_occupy_the_given_share_of_the_free_cells_the_same_every_time():
    room = _room()
    free = int((room.data == 0).sum())
    a = MapVariant(specks=0.01).degrade(room)
    b = MapVariant(specks=0.01).degrade(room)
    assert np.array_equal(a.data, b.data)
    assert int((room.data == 0).sum() - (a.data == 0).sum()) == round(0.01 * free)
    assert ((a.data != room.data) <= (room.data == 0)).all()       # only free cells change


@pytest.mark.parametrize('bad', [{'resolution': 0.0}, {'dilate': -1}, {'specks': 1.0},
                                 {'specks': -0.1}])
def test_a_variant_out_of_range_is_refused(bad):
    with pytest.raises(ValueError, match='MapVariant'):
        MapVariant(**bad)


def test_random_kidnaps_refuse_a_log_too_short_or_too_still():
    """Too few scans, or none 1 m apart: an error naming the fix, not a loop for ever."""
    from types import SimpleNamespace
    from ssm_localization.bench.track import random_kidnaps

    class Seq(SimpleNamespace):
        def __len__(self):
            return len(self.truth)

    with pytest.raises(ValueError, match='9 scans are too few for random kidnaps'):
        random_kidnaps(None, None, Seq(name='short', truth=[(0.0, 0.0, 0.0)] * 9), 1, 0)
    with pytest.raises(ValueError, match='no two of its 40 scans 1 m apart'):
        random_kidnaps(None, None, Seq(name='still', truth=[(0.0, 0.0, 0.0)] * 40), 1, 0)


def test_cached_real_maps_are_named_by_their_cell_size_to_the_micrometre(tmp_path):
    """49.6 mm and 50.4 mm are two maps, not one cache file (both once rounded to 50 mm)."""
    from ssm_localization.bench.places import real_grid
    from ssm_localization.mapping.map_io import save_map_yaml
    data = np.zeros((20, 20), np.int8)
    data[0, :] = 100
    for res in (0.0496, 0.0504):
        save_map_yaml(OccupancyMap(data, res), tmp_path / f'hall_even_{res * 1000:g}mm.yaml')
    for res in (0.0496, 0.0504):
        assert real_grid(tmp_path, tmp_path, 'hall', resolution=res).resolution == res
