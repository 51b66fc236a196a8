"""
Search regions: where the correlative search looks for a scan, at which yaws (beyond the paper).

On the map of one building the localizer searches the whole map at the yaws of its best
hypotheses and at the yaws that align the scan's wall directions with the map's
(``localizer.py``, ``voting.alignment_yaws``). On a campus the map's wall directions are those of
many buildings at many orientations: aligned with all of them at once, a scan finds the dominant
ones, not necessarily those of its own building, and every yaw is searched in every building.

So the map is divided into regions: the connected pieces of its free space, pieces closer than
:data:`JOIN` metres joined (a building, whose rooms the walls and doors cut apart; buildings
with unknown space between them are apart), a piece wider than :data:`MAX_SIZE` cut into tiles
of :data:`TILE` metres. Each region has the direction histogram of its own walls (the pooled
voting features that lie in it), and is searched at the yaws that align the scan with *its*
walls, and at the yaws of the hypotheses that lie in it. A map of one building is one region,
searched exactly as before.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import math
from typing import TypeVar

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from . import voting
from .correlative import CorrelativeGrid, CorrelativeResult
from .voting import direction_histogram, PoseVoting
from ..config.localization import LocalizerConfig
from ..transforms import Pose2, wrap_angle

#: free space closer than this (metres) belongs to one region
JOIN = 10.0
#: a region wider or taller than this (metres) is cut into tiles
MAX_SIZE = 160.0
#: side of those tiles, metres
TILE = 80.0
#: bins of the direction histograms (over half a turn)
BINS = 180
#: the correlative search keeps the best places of every region scoring this much of the best
#: anywhere (``CorrelativeGrid.search``'s ``region_ratio``)
REGION_RATIO = 0.85
#: a regional search expands this many of its best windows per step, all of them before the
#: rest of the pool is looked at again (``CorrelativeGrid.search``'s ``batch`` and
#: ``hot_batches``; 2048 and 4 on a map of one region). The per-region floors keep most
#: windows of a wall-dense region above the bound whatever order they are expanded in, so
#: fewer, larger steps cost less: the same leaves, the 90 captured campus searches in
#: 0.80-0.84 of the time and at 0.6 of their p95 (docs/EXPERIMENTS.md)
REGION_BATCH = 16384
REGION_HOT_BATCHES = 1
#: after a regional search, leaves this far (metres) from every leaf taken are other places:
#: up to ``search_keep`` of them are taken too, as the rivals a look-alike answer must beat
PLACE_APART = 3.0
#: the twin check keeps one leaf (its best) of each cell this wide (metres) and yaw: a place
PLACE_CELL = 1.0


@dataclass(frozen=True)
class SearchPlan:
    """
    The yaws to search and where: ``yaws`` (K,) map-frame, ``allowed`` (K, R) bool.

    Yaw ``k`` is searched in region ``r`` where ``allowed[k, r]``; ``labels`` is the region of
    each top-level window of the correlative grid (-1: none).
    """

    yaws: np.ndarray
    allowed: np.ndarray
    labels: np.ndarray

    @property
    def regions(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the ``regions`` argument of :meth:`CorrelativeGrid.search`."""
        return self.labels, self.allowed


