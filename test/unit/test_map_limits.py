"""
The map-size guard.

(mapping/map_limits.py) wherever a map enters, image headers read before decoding, and the core
writers leaving nothing behind on failure.
"""
from __future__ import annotations

import argparse
import os
import struct
from types import SimpleNamespace
import zipfile
import zlib

from helpers import synthetic_map
import numpy as np
import pytest
from ssm_localization import (build_index, load_index, load_map_yaml, MapBuildConfig,
                              occupancy_map_from_msg, OccupancyMap, read_bag, save_index,
                              save_map_yaml, ScanRecord, write_bag, write_results_csv)
from ssm_localization.cli.arguments import add_max_map_cells
from ssm_localization.evaluation.replay import ResultRow
from ssm_localization.mapping import grid
from ssm_localization.mapping.map_image import header_size
from ssm_localization.mapping.map_limits import check_map_cells, MapTooLargeError, MAX_MAP_CELLS
from ssm_localization.ros.parameters import indexer_parameters, localizer_parameters


def _png_header(path, width, height):
    ihdr = struct.pack('>IIBBBBB', width, height, 8, 0, 0, 0, 0)
    crc = struct.pack('>I', zlib.crc32(b'IHDR' + ihdr) & 0xffffffff)
    path.write_bytes(b'\x89PNG\r\n\x1a\n' + struct.pack('>I', 13) + b'IHDR' + ihdr + crc)


def _map_yaml(tmp_path, image):
    (tmp_path / 'm.yaml').write_text(f'image: {image}\nresolution: 0.05\n'
                                     f'origin: [0.0, 0.0, 0.0]\noccupied_thresh: 0.65\n'
                                     f'free_thresh: 0.196\n')
    return tmp_path / 'm.yaml'


def test_check_map_cells():
    check_map_cells(6000, 6000, MAX_MAP_CELLS)          # exactly 36 M: allowed
    check_map_cells(10**6, 10**6, 0)                    # 0: no limit
    with pytest.raises(MapTooLargeError, match='x: map of 6001 x 6000 cells exceeds '
                                               'max_map_cells = 36000000'):
        check_map_cells(6001, 6000, MAX_MAP_CELLS, 'x')
    with pytest.raises(ValueError, match='>= 0'):
        check_map_cells(1, 1, -5)


def test_header_size_of_png_and_pnm(tmp_path):
    _png_header(tmp_path / 'a.png', 123, 45678)
    (tmp_path / 'b.pgm').write_bytes(b'P5\n# a comment\n 640\n# another\n480 255\n')
    (tmp_path / 'c.bmp').write_bytes(b'BM' + b'\0' * 60)
    assert header_size(tmp_path / 'a.png') == (123, 45678)
    assert header_size(tmp_path / 'b.pgm') == (640, 480)
    assert header_size(tmp_path / 'c.bmp') is None


def test_huge_images_are_refused_from_the_header(tmp_path):
    _png_header(tmp_path / 'big.png', 10000, 10000)      # 41 bytes, no pixel data at all
    with pytest.raises(MapTooLargeError, match='10000 x 10000'):
        load_map_yaml(_map_yaml(tmp_path, 'big.png'))
    with pytest.raises(ValueError, match='not a readable image'):   # no limit: Pillow's turn
        load_map_yaml(_map_yaml(tmp_path, 'big.png'), max_cells=0)


def test_small_limit_and_no_limit(tmp_path):
    save_map_yaml(synthetic_map(), tmp_path / 's.yaml')
    with pytest.raises(MapTooLargeError, match='200 x 140 cells exceeds max_map_cells = 1000'):
        load_map_yaml(tmp_path / 's.yaml', max_cells=1000)
    assert load_map_yaml(tmp_path / 's.yaml', max_cells=0).shape == (140, 200)


def _msg(width, height, data):
    q = SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0)
    pose = SimpleNamespace(position=SimpleNamespace(x=0.0, y=0.0, z=0.0), orientation=q)
    info = SimpleNamespace(resolution=0.05, width=width, height=height, origin=pose)
    return SimpleNamespace(header=SimpleNamespace(frame_id='map'), info=info, data=data)


def test_map_messages_are_guarded_before_conversion():
    class Untouchable:     # the data of an oversized map is never looked at
        def __array__(self, *a, **k):
            raise AssertionError('converted')
    with pytest.raises(MapTooLargeError, match='OccupancyGrid message'):
        occupancy_map_from_msg(_msg(10000, 10000, Untouchable()), max_cells=MAX_MAP_CELLS)
    assert occupancy_map_from_msg(_msg(2, 1, [0, 100])).shape == (1, 2)    # default: no limit


