"""map_io: nav2 map_server loading/saving, OccupancyGrid messages, geometry helpers."""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

from helpers import shared_data
import numpy as np
from PIL import Image
import pytest
from ssm_localization.mapping.map_io import (load_map_yaml, occupancy_map_from_msg, OccupancyMap,
                                             save_map_yaml)

SHARED_MAPS = ('depot', 'tb3_sandbox', 'turtlebot3_world', 'empty_room')


def _write(tmp_path: Path, pixels: np.ndarray, text: str, image: str = 'm.pgm') -> Path:
    Image.fromarray(pixels.astype(np.uint8)).save(tmp_path / image)
    path = tmp_path / 'm.yaml'
    path.write_text(text)
    return path


BASE = ('image: m.pgm\nresolution: 0.1\norigin: [1.0, 2.0, 0.0]\nnegate: 0\n'
        'occupied_thresh: 0.65\nfree_thresh: 0.196\n')


@pytest.mark.parametrize('name', SHARED_MAPS)
def test_every_shared_map_loads(name):
    m = load_map_yaml(shared_data('maps', f'{name}.yaml'))
    img = np.asarray(Image.open(shared_data('maps', f'{name}.pgm')))
    assert m.shape == img.shape
    assert m.data.dtype == np.int8
    assert set(np.unique(m.data)) <= {-1, 0, 100}
    # image row 0 is the top: it becomes the last grid row
    top = np.where(img[0] == 0, 100, np.where(img[0] >= 250, 0, m.data[-1]))
    assert np.array_equal(m.data[-1], top)
    assert (m.data == 100).sum() == (img == 0).sum()
    assert m.frame_id == 'map'


def test_shared_map_geometry():
    maps = shared_data('maps')
    m = load_map_yaml(maps / 'empty_room.yaml')
    assert m.resolution == pytest.approx(0.1)
    assert m.origin == (-10.0, -10.0, 0.0)
    # the 205 grey of depot with free_thresh 0.25 is free under map_server semantics
    d = load_map_yaml(maps / 'depot.yaml')
    img = np.flipud(np.asarray(Image.open(maps / 'depot.pgm')))
    assert (d.data[img == 205] == 0).all()
    t = load_map_yaml(maps / 'turtlebot3_world.yaml')
    img = np.flipud(np.asarray(Image.open(maps / 'turtlebot3_world.pgm')))
    assert (t.data[img == 205] == -1).all()


def test_trinary_flip_and_values(tmp_path):
    px = np.array([[0, 254, 205], [255, 100, 0]])
    m = load_map_yaml(_write(tmp_path, px, BASE))
    # bottom grid row = last image row
    # 255 free, 100 -> p = 0.61: unknown, 0 occupied
    assert m.data.tolist() == [[0, -1, 100], [100, 0, -1]]
    assert m.origin == (1.0, 2.0, 0.0)


def test_negate(tmp_path):
    px = np.array([[0, 254, 205]])
    m = load_map_yaml(_write(tmp_path, px, BASE.replace('negate: 0', 'negate: 1')))
    assert m.data.tolist() == [[0, 100, 100]]


def test_scale_and_raw_modes(tmp_path):
    px = np.array([[0, 255, 128, 50, 101]])
    m = load_map_yaml(_write(tmp_path, px, BASE + 'mode: scale\n'))
    p = 1 - 128 / 255
    expect_mid = round((p - 0.196) / (0.65 - 0.196) * 100)
    assert m.data[0, 0] == 100 and m.data[0, 1] == 0 and m.data[0, 2] == expect_mid
    r = load_map_yaml(_write(tmp_path, px, BASE + 'mode: raw\n'))
    assert r.data.tolist() == [[0, -1, -1, 50, -1]]


