"""
IndexSource: index_file vs the map topic.

The rules of ros/index_source.py, with the real IndexBuilder thread and small stand-in maps (the
node tests run the same rules over DDS with real indexes).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
import threading
import time

import pytest
from ssm_localization.config import IndexConfig, LocalizerConfig
from ssm_localization.ros.index_builder import BuildJob
from ssm_localization.ros.index_source import (FILE, IndexPhase, IndexSource, IndexWork,
                                               MapState, parameter_differences, ServedIndex)


@dataclass
class FakeMap:
    cells: str
    frame_id: str = 'map'
    width: int = 10
    height: int = 10
    resolution: float = 0.05

    def checksum(self) -> str:
        return f'{self.cells:0<16}'


class Log:
    def __init__(self):
        self.lines: list[tuple[str, str]] = []

    def info(self, text):
        self.lines.append(('info', text))

    def warning(self, text):
        self.lines.append(('warning', text))

    def error(self, text):
        self.lines.append(('error', text))

    def warnings(self):
        return [t for level, t in self.lines if level == 'warning']


class FakeWork(IndexWork):
    """IndexWork whose 'index' is the FakeMap it was built from; files hold a map name."""

    def __init__(self, harness):
        super().__init__(IndexConfig(), LocalizerConfig())
        object.__setattr__(self, 'harness', harness)

    def load(self, path):
        self.harness.release.wait(5)
        text = path.read_text()
        if text == 'corrupt':
            raise ValueError(f'{path}: not a readable index file (bad zip)')
        return FakeIndex(FakeMap(text, 'file_frame'))

    def build(self, occ, progress):
        self.harness.built.append(occ.cells)
        return FakeIndex(occ)

    def save(self, index, path):
        path.write_text(index.map.cells)
        self.harness.saved.append(index.map.cells)

    def localizer(self, index):
        return f'localizer({index.map.cells})'


@dataclass
class FakeIndex:
    map: FakeMap  # noqa: A003 - MapIndex's field name
    config: IndexConfig = IndexConfig()
    node_xy: tuple = ((0.0, 0.0),)

    @property
    def map_checksum(self) -> str:
        return self.map.checksum()


class Harness:
    """An IndexSource over FakeWork and the real IndexBuilder thread."""

    def __init__(self, tmp_path: Path, file_content: str | None = None, block_load=False):
        self.path = tmp_path / 'index.npz'
        if file_content is not None:
            self.path.write_text(file_content)
        self.log = Log()
        self.ready: list[ServedIndex] = []
        self.saved: list[str] = []
        self.built: list[str] = []
        self.release = threading.Event()
        if not block_load:
            self.release.set()
        self.work = FakeWork(self)
        self.source = IndexSource(self.work, self.log, self.path, '/map', self.ready.append)

    def settle(self):
        assert self.source.wait_idle(5.0)

    def map_while_loading(self, fake_map) -> None:
        """Start (the file's load blocked), receive ``fake_map``, let the load go on, settle."""
        self.source.start()
        self.source.on_map(fake_map)
        self.release.set()
        self.settle()

    def close(self):
        self.source.stop()


@pytest.fixture
def harness_factory(tmp_path):
    made = []

    def make(*args, **kw):
        h = Harness(tmp_path, *args, **kw)
        made.append(h)
        return h
    yield make
    for h in made:
        h.close()


def test_good_file_then_matching_map_keeps_the_file_and_takes_the_topic_frame(harness_factory):
    h = harness_factory('A', block_load=True)
    h.source.start()
    assert h.source.map_state().phase is IndexPhase.LOADING
    h.source.on_map(FakeMap('A', 'world'))           # arrives while the file loads
    h.release.set()
    h.settle()
    assert [s.checksum[:1] for s in h.ready] == ['A'] and h.built == []
    assert h.ready[0].source.startswith(FILE) and h.ready[0].frame == 'world'
    assert h.source.map_state() == MapState(IndexPhase.READY, h.ready[0].source)
    assert not h.log.warnings() and h.saved == []


def test_file_built_for_another_map_is_not_used(harness_factory):
    h = harness_factory('A', block_load=True)
    h.map_while_loading(FakeMap('B'))
    assert [s.checksum[:1] for s in h.ready] == ['B'] and h.built == ['B']
    warning, = h.log.warnings()
    assert 'was built for another map' in warning and 'not using it' in warning
    assert h.saved == ['B'] and h.path.read_text() == 'B'     # the stale file is rewritten


def test_map_differing_from_a_served_file_index_replaces_it_with_a_warning(harness_factory):
    h = harness_factory('A')
    h.source.start()
    h.settle()
    assert h.ready[-1].checksum[:1] == 'A' and h.ready[-1].frame == 'file_frame'
    h.source.on_map(FakeMap('C'))
    h.settle()
    assert h.ready[-1].checksum[:1] == 'C' and h.ready[-1].source == 'map topic'
    assert any('is not the map' in w for w in h.log.warnings())
    assert h.saved == ['C']


def test_a_map_arriving_while_the_file_index_is_served_is_compared_with_it(harness_factory):
    # the file's index loaded with no map yet; another map arrives while its localizer is made
    # (between the load and READY): it waits for the file and is then compared with it
    h = harness_factory('A')
    arrived = []

    def localizer(index):
        if not arrived:
            arrived.append(True)
            h.source.on_map(FakeMap('D'))
        return f'localizer({index.map.cells})'

    object.__setattr__(h.work, 'localizer', localizer)
    h.source.start()
    h.settle()
    assert [s.checksum[:1] for s in h.ready] == ['A', 'D'] and h.built == ['D']
    assert h.ready[-1].source == 'map topic'
    assert any('is not the map' in w for w in h.log.warnings()), h.log.lines
    assert h.saved == ['D'] and h.path.read_text() == 'D'     # the stale file is rewritten


def test_corrupt_file_falls_back_to_the_map_topic(harness_factory):
    h = harness_factory('corrupt')
    h.source.start()
    h.settle()
    assert h.ready == [] and h.source.map_state().phase is IndexPhase.WAITING
    warning, = h.log.warnings()
    assert 'cannot use index file' in warning and 'bad zip' in warning
    assert 'falling back to the map on /map' in warning
    h.source.on_map(FakeMap('D'))
    h.settle()
    assert h.ready[-1].checksum[:1] == 'D' and h.saved == ['D']


def test_corrupt_file_with_a_map_already_received(harness_factory):
    h = harness_factory('corrupt', block_load=True)
    h.map_while_loading(FakeMap('E'))
    assert h.ready[-1].checksum[:1] == 'E' and h.saved == ['E']


def test_missing_file_is_written_after_indexing_the_topic(harness_factory):
    h = harness_factory(None)
    h.source.start()
    assert 'not found' in h.log.warnings()[0]
    h.source.on_map(FakeMap('F'))
    h.settle()
    assert h.saved == ['F'] and h.path.read_text() == 'F'


def test_a_map_of_coarser_cells_than_the_calibration_maps_is_served_with_a_warning(
        harness_factory):
    h = harness_factory(None)
    h.source.on_map(FakeMap('G', 'map'))             # 0.05 m cells: no warning
    h.settle()
    assert not any('coarser' in w for w in h.log.warnings())
    h.source.on_map(FakeMap('H', 'map', resolution=0.1))
    h.settle()
    assert [s.checksum[:1] for s in h.ready] == ['G', 'H']
    warned = [w for w in h.log.warnings() if 'coarser' in w]
    assert len(warned) == 1 and '0.1 m' in warned[0] and 'map topic' in warned[0]


def test_same_map_again_and_frame_change(harness_factory):
    h = harness_factory(None)
    h.source.on_map(FakeMap('G', 'map'))
    h.settle()
    h.source.on_map(FakeMap('G', 'map'))
    h.settle()
    assert h.built == ['G'] and len(h.ready) == 1
    h.source.on_map(FakeMap('G', 'map2'))
    h.settle()
    assert h.built == ['G'] and [s.frame for s in h.ready] == ['map', 'map2']
    assert h.source.served.frame == 'map2' and h.source.served.index is h.ready[0].index
    assert any("moved from frame 'map' to 'map2'" in w for w in h.log.warnings())


def test_a_newer_map_that_fails_to_index_is_said_while_the_previous_one_serves(
        harness_factory):
    h = harness_factory(None)
    h.source.on_map(FakeMap('G'))
    h.settle()
    build = h.work.build

    def failing(occ, progress):
        if occ.cells == 'BAD':
            raise ValueError('map has no nodes')
        return build(occ, progress)

    object.__setattr__(h.work, 'build', failing)
    h.source.on_map(FakeMap('BAD'))
    h.settle()
    state = h.source.map_state()
    assert state.phase is IndexPhase.READY and h.source.served.index.map.cells == 'G'
    assert 'failed to index (ValueError: map has no nodes): serving the previous map' in \
        state.detail, state.detail
    h.source.on_map(FakeMap('H'))
    h.settle()
    assert h.source.map_state() == MapState(IndexPhase.READY, h.ready[-1].source)


def test_no_index_file_no_map(harness_factory, tmp_path):
    h = harness_factory(None)
    h.source._path = None
    h.source.start()
    assert h.log.lines == []
    assert h.source.map_state() == MapState(IndexPhase.WAITING, 'waiting for a map on /map')


def test_a_map_job_dropped_by_the_builder_is_not_taken_for_pending(harness_factory):
    """
    A queued map job replaced by a newer job must not block the same map later.

    IndexBuilder: the newest job wins; 'being indexed' would be a lie then.
    """
    h = harness_factory('corrupt', block_load=True)
    builder = h.source._builder
    builder.submit(BuildJob('slow', lambda progress: h.release.wait(5)))
    end = time.monotonic() + 5
    while builder.status() != 'slow' and time.monotonic() < end:
        time.sleep(0.01)
    assert builder.status() == 'slow'
    h.source.on_map(FakeMap('H'))            # queued behind 'slow', then replaced below
    h.source.start()                         # the file job replaces the queued map job
    h.release.set()
    h.settle()
    assert h.ready and h.ready[-1].checksum[:1] == 'H', [s.checksum for s in h.ready]


def test_index_parameters_differing_from_the_file_are_named(harness_factory):
    """``index.*`` parameters cannot change a loaded index file: a warning says which."""
    h = harness_factory('A')
    configured = IndexConfig(matcher=replace(IndexConfig().matcher, max_points=77), beams=180)
    object.__setattr__(h.work, 'index_config', configured)
    h.source.start()
    h.settle()
    assert h.ready and h.ready[-1].from_file
    warning, = h.log.warnings()
    assert 'index.matcher.max_points=' in warning and '(parameter: 77)' in warning
    assert 'index.beams=360 (parameter: 180)' in warning and "file's values are used" in warning


def test_parameter_differences_names_the_laser_pose_by_its_parameters():
    assert parameter_differences(IndexConfig(), IndexConfig()) == []
    moved = IndexConfig(sensor_pose=(0.2, 0.0, 0.0))
    assert parameter_differences(IndexConfig(), moved) == [
        'laser_x/laser_y/laser_yaw=[0.0, 0.0, 0.0] (parameter: [0.2, 0.0, 0.0])']