def test_grid_building_is_guarded_and_chunking_does_not_change_the_grid(monkeypatch):
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    ranges = (2.0 / np.maximum(np.abs(np.cos(angles)), np.abs(np.sin(angles))))[None]
    with pytest.raises(MapTooLargeError, match='grid at resolution 1e-05 m'):
        grid.build_occupancy_grid(ranges, np.zeros((1, 3)), angles,
                                  MapBuildConfig(resolution=1e-5))
    cfg = MapBuildConfig(resolution=0.05)
    whole, _ = grid.build_occupancy_grid(ranges, np.zeros((1, 3)), angles, cfg)
    monkeypatch.setattr(grid, 'SAMPLES_PER_CHUNK', 500)      # a few beams per batch
    chunked, _ = grid.build_occupancy_grid(ranges, np.zeros((1, 3)), angles, cfg)
    assert np.array_equal(whole, chunked)


@pytest.mark.parametrize('field, value', [('resolution', float('nan')), ('margin', -1.0),
                                          ('occupied_ratio', 2.0), ('chunk_beams', 0)])
def test_map_build_config_is_validated(field, value):
    with pytest.raises(ValueError, match=f'MapBuildConfig.{field}'):
        MapBuildConfig(**{field: value})


def test_occupancy_map_geometry_must_fit_a_map_message():
    with pytest.raises(ValueError, match='float32'):
        OccupancyMap(np.zeros((2, 2), np.int8), 1e300)
    with pytest.raises(ValueError, match='float32'):
        OccupancyMap(np.zeros((2, 2), np.int8), 0.05, (1e39, 0.0, 0.0))


def test_index_files_are_guarded_from_their_headers(tmp_path):
    path = tmp_path / 'bomb.npz'
    with zipfile.ZipFile(path, 'w') as zf, zf.open('map_data.npy', 'w') as fh:
        np.lib.format.write_array_header_1_0(
            fh, {'descr': '|i1', 'fortran_order': False, 'shape': (10000, 10000)})
    with pytest.raises(MapTooLargeError, match='map_data: map of 10000 x 10000'):
        load_index(path)
    index = build_index(synthetic_map())
    save_index(index, tmp_path / 'ok.npz')
    with pytest.raises(MapTooLargeError, match='max_map_cells = 100'):
        load_index(tmp_path / 'ok.npz', max_cells=100)
    assert len(load_index(tmp_path / 'ok.npz')) == len(index)
    assert sorted(os.listdir(tmp_path)) == ['bomb.npz', 'ok.npz']     # no temporary file


def test_bag_maps_are_guarded(tmp_path):
    write_bag(tmp_path / 'b', map=synthetic_map())
    with pytest.raises(MapTooLargeError, match='/map: OccupancyGrid message: map of 200 x 140'):
        read_bag(tmp_path / 'b', require_scans=False, max_map_cells=1000)
    assert read_bag(tmp_path / 'b', require_scans=False).map.shape == (140, 200)
    skipped = read_bag(tmp_path / 'b', require_scans=False, max_map_cells=1000, read_map=False)
    assert skipped.map is None and skipped.topic_counts == {'/map': 1}     # not decoded


def test_failed_writers_leave_nothing_behind(tmp_path):
    (tmp_path / 'file').write_text('x')
    with pytest.raises(ValueError, match='not a directory'):
        save_map_yaml(synthetic_map(), tmp_path / 'file' / 'm.yaml')
    bad = ScanRecord.from_ranges(1.0, np.ones(10), 0.0, 0.1, frame_id=None)   # cannot serialize
    with pytest.raises(Exception):
        write_bag(tmp_path / 'bag', map=synthetic_map(), scans=[bad])

    def rows():
        yield ResultRow(stamp=1.0, x=0.0, y=0.0, yaw=0.0, status='ok', latency_ms=1.0, node=0,
                        score=1.0)
        raise RuntimeError('the replay died')
    with pytest.raises(RuntimeError):
        write_results_csv(rows(), tmp_path / 'results' / 'r.csv')
    assert sorted(os.listdir(tmp_path)) == ['file']


def test_nodes_and_command_line_share_the_default_cap():
    """The nodes' max_map_cells, the command line's --max-map-cells and the library agree."""
    assert indexer_parameters()['max_map_cells'][0] == MAX_MAP_CELLS
    assert localizer_parameters()['max_map_cells'][0] == MAX_MAP_CELLS
    parser = argparse.ArgumentParser()
    add_max_map_cells(parser)
    assert parser.parse_args([]).max_map_cells == MAX_MAP_CELLS
    assert MAX_MAP_CELLS >= 30_000_000         # campus-scale maps (bench index --campus)
