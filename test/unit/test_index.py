"""index: build, save/load (versioned npz, no pickle), parameters, CLI, bench helpers."""
from __future__ import annotations

import argparse
import dataclasses
import io
import math
from pathlib import Path
import re
import zipfile

from helpers import shared_data
import numpy as np
import pytest
from ssm_localization import (build_index, IndexConfig, load_index, load_index_config,
                              load_map_yaml, OccupancyMap, save_index, save_map_yaml,
                              TopologyConfig)
from ssm_localization import GlobalLocalizer
from ssm_localization.bench.memory import format_layers, LayerMeter
from ssm_localization.config import config_from_json, config_to_json
from ssm_localization.localization.map_layers import LAYER_NAMES
from ssm_localization.mapping.index import FORMAT_VERSION, INDEX_LAYERS
from ssm_localization.mapping.raycast import cast_rays
from ssm_localization.mapping.topology import NodeKind
from ssm_localization.matching.features import prepare_scan

RES = 0.05


def _rooms(extra: bool = False) -> OccupancyMap:
    """8 m x 5 m, two rooms joined by a door, some furniture."""
    d = np.zeros((100, 160), np.int8)
    d[:2, :] = d[-2:, :] = 100
    d[:, :2] = d[:, -2:] = 100
    d[:, 80:82] = 100
    d[40:60, 80:82] = 0               # door
    d[70:76, 20:40] = 100
    d[15:25, 120:126] = 100
    if extra:
        d[50:54, 50:54] = 100
    return OccupancyMap(d, RES, (-1.0, 0.5, 0.0))


@pytest.fixture(scope='module')
def built():
    cfg = IndexConfig(sensor_pose=(0.1, 0.05, 0.2), beams=180, max_range=12.0)
    calls = []
    index = build_index(_rooms(), cfg, progress=lambda d, t, label: calls.append((d, t, label)))
    return index, calls


def test_build_index_shapes_and_sensor_pose(built):
    index, _ = built
    k = len(index)
    assert k >= 3
    assert index.node_xy.shape == (k, 2) and index.node_kind.shape == (k,)
    assert index.ranges.shape == (k, 180) and index.beam_angles.shape == (180,)
    assert len(index.features) == k
    # Table 1: laser pose = node pose (x, y, 0) composed with the sensor pose
    expect = np.column_stack((index.node_xy[:, 0] + 0.1, index.node_xy[:, 1] + 0.05,
                              np.full(k, 0.2)))
    assert np.allclose(index.node_sensor_pose, expect)
    m = index.map
    again = cast_rays(m.occupied_mask(), m.resolution, m.origin, index.node_sensor_pose,
                      index.beam_angles, 12.0)
    assert np.array_equal(again, index.ranges)
    assert np.isfinite(index.ranges).all()  # a closed map: every beam hits a wall
    assert index.map_checksum == m.checksum() and index.version == FORMAT_VERSION


def test_features_are_the_virtual_scan_in_the_laser_frame(built):
    index, _ = built
    for k in (0, len(index) - 1):
        f = index.features[k]
        assert len(f.points) >= 10
        ok = np.isfinite(index.ranges[k])
        a = index.beam_angles[ok]
        pts = np.column_stack((index.ranges[k, ok] * np.cos(a), index.ranges[k, ok] * np.sin(a)))
        assert np.allclose(f.points, pts[f.source_index])
        # the nodes keep no ICP set (nothing matches them with ICP); the rest is the same
        assert len(f.fine_points) == len(f.fine_normals) == len(f.fine_weights) == 0
        full = prepare_scan(pts, index.config.matcher)
        assert len(full.fine_points) > 0
        for name in ('points', 'tangents', 'descriptors', 'source_index'):
            assert np.array_equal(getattr(f, name), getattr(full, name)), name


def test_progress_reports_increasing_fraction(built):
    _, calls = built
    done = [d for d, _, _ in calls]
    assert calls and all(t == 100 for _, t, _ in calls)
    assert done == sorted(done) and done[-1] == 100


def test_save_load_round_trip(built, tmp_path):
    index, _ = built
    path = save_index(index, tmp_path / 'idx.npz')
    back = load_index(path, expected_map=_rooms())
    assert len(back) == len(index) > 0 and back.version == FORMAT_VERSION
    assert back.config == index.config
    for name in ('node_xy', 'node_kind', 'node_sensor_pose', 'ranges', 'beam_angles',
                 'gvd_mask', 'edges', 'node_clearance'):
        assert np.array_equal(getattr(back, name), getattr(index, name)), name
    assert np.array_equal(back.map.data, index.map.data) and back.map.origin == index.map.origin
    assert back.map_checksum == index.map_checksum
    for a, b in zip(back.features, index.features):
        for key, arr in a.to_arrays().items():
            assert np.array_equal(arr, b.to_arrays()[key]), key


