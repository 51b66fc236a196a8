"""
Which index global_localizer serves: the ``index_file``, or the map on the ``map`` topic.

Rules (issue 13, item 4: no silent use of a wrong index, no dead end):

- ``index_file`` set and readable: it is loaded (in the index builder's worker thread). The map
  topic is still watched: when a map arrives there whose checksum differs from the one the file
  was built for, the file's index is not used (a warning names both checksums), the topic's map
  is indexed instead and the file rewritten with that index;
- ``index_file`` missing, corrupt, of another format version: a warning with the reason, then
  the map topic is indexed and the file (re)written there;
- a map on the topic identical to the served one (same cells and geometry) is not re-indexed; a
  new ``frame_id`` on it moves the published poses to that frame (``on_frame``);
- a newer map supersedes one being indexed (IndexBuilder: the newest job wins).

The jobs run in the :class:`IndexBuilder` thread; callbacks ``on_ready(served)`` /
``on_frame(frame)`` run there too (``on_frame`` also on the caller's thread of :meth:`on_map`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
import threading
from typing import Any, Callable

from ssm_localization.mapping.index import save_index

FILE = 'index file'
MAP = 'map'


def map_label(occ: Any, checksum: str) -> str:
    """Name a map in the log: ``map WxH @ RES m (checksum[:8])``."""
    return f'{MAP} {occ.width}x{occ.height} @ {occ.resolution:g} m ({checksum[:8]})'


def write_index(index: Any, path: Path, log: Any,
                save: Callable[[Any, Path], Any] = save_index) -> bool:
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


@dataclass(frozen=True)
class ServedIndex:
    """A complete index ready to serve, with what it was made from."""

    index: Any            # MapIndex
    localizer: Any        # GlobalLocalizer over it
    checksum: str         # OccupancyMap.checksum() of the map it was built for
    source: str           # 'index file PATH' or 'map topic'
    frame: str            # frame_id of that map
    # localizers over ``index`` for other laser mounts ({mount pose: GlobalLocalizer}), kept
    # with the index they use: dropped with it, kept when only the frame changes
    variants: dict = field(default_factory=dict, compare=False, repr=False)


class IndexSource:
    """
    Arbitrates between ``index_file`` and the map topic; see the module docstring.

    ``make(index, source) -> ServedIndex`` wraps a loaded / built index; ``load(path) -> index``
    and ``build(occupancy_map, progress) -> index`` do the work; ``save(index, path)`` writes
    the file (:func:`write_index` logs its errors).
    """

    def __init__(self, builder: Any, logger: Any, index_path: Path | None, topic: str,
                 load: Callable[[Path], Any], build: Callable[[Any, Any], Any],
                 make: Callable[[Any, str], ServedIndex], save: Callable[[Any, Path], None],
                 on_ready: Callable[[ServedIndex], None],
                 on_frame: Callable[[str], None]) -> None:
        self._builder = builder
        self._log = logger
        self._path = index_path
        self._topic = topic
        self._load, self._build, self._make, self._save = load, build, make, save
        self._on_ready, self._on_frame = on_ready, on_frame
        self._lock = threading.Lock()
        self._served: ServedIndex | None = None
        self._topic_map: Any = None          # the newest usable map seen on the topic
        self._topic_checksum = ''            # and its checksum
        self._file_pending = False
        self._pending_checksum: str | None = None
        self._save_to: Path | None = None

    # ------------------------------------------------------------------ state
    @property
    def served(self) -> ServedIndex | None:
        """Return what is being served now, or None before the first index is ready."""
        with self._lock:
            return self._served

    def map_state(self) -> tuple[str, str]:
        """``('no map' | 'indexing' | 'ready', detail)``."""
        if self._builder.busy:
            return 'indexing', self._builder.status()
        with self._lock:
            if self._served is not None:
                return 'ready', self._served.source
        return 'no map', f'waiting for a map on {self._topic}'

    # ------------------------------------------------------------------ inputs
    def start(self) -> None:
        """Load ``index_file`` if it exists (else remember to write it)."""
        if self._path is None:
            return
        if self._path.is_file():
            with self._lock:
                self._file_pending = True
            label = f'{FILE} {self._path}'
            self._builder.submit(label, lambda progress: (FILE, self._load(self._path)))
        else:
            self._log.warning(f'index file {self._path} not found: indexing the map on '
                              f'{self._topic} and saving the index there')
            with self._lock:
                self._save_to = self._path

    def on_map(self, occ: Any) -> None:
        """Take a usable map arrived on the topic."""
        checksum = occ.checksum()
        with self._lock:
            self._topic_map, self._topic_checksum = occ, checksum
            waiting = self._file_pending
        if waiting:
            self._log.info(f'map on {self._topic} received while {self._path} loads: compared '
                           'with it once loaded')
            return
        self._consider(occ, checksum)

    def _consider(self, occ: Any, checksum: str) -> None:
        frame = getattr(occ, 'frame_id', '') or ''
        with self._lock:
            served, pending = self._served, self._pending_checksum
            if served is not None and served.checksum == checksum and pending is None:
                same_frame = served.frame == frame
                if not same_frame:
                    self._served = replace(served, frame=frame)
            elif pending == checksum and self._builder.has_job((MAP, checksum)):
                self._log.info('received the map being indexed again: nothing to do')
                return
            else:
                served = None
        if served is not None:
            if same_frame:
                self._log.info('received the same map again: keeping its index')
            else:
                self._log.warning(f'the map on {self._topic} moved from frame '
                                  f'{served.frame!r} to {frame!r}: publishing in {frame!r}')
                self._on_frame(frame)
            return
        with self._lock:
            current = self._served
            self._pending_checksum = checksum
            if current is not None and current.source.startswith(FILE):
                self._save_to = self._path
        if current is not None and current.source.startswith(FILE):
            self._log.warning(f'the map on {self._topic} ({checksum[:12]}) is not the map '
                              f'{self._path} was built for ({current.checksum[:12]}): '
                              'indexing the map topic; the index file will be rewritten')
        label = map_label(occ, checksum)
        self._log.info(f'{label}: indexing')
        self._builder.submit(label, lambda progress: (MAP, self._build(occ, progress)),
                             (MAP, checksum))

    # ------------------------------------------------------------------ builder callbacks
    def on_done(self, result: tuple[str, Any], label: str) -> None:
        """Handle IndexBuilder ``on_done``: a job finished."""
        kind, index = result
        served = self._make(index, label if kind == FILE else 'map topic')
        if kind == FILE:
            with self._lock:
                self._file_pending = False
                topic_map, topic_checksum = self._topic_map, self._topic_checksum
            if topic_map is not None and topic_checksum != served.checksum:
                self._log.warning(f'{self._path} was built for another map '
                                  f'({served.checksum[:12]}) than the one on {self._topic} '
                                  f'({topic_checksum[:12]}): not using it; indexing the '
                                  'map topic, the index file will be rewritten')
                with self._lock:
                    self._save_to = self._path
                self._consider(topic_map, topic_checksum)
                return
            if topic_map is not None:
                served = replace(served, frame=getattr(topic_map, 'frame_id', '') or '')
        with self._lock:
            if kind == MAP and self._pending_checksum == served.checksum:
                self._pending_checksum = None
            self._served = served
            save_to = self._save_to if kind == MAP else None
            if save_to is not None:
                self._save_to = None
        self._on_ready(served)
        if save_to is not None:
            write_index(index, save_to, self._log, self._save)

    def on_error(self, exc: BaseException, label: str) -> None:
        """Handle IndexBuilder ``on_error``: a job failed."""
        reason = f'{type(exc).__name__}: {exc}'
        if label.startswith(FILE):
            with self._lock:
                self._file_pending = False
                self._save_to = self._path
                topic_map, topic_checksum = self._topic_map, self._topic_checksum
            self._log.warning(f'cannot use index file {self._path} ({reason}): falling back to '
                              f'the map on {self._topic}; the file will be rewritten')
            if topic_map is not None:
                self._consider(topic_map, topic_checksum)
            return
        with self._lock:
            self._pending_checksum = None
            keeping = self._served is not None
        self._log.warning(f'{label}: indexing failed ({reason}); '
                          + ('keeping the previous index' if keeping else 'still no index'))