def test_a_16_bit_pgm_reads_as_its_8_bit_twin(tmp_path):
    """Samples scaled by 65535 whatever the maxval (not by the image's brightest pixel)."""
    px = np.array([[0, 254, 205, 100]])
    eight = load_map_yaml(_write(tmp_path, px, BASE))
    for maxval in (65535, 1000):
        wide = np.round(px * maxval / 255).astype('>u2')
        (tmp_path / 'w.pgm').write_bytes(b'P5\n4 1\n%d\n' % maxval + wide.tobytes())
        (tmp_path / 'w.yaml').write_text(BASE.replace('m.pgm', 'w.pgm'))
        assert load_map_yaml(tmp_path / 'w.yaml').data.tolist() == eight.data.tolist()
    assert eight.data.tolist() == [[100, 0, -1, -1]]


def test_a_32_bit_image_is_refused(tmp_path):
    Image.fromarray(np.array([[0, 500, 1000]], np.int32)).save(tmp_path / 'm.tif')
    (tmp_path / 'm.yaml').write_text(BASE.replace('m.pgm', 'm.tif'))
    with pytest.raises(ValueError, match='32-bit integer pixels'):
        load_map_yaml(tmp_path / 'm.yaml')


def test_rgba_png_alpha_ignored(tmp_path):
    px = np.zeros((2, 2, 4), np.uint8)
    px[..., :3] = 254
    px[0, 0, :3] = 0
    px[..., 3] = 0  # fully transparent: still read by colour
    Image.fromarray(px, 'RGBA').save(tmp_path / 'm.png')
    (tmp_path / 'm.yaml').write_text(BASE.replace('m.pgm', 'm.png'))
    m = load_map_yaml(tmp_path / 'm.yaml')
    assert m.data.tolist() == [[0, 0], [100, 0]]


def test_missing_yaml_and_image(tmp_path):
    with pytest.raises(FileNotFoundError, match='nope.yaml'):
        load_map_yaml(tmp_path / 'nope.yaml')
    (tmp_path / 'm.yaml').write_text(BASE)
    with pytest.raises(FileNotFoundError, match='m.pgm'):
        load_map_yaml(tmp_path / 'm.yaml')


@pytest.mark.parametrize('text, field', [
    ('image: [unclosed\n', 'malformed'),
    ('- just\n- a list\n', 'mapping'),
    (BASE.replace('resolution: 0.1\n', ''), 'resolution'),
    (BASE.replace('resolution: 0.1', 'resolution: fast'), 'resolution'),
    (BASE.replace('resolution: 0.1', 'resolution: -0.1'), 'resolution'),
    (BASE.replace('origin: [1.0, 2.0, 0.0]', 'origin: [1.0, 2.0]'), 'origin'),
    (BASE.replace('image: m.pgm\n', ''), 'image'),
    (BASE.replace('occupied_thresh: 0.65', 'occupied_thresh: 1.5'), 'occupied_thresh'),
    (BASE.replace('free_thresh: 0.196', 'free_thresh: -0.1'), 'free_thresh'),
    (BASE.replace('free_thresh: 0.196', 'free_thresh: 0.9'), 'free_thresh'),
    (BASE.replace('negate: 0', 'negate: 2'), 'negate'),
    (BASE + 'mode: fancy\n', 'mode'),
])
def test_bad_yaml_names_file_and_field(tmp_path, text, field):
    path = _write(tmp_path, np.zeros((2, 2)), text)
    with pytest.raises(ValueError, match=field) as exc:
        load_map_yaml(path)
    assert 'm.yaml' in str(exc.value)


def test_save_load_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=(30, 41))
    m = OccupancyMap(data, 0.05, (-3.25, 1.5, 0.0))
    save_map_yaml(m, tmp_path / 'out' / 'saved.yaml')
    assert (tmp_path / 'out' / 'saved.pgm').is_file()
    back = load_map_yaml(tmp_path / 'out' / 'saved.yaml')
    assert np.array_equal(back.data, data)
    assert back.resolution == 0.05 and back.origin == m.origin
    assert back.checksum() == m.checksum()