def test_the_ray_caster_of_the_virtual_scans_is_kept_for_the_localizer(built, tmp_path):
    index, _ = built
    assert index.ray_caster() is index.ray_caster()
    poses, angles = index.node_sensor_pose[:5], index.beam_angles
    ranges = index.ray_caster().cast(poses, angles, index.config.max_range)
    assert np.array_equal(ranges, index.ranges[:5])         # the one the scans were cast with
    # a loaded index, or a copy (maybe of another map), builds its own, casting the same
    back = load_index(save_index(index, tmp_path / 'idx.npz'), expected_map=_rooms())
    copy = dataclasses.replace(index, map=_rooms(extra=True))
    for other in (back, copy):
        assert other.ray_caster() is not index.ray_caster()
        assert other.ray_caster() is other.ray_caster()
    assert np.array_equal(back.ray_caster().cast(poses, angles, 12.0), ranges)
    assert not np.array_equal(copy.ray_caster().cast(poses, angles, 12.0), ranges)
    # an index only saved or published (the map_indexer node) keeps none
    lean = build_index(_rooms(), index.config, keep_caster=False)
    assert '_caster' not in vars(lean) and np.array_equal(lean.ranges, index.ranges)


def test_file_holds_no_pickles(built, tmp_path):
    index, _ = built
    path = save_index(index, tmp_path / 'idx.npz')
    with np.load(path, allow_pickle=False) as z:
        for key in z.files:
            assert z[key].dtype != object, key


def _rewrite(src: Path, dst: Path, **changes) -> Path:
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(changes)
    np.savez(dst, **arrays)
    return dst


def test_refuses_other_version(built, tmp_path):
    index, _ = built
    path = save_index(index, tmp_path / 'idx.npz')
    bad = _rewrite(path, tmp_path / 'old.npz',
                   format_version=np.asarray(FORMAT_VERSION + 1, np.int64))
    with pytest.raises(ValueError, match='version'):
        load_index(bad)
    # another version has another layout: the version is what is said, not the layout
    newer = _rewrite(path, tmp_path / 'newer.npz', node_names=np.asarray(['a', 'b']),
                     format_version=np.asarray(FORMAT_VERSION + 1, np.int64))
    with pytest.raises(ValueError, match=f'index format version {FORMAT_VERSION + 1}.*rebuild'):
        load_index(newer)


def test_refuses_other_map(built, tmp_path):
    index, _ = built
    path = save_index(index, tmp_path / 'idx.npz')
    with pytest.raises(ValueError, match='another map'):
        load_index(path, expected_map=_rooms(extra=True))
    tampered = index.map.data.copy()
    tampered[50, 50] = 100
    bad = _rewrite(path, tmp_path / 'tampered.npz', map_data=tampered)
    with pytest.raises(ValueError, match='checksum'):
        load_index(bad)


def test_refuses_pickles_and_garbage(tmp_path):
    obj = tmp_path / 'obj.npz'
    np.savez(obj, format_version=np.asarray(FORMAT_VERSION), config_json=np.array([{}], object))
    with pytest.raises(ValueError):
        load_index(obj)
    junk = tmp_path / 'junk.npz'
    junk.write_bytes(b'not a zip')
    with pytest.raises(ValueError, match='junk.npz'):
        load_index(junk)
    with zipfile.ZipFile(tmp_path / 'empty.npz', 'w'):
        pass
    with pytest.raises(ValueError, match='format_version'):
        load_index(tmp_path / 'empty.npz')
    with pytest.raises(FileNotFoundError):
        load_index(tmp_path / 'missing.npz')


def test_empty_room_gets_nodes_from_extras():
    empty_room = shared_data('maps', 'empty_room.yaml')
    index = build_index(load_map_yaml(empty_room))
    counts = index.kind_counts()
    assert counts['branch'] == 0 and len(index) >= 2
    assert counts['region'] >= 1
    paper_only = IndexConfig(topology=TopologyConfig(dead_end_nodes=False, region_nodes=False,
                                                     arc_spacing=0.0))
    assert len(build_index(load_map_yaml(empty_room), paper_only)) == 0


def test_map_without_free_space_gives_an_empty_index(tmp_path):
    index = build_index(OccupancyMap(np.full((20, 20), 100, np.int8), RES))
    assert len(index) == 0 and index.ranges.shape == (0, 360)
    back = load_index(save_index(index, tmp_path / 'empty.npz'))
    assert len(back) == 0 and back.features == []


