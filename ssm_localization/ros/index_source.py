"""
Which index global_localizer serves: the ``index_file``, or the map on the ``map`` topic.

Rules (no silent use of a wrong index, no dead end):

- ``index_file`` set and readable: it is loaded (in the index builder's worker thread). The map
  topic is still watched: when a map arrives there whose checksum differs from the one the file
  was built for, the file's index is not used (a warning names both checksums), the topic's map
  is indexed instead and the file rewritten with that index. ``index.*`` parameters that differ
  from what the file was built with are named in a warning: the file's values are used;
- ``index_file`` missing, corrupt, of another format version: a warning with the reason, then
  the map topic is indexed and the file (re)written there;
- a map on the topic identical to the served one (same cells and geometry) is not re-indexed; a
  new ``frame_id`` on it moves the published poses to that frame;
- a newer map supersedes one being indexed (IndexBuilder: the newest job wins).

The flow in one place: :meth:`IndexSource.start` (configure) and :meth:`IndexSource.on_map`
(the map subscription) submit jobs to the source's own :class:`IndexBuilder`; its worker thread
calls :meth:`IndexSource._built` / :meth:`IndexSource._failed`, which serve a new
:class:`ServedIndex` (the index with its localizer) and hand it to ``on_served``, the node's one
callback. :meth:`IndexSource.map_state` names the state (:class:`IndexPhase`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import Enum
from functools import partial
from pathlib import Path
import threading
from typing import Any, Callable, NamedTuple

from ssm_localization.config import IndexConfig, LocalizerConfig
from ssm_localization.config.convert import flatten
from ssm_localization.files.reading import clip
from ssm_localization.localization.confidence import resolution_warning
from ssm_localization.localization.localizer import GlobalLocalizer
from ssm_localization.mapping.index import build_index, load_index, MapIndex, save_index
from ssm_localization.mapping.map_limits import MAX_MAP_CELLS
from ssm_localization.mapping.occupancy import OccupancyMap
from ssm_localization.progress import ProgressCallback
from ssm_localization.ros.index_builder import BuildJob, IndexBuilder

FILE = 'index file'
MAP = 'map'
MAP_TOPIC = 'map topic'


class IndexPhase(Enum):
    """What the index source is doing; ``reported`` is the word diagnostics and logs use."""

    WAITING = 'waiting for a map'        # nothing served, nothing in progress
    LOADING = 'loading the index file'   # index_file being read; a map that comes waits
    INDEXING = 'indexing a map'          # a topic map being indexed; an older one may be served
    READY = 'ready'                      # an index is served, nothing in progress

    @property
    def reported(self) -> str:
        """``'no map'``, ``'indexing'`` or ``'ready'`` (diagnostics ``map`` value)."""
        return {IndexPhase.WAITING: 'no map', IndexPhase.READY: 'ready'}.get(self, 'indexing')


class MapState(NamedTuple):
    """The phase and a line saying what it is about (the job, the served source, the topic)."""

    phase: IndexPhase
    detail: str


class JobKind(Enum):
    """What a job of the index source does."""

    LOAD_FILE = 'load'
    INDEX_MAP = 'index'


def map_label(occ: Any, checksum: str) -> str:
    """Name a map in the log: ``map WxH @ RES m (checksum[:8])``."""
    return f'{MAP} {occ.width}x{occ.height} @ {occ.resolution:g} m ({checksum[:8]})'


def write_index(index: MapIndex, path: Path, log: Any,
                save: Callable[[MapIndex, Path], Any] = save_index) -> bool:
    """
    Write ``index`` to ``path`` with ``save`` (:func:`save_index`: atomic, makes the folders).

    The outcome is logged; returns True when the file was written.
    """
    try:
        save(index, path)
    except (OSError, ValueError) as exc:
        log.error(f'cannot write index file {path}: {exc}')
        return False
    log.info(f'index written to {path}')
    return True


def parameter_differences(built_with: IndexConfig, configured: IndexConfig) -> list[str]:
    """
    Return ``index.*`` parameters whose configured value differs from an index file's.

    Each as ``'name=file value (parameter: configured value)'``; the laser pose is named by the
    nodes' ``laser_x/laser_y/laser_yaw`` parameters.
    """
    file_values = flatten(built_with, 'index.')
    out = []
    for name, value in flatten(configured, 'index.').items():
        theirs = file_values.get(name)
        if theirs != value:
            shown = 'laser_x/laser_y/laser_yaw' if name == 'index.sensor_pose' else name
            out.append(f'{shown}={theirs} (parameter: {value})')
    return out


@dataclass(frozen=True)
class IndexWork:
    """
    What the source does with files and maps: the core's load, build, save and localizer.

    Tests give a subclass with stand-ins.
    """

    index_config: IndexConfig
    localizer_config: LocalizerConfig
    max_map_cells: int = MAX_MAP_CELLS

    def load(self, path: Path) -> MapIndex:
        """Read an index file (refused when its map is over ``max_map_cells``)."""
        return load_index(path, max_cells=self.max_map_cells)

    def build(self, occ: OccupancyMap, progress: ProgressCallback) -> MapIndex:
        """Index a map."""
        return build_index(occ, self.index_config, progress=progress)

    def save(self, index: MapIndex, path: Path) -> None:
        """Write an index file."""
        save_index(index, path)

    def localizer(self, index: MapIndex) -> GlobalLocalizer:
        """Return the localizer over a new index."""
        return GlobalLocalizer(index, self.localizer_config)


@dataclass(frozen=True)
class ServedIndex:
    """A complete index ready to serve, with what it was made from."""

    index: MapIndex
    localizer: GlobalLocalizer       # over ``index``, for the configured laser mount
    checksum: str                    # OccupancyMap.checksum() of the map it was built for
    source: str                      # 'index file PATH' or 'map topic'
    frame: str                       # frame_id of that map
    # localizers over ``index`` for other laser mounts ({mount pose: GlobalLocalizer}), kept
    # with the index they use: dropped with it, kept when only the frame changes
    variants: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def from_file(self) -> bool:
        """Tell whether the index came from ``index_file``."""
        return self.source != MAP_TOPIC


@dataclass(frozen=True)
class TopicMap:
    """A usable map received on the topic, with its checksum."""

    occ: OccupancyMap
    checksum: str

    @property
    def frame(self) -> str:
        return getattr(self.occ, 'frame_id', '') or ''


class IndexSource:
    """
    Arbitrates between ``index_file`` and the map topic; see the module docstring.

    ``work`` does the loading, indexing and writing; ``on_served(served)`` is called (in the
    builder's thread, or the map subscription's for a frame change) whenever a new
    :class:`ServedIndex` is served.
    """

    def __init__(self, work: IndexWork, logger: Any, index_path: Path | None, topic: str,
                 on_served: Callable[[ServedIndex], None]) -> None:
        self._work = work
        self._log = logger
        self._path = index_path
        self._topic = topic
        self._on_served = on_served
        self._builder = IndexBuilder(logger, self._built, self._failed)
        self._lock = threading.Lock()
        # the state: the phase follows from these and the builder (see map_state)
        self._served: ServedIndex | None = None
        self._latest: TopicMap | None = None     # the newest usable map seen on the topic
        self._loading = False                    # index_file is being read
        self._write_to: Path | None = None       # write the next index built from the topic
        self._stale = ''                         # why the served index is not the topic's map

    # ------------------------------------------------------------------ state
    @property
    def served(self) -> ServedIndex | None:
        """Return what is being served now, or None before the first index is ready."""
        with self._lock:
            return self._served

    @property
    def busy(self) -> bool:
        """Tell whether a file is being loaded or a map indexed."""
        return self._builder.busy

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Wait until nothing is loaded or indexed; False on timeout."""
        return self._builder.wait_idle(timeout)

    def map_state(self) -> MapState:
        """Return the phase and what it is about."""
        with self._lock:
            loading, served, stale = self._loading, self._served, self._stale
        if loading:
            return MapState(IndexPhase.LOADING, self._builder.status())
        if self._builder.busy:
            return MapState(IndexPhase.INDEXING, self._builder.status())
        if served is not None:
            return MapState(IndexPhase.READY, f'{served.source}; {stale}' if stale
                            else served.source)
        return MapState(IndexPhase.WAITING, f'waiting for a map on {self._topic}')

    def stop(self) -> None:
        """End the builder thread (a job in progress is dropped)."""
        self._builder.stop()

    # ------------------------------------------------------------------ inputs
    def start(self) -> None:
        """Load ``index_file`` if it exists (else remember to write it)."""
        path = self._path
        if path is None:
            return
        if not path.is_file():
            self._log.warning(f'index file {path} not found: indexing the map on '
                              f'{self._topic} and saving the index there')
            with self._lock:
                self._write_to = path
            return
        with self._lock:
            self._loading = True
        self._builder.submit(BuildJob(f'{FILE} {path}', lambda progress: self._work.load(path),
                                      (JobKind.LOAD_FILE, path)))

    def on_map(self, occ: OccupancyMap) -> None:
        """Take a usable map arrived on the topic."""
        topic_map = TopicMap(occ, occ.checksum())
        with self._lock:
            self._latest = topic_map
        self._take(topic_map)

    def _take(self, topic_map: TopicMap) -> None:
        """Decide what a map from the topic needs: wait for the file, nothing, or an index."""
        with self._lock:
            loading, served = self._loading, self._served
        if loading:
            self._log.info(f'map on {self._topic} received while {self._path} loads: compared '
                           'with it once loaded')
        elif (served is not None and served.checksum == topic_map.checksum
              and not self._builder.busy):
            self._same_map_again(served, topic_map.frame)
        elif self._builder.has_job((JobKind.INDEX_MAP, topic_map.checksum)):
            self._log.info('received the map being indexed again: nothing to do')
        else:
            self._index(topic_map)

    # ------------------------------------------------------------------ transitions
    def _same_map_again(self, served: ServedIndex, frame: str) -> None:
        """READY, the served map again: keep its index; follow a new frame_id."""
        if served.frame == frame:
            self._log.info('received the same map again: keeping its index')
            return
        moved = replace(served, frame=frame)
        with self._lock:
            self._served = moved
        self._log.warning(f'the map on {self._topic} moved from frame {served.frame!r} to '
                          f'{frame!r}: publishing in {frame!r}')
        self._on_served(moved)

    def _index(self, topic_map: TopicMap) -> None:
        """-> INDEXING: index a topic map (an index file served until now is to be rewritten)."""
        with self._lock:
            replaces_file = self._served is not None and self._served.from_file
            if replaces_file:
                self._write_to = self._path
            current = self._served
        if replaces_file:
            self._log.warning(f'the map on {self._topic} ({topic_map.checksum[:12]}) is not the '
                              f'map {self._path} was built for ({current.checksum[:12]}): '
                              'indexing the map topic; the index file will be rewritten')
        label = map_label(topic_map.occ, topic_map.checksum)
        self._log.info(f'{label}: indexing')
        self._builder.submit(BuildJob(label, partial(self._work.build, topic_map.occ),
                                      (JobKind.INDEX_MAP, topic_map.checksum)))

    def _built(self, job: BuildJob, index: MapIndex) -> None:
        """Builder: a job finished (LOADING or INDEXING -> READY, or LOADING -> INDEXING)."""
        if job.key[0] is JobKind.INDEX_MAP:
            self._serve(index, MAP_TOPIC, getattr(index.map, 'frame_id', '') or '')
            return
        with self._lock:
            latest = self._latest
        differences = parameter_differences(index.config, self._work.index_config)
        if differences:
            self._log.warning(f'{self._path} was built with other index parameters than the '
                              f'node has: {"; ".join(differences)}. The file\'s values are used; '
                              'to apply the parameters, delete the file (it is rebuilt from the '
                              'map topic and written again)')
        if latest is not None and latest.checksum != index.map_checksum:
            self._log.warning(f'{self._path} was built for another map '
                              f'({index.map_checksum[:12]}) than the one on {self._topic} '
                              f'({latest.checksum[:12]}): not using it; indexing the '
                              'map topic, the index file will be rewritten')
            with self._lock:
                self._write_to = self._path
                self._loading = False
            self._index(latest)
            return
        frame = latest.frame if latest is not None else getattr(index.map, 'frame_id', '')
        self._serve(index, job.label, frame or '')
        # LOADING ends only once the file is served: a map that came meanwhile waited for it
        # and is compared with it now (another map is indexed, with a warning)
        with self._lock:
            self._loading = False
            arrived = self._latest
        if arrived is not None and arrived is not latest:
            self._take(arrived)

    def _failed(self, job: BuildJob, exc: BaseException) -> None:
        """Builder: a job failed (LOADING -> WAITING or INDEXING; INDEXING -> as before)."""
        reason = f'{type(exc).__name__}: {exc}'
        if job.key[0] is JobKind.INDEX_MAP:
            with self._lock:
                keeping = self._served is not None
                if keeping:      # said in map_state (/diagnostics) until a map is served
                    self._stale = (f'the newer {job.label} failed to index ({clip(reason)}): '
                                   'serving the previous map')
            self._log.warning(f'{job.label}: indexing failed ({reason}); '
                              + ('keeping the previous index' if keeping else 'still no index'))
            return
        with self._lock:
            self._loading = False
            self._write_to = self._path
            latest = self._latest
        self._log.warning(f'cannot use index file {self._path} ({reason}): falling back to '
                          f'the map on {self._topic}; the file will be rewritten')
        if latest is not None:
            self._index(latest)

    def _serve(self, index: MapIndex, source: str, frame: str) -> None:
        """-> READY: serve ``index``, tell the node, write the index file if it is due."""
        served = ServedIndex(index, self._work.localizer(index), index.map_checksum, source,
                             frame)
        with self._lock:
            self._served, self._stale = served, ''
            write_to = None if served.from_file else self._write_to
            if write_to is not None:
                self._write_to = None
        how = 'indexed' if source == MAP_TOPIC else 'loaded'
        self._log.info(f'{source}: {how}, ready, {len(index.node_xy)} nodes')
        note = resolution_warning(index.map.resolution)
        if note:
            self._log.warning(f'{source}: {note}')
        self._on_served(served)
        if write_to is not None:
            write_index(index, write_to, self._log, self._work.save)