@dataclass(frozen=True, eq=False)
class SearchRegions:
    """
    The regions of a map (see the module docstring).

    ``labels`` (rows, cols) int32: the region of each top-level window of the correlative grid
    that holds a free cell, -1 elsewhere; ``reach`` the same over the windows within
    :data:`JOIN` of free space (where walls of the region lie); ``spectra`` (R, :data:`BINS`)
    the FFT of each region's wall-direction histogram.
    """

    labels: np.ndarray
    reach: np.ndarray
    spectra: np.ndarray
    window: float            # metres: side of a top-level window
    origin: Pose2

    @property
    def count(self) -> int:
        return len(self.spectra)

    @classmethod
    def build(cls, grid: CorrelativeGrid, voting: PoseVoting,
              node_xy: np.ndarray) -> 'SearchRegions':
        """
        Return the regions of the map of ``grid``.

        Their walls: ``voting``'s features, each in the region of the node (at ``node_xy``)
        whose virtual scan saw it.
        """
        free = grid.free_windows()
        window = grid.resolution * (1 << grid.depth)
        join = max(int(math.ceil(JOIN / window)), 1)
        near = ndimage.binary_dilation(free, np.ones((2 * join + 1, 2 * join + 1), bool))
        pieces, n = ndimage.label(near, np.ones((3, 3), bool))
        reach = np.full(free.shape, -1, dtype=np.int64)
        tile = max(int(round(TILE / window)), 1)
        big = max(int(round(MAX_SIZE / window)), 1)
        rows, cols = np.indices(free.shape)
        for i, box in enumerate(ndimage.find_objects(pieces), start=1):
            inside = pieces[box] == i
            rs, cs = box
            if rs.stop - rs.start > big or cs.stop - cs.start > big:
                key = (rows[box] - rs.start) // tile * 1_000_000 + (cols[box] - cs.start) // tile
            else:
                key = np.zeros(inside.shape, dtype=np.int64)
            sub = reach[box]
            sub[inside] = i * 1_000_000_000 + key[inside]
        ids, inverse = np.unique(reach, return_inverse=True)
        inverse = inverse.reshape(reach.shape)
        first = 1 if ids[0] == -1 else 0        # -1 (outside every region) stays -1
        reach = np.where(reach >= 0, inverse - first, -1).astype(np.int32)
        labels = np.where(free, reach, -1).astype(np.int32)
        count = len(ids) - first
        regions = cls(labels=labels, reach=reach, spectra=np.zeros((count, BINS), complex),
                      window=window, origin=grid.origin)
        # each region's walls: the voting features seen from its nodes
        node_region = regions.region_of(node_xy)
        region = node_region[voting.nodes]
        for r in range(count):
            mine = voting.angles[region == r]
            if len(mine):
                regions.spectra[r] = np.fft.fft(direction_histogram(mine, BINS))
        return regions

    def region_of(self, xy: np.ndarray) -> np.ndarray:
        """Return the region (-1: none) of map-frame positions ``xy`` (N, 2)."""
        at = _to_windows(self.origin, self.window, np.asarray(xy, float).reshape(-1, 2))
        ok = ((at[:, 0] >= 0) & (at[:, 0] < self.reach.shape[0]) & (at[:, 1] >= 0)
              & (at[:, 1] < self.reach.shape[1]))
        out = np.full(len(at), -1, dtype=np.int64)
        out[ok] = self.reach[at[ok, 0], at[ok, 1]]
        return out

    def plan(self, scan_angles: np.ndarray, seeds: list[Pose2],
             cfg: LocalizerConfig, more: bool = False,
             weak: Sequence[Pose2] = ()) -> SearchPlan:
        """
        Return the yaws to search in each region.

        Up to ``search_seeds`` seeds distinct modulo a half turn (the hypotheses' laser poses,
        best first) are searched in their own region (in every region when they lie in none);
        every region at its ``search_alignments`` yaws that align the scan's wall directions
        (``scan_angles``) with its own; each yaw with its flip, each +- ``search_spread`` in
        steps of ``search_step``. With one region: the yaws of ``GlobalLocalizer.search_yaws``,
        in the same order. ``more`` (the second look at an answer that is not ``ok``): instead
        only the next ``search_more_alignments`` alignment yaws of every region, those the
        first plan did not search, then the first plan's yaws once more out to
        ``search_more_spread`` (:func:`ring_yaws`). ``weak`` (the weak look at a ``failed``
        answer, see ``GlobalLocalizer.weak_look``): instead only the yaws of these poses (the
        RANSAC poses of weak vote peaks), each in its own region (none when it lies in none),
        those the first plan did not search there.
        """
        centres: list[tuple[float, int]] = []          # (yaw, region or -1: all)
        for pose in seeds:
            yaw = float(pose[2])
            if is_new_yaw(yaw, [c for c, _ in centres], cfg.search_step):
                region = int(self.region_of(np.array([pose[:2]]))[0])
                centres.append((yaw, region))
            if len(centres) >= cfg.search_seeds:
                break
        weak_regions = self.region_of(np.array([p[:2] for p in weak])) if len(weak) else []
        first = cfg.search_alignments
        aligned = self.alignment_yaws(scan_angles,
                                      first + (cfg.search_more_alignments if more else 0))
        yaws, allowed = [], []
        for r in range(self.count):
            mine = [c for c, g in centres if g in (r, -1)]
            for yaw in aligned[r][:first]:
                if is_new_yaw(yaw, mine, cfg.search_step):
                    mine.append(float(yaw))
            ring = np.zeros(0)
            if more:
                searched, mine = mine, []
                for yaw in aligned[r][first:]:
                    if is_new_yaw(yaw, searched + mine, cfg.search_step):
                        mine.append(float(yaw))
                ring = ring_yaws(searched, cfg)
            elif len(weak):
                searched, mine = mine, []
                for pose, g in zip(weak, weak_regions):
                    if g == r and is_new_yaw(float(pose[2]), searched + mine, cfg.search_step):
                        mine.append(float(pose[2]))
            if not mine and not len(ring):
                continue
            region_yaws = spread_yaws(mine, cfg)
            region_yaws = np.concatenate((region_yaws, not_near(ring, region_yaws, cfg)))
            yaws.append(region_yaws)
            mask = np.zeros((len(region_yaws), self.count), bool)
            mask[:, r] = True
            allowed.append(mask)
        if not yaws:
            return SearchPlan(np.zeros(0), np.zeros((0, self.count), bool), self.labels)
        if self.count == 1:
            return SearchPlan(yaws[0], allowed[0], self.labels)
        return SearchPlan(np.concatenate(yaws), np.concatenate(allowed), self.labels)

    def alignment_yaws(self, scan_angles: np.ndarray, count: int) -> list[np.ndarray]:
        """
        Per region, the ``count`` yaws (modulo a half turn) best aligning the scan with its walls.

        As ``voting.alignment_yaws`` against each region's own direction histogram.
        """
        if count <= 0:
            return [np.zeros(0)] * self.count
        return [voting.alignment_yaws(spectrum, scan_angles, count) if np.any(spectrum)
                else np.zeros(0)                # no walls seen from this region
                for spectrum in self.spectra]