def test_config_validation():
    with pytest.raises(ValueError, match='beams'):
        IndexConfig(beams=0)
    with pytest.raises(ValueError, match='max_range'):
        IndexConfig(max_range=-1.0)
    assert config_from_json(IndexConfig, config_to_json(IndexConfig())) == IndexConfig()


def test_load_index_config_flat_nested_and_ros(tmp_path):
    flat = tmp_path / 'flat.yaml'
    flat.write_text('beams: 180\nmax_range: 15\narc_spacing: 3.0\nsensor_pose: [0.1, 0, 0]\n')
    cfg = load_index_config(flat)
    assert cfg.beams == 180 and cfg.max_range == 15.0 and cfg.topology.arc_spacing == 3.0
    assert cfg.sensor_pose == (0.1, 0.0, 0.0)
    ros = tmp_path / 'ros.yaml'
    ros.write_text('map_indexer:\n  ros__parameters:\n    beams: 90\n    topology.min_clearance: '
                   '0.3\n    index_file: /tmp/x.npz\n')
    cfg = load_index_config(ros)
    assert cfg.beams == 90 and cfg.topology.min_clearance == 0.3
    loc = tmp_path / 'loc.yaml'
    loc.write_text('global_localizer:\n  ros__parameters:\n    index:\n      beams: 72\n')
    assert load_index_config(loc).beams == 72
    typo = tmp_path / 'typo.yaml'
    typo.write_text('beamz: 10\n')
    with pytest.raises(ValueError, match='beamz'):
        load_index_config(typo)


def test_cli_index_with_params_and_plot(tmp_path, capsys):
    from ssm_localization.cli import index_cmd
    save_map_yaml(_rooms(), tmp_path / 'rooms.yaml')
    (tmp_path / 'p.yaml').write_text('beams: 120\n')
    parser = argparse.ArgumentParser()
    index_cmd.add_arguments(parser)
    args = parser.parse_args([str(tmp_path / 'rooms.yaml'), '-o', str(tmp_path / 'i.npz'),
                              '--params', str(tmp_path / 'p.yaml'), '--plot',
                              str(tmp_path / 'i.png'), '--quiet'])
    assert index_cmd.run(args) == 0
    out = capsys.readouterr().out
    index = load_index(tmp_path / 'i.npz', expected_map=load_map_yaml(tmp_path / 'rooms.yaml'))
    assert f'{len(index)} nodes' in out and 'branch' in out
    assert index.ranges.shape[1] == 120
    assert (tmp_path / 'i.png').stat().st_size > 1000


def test_office_map_is_deterministic():
    from ssm_localization.bench.synthetic import office_map
    a, b = office_map(size=30.0), office_map(size=30.0)
    assert a.shape == (600, 600) and a.checksum() == b.checksum()
    free = a.free_mask().mean()
    assert 0.5 < free < 0.97
    index = build_index(a, IndexConfig(topology=TopologyConfig(arc_spacing=0.0)))
    assert index.kind_counts()['branch'] >= 3


def test_outdoor_map_is_deterministic_with_buildings_open_ground_and_unknown():
    from ssm_localization.bench.synthetic import outdoor_map
    a, b = outdoor_map(size=120.0), outdoor_map(size=120.0)
    assert a.shape == (2400, 2400) and a.checksum() == b.checksum()
    assert a.checksum() != outdoor_map(size=120.0, seed=1).checksum()
    assert set(np.unique(a.data).tolist()) == {-1, 0, 100}
    assert 0.0 < (a.data == -1).mean() < 0.2           # open ground far from anything
    assert 0.01 < (a.data == 100).mean() < 0.1
    # rooms: the longest straight wall runs are building walls (25-60 m), not trees or cars
    runs = [np.diff(np.flatnonzero(np.diff(np.r_[0, row == 100, 0]))) for row in a.data]
    assert max(r[::2].max(initial=0) for r in runs) * a.resolution >= 25.0


def test_node_kinds_are_small_ints(built):
    index, _ = built
    assert index.node_kind.dtype == np.int8
    assert set(index.node_kind.tolist()) <= {int(k) for k in NodeKind}
    assert math.isclose(float(index.beam_angles[0]), -math.pi)


def _declaring(src: Path, dst: Path, name: str, shape: tuple, dtype: str = '<f8') -> Path:
    """Copy ``src`` with one more member whose header declares ``shape``; its data is 8 bytes."""
    header = {'descr': dtype, 'fortran_order': False, 'shape': shape}
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, 'w') as zout:
        for item in zin.infolist():
            if item.filename != f'{name}.npy':
                zout.writestr(item, zin.read(item))
        buf = io.BytesIO()
        np.lib.format.write_array_header_2_0(buf, header)
        zout.writestr(f'{name}.npy', buf.getvalue() + bytes(8))
    return dst