def test_checksum_depends_on_data_and_geometry():
    data = np.zeros((5, 6), np.int8)
    a = OccupancyMap(data, 0.05)
    assert a.checksum() == OccupancyMap(data.copy(), 0.05).checksum()
    b = data.copy()
    b[2, 3] = 100
    assert OccupancyMap(b, 0.05).checksum() != a.checksum()
    assert OccupancyMap(data, 0.1).checksum() != a.checksum()
    assert OccupancyMap(data, 0.05, (0.0, 0.0, 0.1)).checksum() != a.checksum()
    assert OccupancyMap(data.reshape(6, 5), 0.05).checksum() != a.checksum()


def test_cell_world_round_trip_with_rotated_origin():
    m = OccupancyMap(np.zeros((20, 30), np.int8), 0.1, (1.0, -2.0, 0.7))
    rows = np.array([0, 5, 19])
    cols = np.array([0, 17, 29])
    xy = m.cell_to_world(rows, cols)
    r, c = m.world_to_cell(xy)
    assert r.tolist() == rows.tolist() and c.tolist() == cols.tolist()
    # cell (0, 0) centre is origin + R(yaw) (0.05, 0.05)
    ca, sa = math.cos(0.7), math.sin(0.7)
    assert xy[0] == pytest.approx((1.0 + 0.05 * ca - 0.05 * sa, -2.0 + 0.05 * sa + 0.05 * ca))


def test_invalid_map_values():
    with pytest.raises(ValueError, match='resolution'):
        OccupancyMap(np.zeros((2, 2), np.int8), 0.0)
    with pytest.raises(ValueError, match='data'):
        OccupancyMap(np.zeros((0, 2), np.int8), 0.1)
    with pytest.raises(ValueError, match='-1'):
        OccupancyMap(np.full((2, 2), 120), 0.1)


def _msg(data, width, height, yaw=0.0, frame='map'):
    q = SimpleNamespace(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    info = SimpleNamespace(resolution=0.05, width=width, height=height,
                           origin=SimpleNamespace(position=SimpleNamespace(x=1.0, y=2.0, z=0.0),
                                                  orientation=q))
    return SimpleNamespace(header=SimpleNamespace(frame_id=frame), info=info, data=data)


def test_from_msg_list_and_array():
    data = [0, 100, -1, 0, 0, 100]
    m = occupancy_map_from_msg(_msg(data, 3, 2, yaw=0.3, frame='world'))
    assert m.data.tolist() == [[0, 100, -1], [0, 0, 100]]
    assert m.origin == pytest.approx((1.0, 2.0, 0.3))
    assert m.frame_id == 'world'
    # rosbags gives int8 numpy arrays; rclpy array('b')
    import array
    m2 = occupancy_map_from_msg(_msg(array.array('b', data), 3, 2))
    m3 = occupancy_map_from_msg(_msg(np.asarray(data, np.int8), 3, 2))
    assert np.array_equal(m2.data, m.data) and np.array_equal(m3.data, m.data)


def test_from_msg_bad_length():
    with pytest.raises(ValueError, match='width'):
        occupancy_map_from_msg(_msg([0, 0, 0], 2, 2))


def test_from_rosbags_message():
    pytest.importorskip('rosbags')
    from rosbags.typesys import get_typestore, Stores
    ts = get_typestore(Stores.ROS2_JAZZY)
    Grid = ts.types['nav_msgs/msg/OccupancyGrid']
    Header = ts.types['std_msgs/msg/Header']
    Time = ts.types['builtin_interfaces/msg/Time']
    Info = ts.types['nav_msgs/msg/MapMetaData']
    Pose = ts.types['geometry_msgs/msg/Pose']
    Point = ts.types['geometry_msgs/msg/Point']
    Quat = ts.types['geometry_msgs/msg/Quaternion']
    info = Info(map_load_time=Time(sec=0, nanosec=0), resolution=0.1, width=2, height=3,
                origin=Pose(position=Point(x=0.5, y=0.0, z=0.0),
                            orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0)))
    msg = Grid(header=Header(stamp=Time(sec=1, nanosec=0), frame_id='map'), info=info,
               data=np.array([0, 100, -1, 0, 100, 100], np.int8))
    m = occupancy_map_from_msg(msg)
    assert m.shape == (3, 2) and m.data[2].tolist() == [100, 100]