def is_new_yaw(yaw: float, centres: Sequence[float], step: float) -> bool:
    """Tell whether ``yaw`` is over two ``step`` from each of ``centres`` (mod a half turn)."""
    return all(abs(wrap_angle(2.0 * (yaw - c))) > 2.0 * step for c in centres)


def spread_yaws(centres: Sequence[float], cfg: LocalizerConfig) -> np.ndarray:
    """Return ``centres`` and their flips, each +- ``search_spread`` by ``search_step`` steps."""
    n = int(round(cfg.search_spread / cfg.search_step))
    return _stepped(centres, range(-n, n + 1), cfg)


def _stepped(centres: Sequence[float], steps, cfg: LocalizerConfig) -> np.ndarray:
    """Return ``centres`` and their flips at each of ``steps`` (whole ``search_step``)."""
    base = np.concatenate((centres, np.asarray(centres, float) + math.pi))
    return np.concatenate([base + cfg.search_step * k for k in steps] or [np.zeros(0)])


def ring_yaws(centres: Sequence[float], cfg: LocalizerConfig) -> np.ndarray:
    """
    Return the yaws beyond ``centres``' spread: each centre and flip +- ``search_more_spread``.

    The steps of ``search_step`` further than ``search_spread`` from the centre, without the
    yaws that lie within half a step of a yaw searched around another centre (the second look's
    ring around the first look's yaws: a scan whose walls run a few degrees off the map's, where
    the nearest first yaw scores too little for a place).
    """
    near = int(round(cfg.search_spread / cfg.search_step))
    far = int(round(cfg.search_more_spread / cfg.search_step))
    ring = _stepped(centres, [k for k in range(-far, far + 1) if abs(k) > near], cfg)
    return not_near(ring, spread_yaws(centres, cfg), cfg)


def not_near(yaws: np.ndarray, taken: np.ndarray, cfg: LocalizerConfig) -> np.ndarray:
    """Return ``yaws`` (in order) without those within half a ``search_step`` of one before."""
    yaws, taken = np.asarray(yaws, float), np.asarray(taken, float)
    if len(taken):
        apart = np.abs(wrap_angle(yaws[:, None] - taken[None, :])).min(axis=1)
        yaws = yaws[apart > 0.5 * cfg.search_step]
    out: list[float] = []
    for yaw in yaws:
        if all(abs(wrap_angle(yaw - t)) > 0.5 * cfg.search_step for t in out):
            out.append(float(yaw))
    return np.array(out)