@pytest.mark.parametrize('name, shape, why', [
    ('junk', (300_000_000,), 'unexpected arrays'),               # a bomb in a member of its own
    ('ranges', (10 ** 9, 360), 'ranges has shape'),            # in one of the layout's
    ('feat__points', (10 ** 12, 2), 'one row per beam'),
    ('node_xy', (5,), 'expected (K, 2)'),
])
def test_declared_shapes_are_checked_before_anything_is_decompressed(built, tmp_path, name,
                                                                     shape, why):
    """A few bytes may declare gigabytes: the headers are checked first, then nothing is read."""
    index, _ = built
    path = save_index(index, tmp_path / 'idx.npz')
    bad = _declaring(path, tmp_path / 'bad.npz', name, shape)
    with pytest.raises(ValueError, match=re.escape(why)):
        load_index(bad)


@pytest.mark.parametrize('changes, why', [
    (lambda a: {'node_xy': np.where(np.arange(a['node_xy'].size).reshape(-1, 2) == 0, np.nan,
                                    a['node_xy'])}, 'node_xy holds non-numbers, NaN or inf'),
    (lambda a: {'feat__tangents': a['feat__tangents'] * np.inf}, 'feat__tangents holds'),
    (lambda a: {'ranges': -a['ranges']}, 'negative ranges'),
    (lambda a: {'node_kind': a['node_kind'] + 99}, 'kinds outside'),
    (lambda a: {'edges': a['edges'] + 10 ** 9}, 'node numbers outside'),
    (lambda a: {'format_version': np.asarray(1.9)}, 'not a whole number'),
    (lambda a: {'format_version': np.asarray(np.inf)}, 'not a whole number'),
    (lambda a: {'feat__points__offsets': a['feat__points__offsets'][::-1].copy()},
     'does not split'),
    (lambda a: {'feat__descriptors': a['feat__descriptors'][:, :3].copy()}, '3 wide'),
    (lambda a: {'config_json': np.asarray('[1, 2]')}, 'stored parameters do not fit'),
    (lambda a: {'config_json': np.asarray('[' * 100000)}, 'stored parameters do not fit'),
])
def test_values_no_build_writes_are_refused_naming_the_file(built, tmp_path, changes, why):
    index, _ = built
    path = save_index(index, tmp_path / 'idx.npz')
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    bad = _rewrite(path, tmp_path / 'bad.npz', **changes(arrays))
    with pytest.raises(ValueError, match=re.escape(str(bad)) + '.*' + re.escape(why)):
        load_index(bad)


def test_refuses_features_of_another_matcher(built, tmp_path):
    index, _ = built
    path = save_index(index, tmp_path / 'idx.npz')
    bad = _rewrite(path, tmp_path / 'feat.npz', feature_fields=np.asarray(['points', 'other']))
    with pytest.raises(ValueError, match='rebuild'):
        load_index(bad)
    cfg = _rewrite(path, tmp_path / 'cfg.npz', config_json=np.asarray('{"no_such": 1}'))
    with pytest.raises(ValueError, match='rebuild'):
        load_index(cfg)


def test_layers_are_reported_in_order_with_their_memory():
    """build_index and GlobalLocalizer name each layer to the hook; the meter measures it."""
    meter = LayerMeter()
    index = build_index(_rooms(), IndexConfig(beams=90), layer=meter)
    localizer = GlobalLocalizer(index, layer=meter)
    assert [c.name for c in meter.costs] == list(INDEX_LAYERS) + list(LAYER_NAMES)
    kept = {c.name: c.kept for c in meter.costs}
    # the virtual scans' caster is the localizer's: kept by that layer, not built again
    assert localizer.caster is index.ray_caster()
    assert kept['virtual scans'] >= localizer.caster._code.nbytes > kept['ray caster']
    assert kept['wall surface'] >= localizer.surface.codes.nbytes
    # (a layer that builds nothing may free a few bytes of the one before)
    assert all(c.peak >= c.kept > -4096 and c.peak >= 0 and c.seconds >= 0 for c in meter.costs)
    table = format_layers(meter.as_dicts(), index.map.data.size, {'ray caster': 'shared'})
    assert 'correlative grid' in table and 'all layers kept' in table
    assert [line.endswith('(shared)') for line in table.splitlines()] == [
        name == 'ray caster' for name in ['header', *INDEX_LAYERS, *LAYER_NAMES, 'all']]