def _to_windows(origin: Pose2, window: float, xy: np.ndarray) -> np.ndarray:
    """Return the (row, col) of the top-level windows holding map-frame positions ``xy``."""
    ox, oy, oyaw = origin
    c, s = math.cos(oyaw), math.sin(oyaw)
    d = xy - (ox, oy)
    u = (c * d[:, 0] + s * d[:, 1]) / window
    v = (-s * d[:, 0] + c * d[:, 1]) / window
    return np.column_stack((np.floor(v), np.floor(u))).astype(np.int64)


def pick_leaves(found: CorrelativeResult, keep: int,
                same: Callable[[Pose2, Pose2], bool], rivals: int | None = None) -> list[int]:
    """
    Return the leaves of a search to turn into hypotheses, best first.

    The first ``keep`` leaves that are not the ``same`` place as one taken before. After a
    regional search (``found.regions``) also the best such leaf of every region not yet among
    them, and up to ``rivals`` (default ``keep``) leaves more than :data:`PLACE_APART` from
    every leaf taken (other rooms that look alike: the rivals that tell whether the answer is
    unique).
    """
    rivals = keep if rivals is None else rivals
    out: list[int] = []
    poses: list[Pose2] = []
    taken: set[int] = set()
    others = 0
    for i, pose in enumerate(found.poses):
        pose = tuple(float(v) for v in pose)
        region = int(found.regions[i]) if found.regions is not None else -1
        if len(out) >= keep and found.regions is None:
            break
        if any(same(pose, p) for p in poses):
            continue
        if len(out) >= keep and region in taken:
            if others >= rivals or any(
                    math.hypot(pose[0] - p[0], pose[1] - p[1]) <= PLACE_APART for p in poses):
                continue
            others += 1
        out.append(i)
        poses.append(pose)
        taken.add(region)
    return out


def place_leaves(poses: np.ndarray, cell: float = PLACE_CELL) -> np.ndarray:
    """
    Return the index of the best leaf of each place among ``poses`` (L, 3), best first.

    Leaves come best first (``CorrelativeResult``). A leaf within ``cell`` metres of a better
    one at the same yaw is the same place: first the best leaf of each ``cell`` x ``cell`` square
    and yaw, then those squares' leaves merged greedily (a place on a square's edge is one).
    """
    poses = np.asarray(poses, float).reshape(-1, 3)
    if not len(poses):
        return np.zeros(0, np.int64)
    keys = np.column_stack((np.floor(poses[:, :2] / cell), np.round(poses[:, 2], 6)))
    first = np.sort(np.unique(keys, axis=0, return_index=True)[1])
    p = poses[first]
    # pairs of squares' leaves within a cell of each other at one yaw (i < j: i is the better)
    pairs = cKDTree(p[:, :2]).query_pairs(cell, output_type='ndarray')
    pairs = pairs[np.abs(wrap_angle(p[pairs[:, 0], 2] - p[pairs[:, 1], 2])) < 1e-6]
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    merged = np.zeros(len(first), bool)
    for i, j in pairs:
        if not merged[i]:
            merged[j] = True
    return first[~merged]


T = TypeVar('T')


def with_region_bests(regions: SearchRegions, ranked: Sequence[T], first: int,
                      pose_of: Callable[[T], Pose2],
                      always: Callable[[T], bool] = lambda item: False) -> list[T]:
    """
    Return the ``first`` items of ``ranked``, and the first item of each region they miss.

    So every building's best candidate goes on, however the others rank; with several regions
    also every item for which ``always`` holds (the search's leaves: its rivals). With one
    region just the first ``first``.
    """
    head = list(ranked[:first])
    if regions.count <= 1 or len(ranked) <= first:
        return head
    where = regions.region_of(np.array([pose_of(h)[:2] for h in ranked]))
    have = set(where[:first].tolist())
    for item, region in zip(ranked[first:], where[first:].tolist()):
        if (region >= 0 and region not in have) or always(item):
            head.append(item)
            have.add(region)
    return head
