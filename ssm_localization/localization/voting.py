"""
Pose voting over every node's virtual-scan features (beyond the paper).

The paper matches the query against each node's virtual scan separately. Here the features of all
virtual scans are pooled in the map frame (each point with its tangent direction and shape
descriptor); every query point is paired with the ``neighbours`` map features whose descriptors
are nearest, and each such tentative correspondence implies a full pose, because a point and its
tangent fix the rotation (tangents of the query and the virtual scans are oriented the same way
about their sensors, ``matching/scan.py``): ``yaw = phi_map - phi_query`` and
``t = p_map - R(yaw) p_query``. Votes are accumulated in a sparse (x, y, yaw) histogram; its
local maxima are places where many correspondences agree. The correspondences of each peak are
the tentative set L the spectral matching (eqs. 2-6) then works on.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy.spatial import cKDTree

from ..mapping.index import MapIndex
from ..matching.features import ScanFeatures
from ..threads import checked_workers
from ..transforms import apply

#: the tree proposes this many times the wanted neighbours; exact distances pick among them
RERANK = 3
#: the tree's proposals may be up to (1 + TREE_EPS) times further than the true ones (scipy's
#: ``eps``): half the tree search; after the exact re-ranking nearly the same neighbours (no
#: answer changed on 500 real and simulated queries; over every ``bench localize`` set the
#: wrong ``ok`` answers stayed at 4 of 7070: Intel #417, a yaw-seed case, became one, one on
#: Freiburg 079 stopped being one)
TREE_EPS = 0.5

#: the 27 bin offsets of a 3 x 3 x 3 neighbourhood
_OFFSETS = np.array([(dx, dy, da) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for da in (-1, 0, 1)])


@dataclass(frozen=True)
class Votes:
    """
    Tentative correspondences ``query[qi[v]] <-> map feature mj[v]`` and the pose each implies.

    ``bins`` (V, 3) are their (x, y, yaw) histogram bins, ``weight`` (V,) their vote weight.
    """

    qi: np.ndarray
    mj: np.ndarray
    bins: np.ndarray
    weight: np.ndarray

    def __len__(self) -> int:
        return len(self.qi)


@dataclass(frozen=True)
class Peak:
    """
    A local maximum of the vote histogram.

    Its ``strength`` (summed weight of the votes in its 3 x 3 x 3 neighbourhood), the ``pose`` at
    the centre of its bin and the indices ``members`` of those votes.
    """

    strength: float
    pose: tuple[float, float, float]
    members: np.ndarray


class PoseVoting:
    """The pooled map features of an index and the vote histogram's geometry."""

    def __init__(self, index: MapIndex, neighbours: int = 20, bin_xy: float = 0.5,
                 bin_yaw: float = math.radians(10.0), range_scale: float = 5.0,
                 merge_xy: float = 0.1, merge_yaw: float = math.radians(15.0),
                 search_dims: int = 12, workers: int = 1) -> None:
        if neighbours < 1 or not (bin_xy > 0 and bin_yaw > 0):
            raise ValueError('PoseVoting: neighbours >= 1 and positive bin sizes required')
        #: threads of the tree query (scipy's ``workers``): each takes a share of the query
        #: points, so the neighbours are the same with any number
        self.workers = checked_workers(workers, 'PoseVoting')
        pos, ang, desc, node, rng = [], [], [], [], []
        for k, f in enumerate(index.features):
            pose = tuple(float(v) for v in index.node_sensor_pose[k])
            pos.append(apply(pose, f.points))
            ang.append(pose[2] + np.arctan2(f.tangents[:, 1], f.tangents[:, 0]))
            desc.append(np.asarray(f.descriptors, np.float32))
            node.append(np.full(len(f.points), k, np.int64))
            rng.append(np.hypot(f.points[:, 0], f.points[:, 1]))
        if not pos or sum(len(p) for p in pos) == 0:
            raise ValueError('PoseVoting: the index has no features')
        points, angles = np.concatenate(pos), np.concatenate(ang)
        # neighbouring nodes see the same wall patches: keep the closest view of each patch
        # (``merge_xy`` metres, ``merge_yaw`` of tangent direction)
        yaw_bins = np.floor(np.mod(angles, 2.0 * math.pi) / merge_yaw).astype(np.int64)
        key = np.column_stack((np.floor(points / merge_xy).astype(np.int64), yaw_bins))
        order = np.lexsort((np.concatenate(rng), *key.T[::-1]))
        first = np.ones(len(order), bool)
        first[1:] = np.any(key[order[1:]] != key[order[:-1]], axis=1)
        keep = np.sort(order[first])
        #: map-frame feature positions (M, 2), tangent angles (M,) and unit tangents (M, 2),
        #: descriptors (M, D), node ids
        self.points = points[keep]
        self.angles = angles[keep]
        self.tangents = np.column_stack((np.cos(self.angles), np.sin(self.angles)))
        self.descriptors = np.concatenate(desc)[keep]
        self.nodes = np.concatenate(node)[keep]
        # nearest descriptors: candidates from a k-d tree in the ``search_dims`` leading principal
        # axes, re-ranked by their exact distance; the cost grows with the log of the map's size
        # instead of linearly (0: exact, by brute force). Split at sliding midpoints, not at
        # medians: built in half the time and queried in 0.95 of it on office_30m's queries
        # (docs/EXPERIMENTS.md, 2026-11-28)
        self._tree = None
        if 0 < search_dims < self.descriptors.shape[1]:
            sample = self.descriptors[::max(1, len(self.descriptors) // 20000)].astype(float)
            self._mean = sample.mean(axis=0)
            self._axes = np.linalg.svd(sample - self._mean, full_matrices=False)[2][:search_dims].T
            self._tree = cKDTree((self.descriptors - self._mean) @ self._axes,
                                 balanced_tree=False, compact_nodes=False)
        else:
            self._desc_sq = (self.descriptors.astype(np.float32) ** 2).sum(axis=1)
        self.neighbours = int(neighbours)
        self.bin_xy = float(bin_xy)
        self.n_yaw = max(int(round(2.0 * math.pi / bin_yaw)), 1)
        self.bin_yaw = 2.0 * math.pi / self.n_yaw
        self.range_scale = float(range_scale)
        self._lo = self.points.min(axis=0) - 2.0 * self.bin_xy
        hi = self.points.max(axis=0) + 2.0 * self.bin_xy
        self._n_xy = np.ceil((hi - self._lo) / self.bin_xy).astype(np.int64) + 1

    def orientation_histogram(self, bins: int = 180) -> np.ndarray:
        """
        Return the histogram of the map's wall directions.

        Modulo a half turn, ``bins`` bins, from the tangents of the pooled features.
        """
        return direction_histogram(self.angles, bins)

    def vote(self, query: ScanFeatures) -> Votes:
        """
        Each query point's ``neighbours`` nearest map descriptors, as pose votes.

        A vote weighs ``1 / (1 + range / range_scale)``: near points fix the translation better
        for the same tangent error.
        """
        q_desc = np.asarray(query.descriptors, np.float32)
        n_q, n_m = len(q_desc), len(self.descriptors)
        if n_q == 0:
            z = np.zeros(0, np.int64)
            return Votes(z, z, np.zeros((0, 3), np.int64), np.zeros(0))
        k = min(self.neighbours, n_m)
        if self._tree is not None:
            # candidates from the tree, re-ranked by their exact descriptor distance
            kk = min(RERANK * k, n_m)
            _, cand = self._tree.query((q_desc - self._mean) @ self._axes, k=kk, eps=TREE_EPS,
                                       workers=self.workers)
            cand = np.asarray(cand).reshape(n_q, kk)
            diff = self.descriptors[cand] - q_desc[:, None, :]
            d2 = np.einsum('qkd,qkd->qk', diff, diff)
            top = np.take_along_axis(cand, np.argpartition(d2, k - 1, axis=1)[:, :k], axis=1)
        else:
            d2 = (q_desc ** 2).sum(axis=1)[:, None] + self._desc_sq[None, :] \
                - 2.0 * (q_desc @ self.descriptors.T)
            top = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < n_m else \
                np.broadcast_to(np.arange(n_m), (n_q, n_m))
        qi = np.repeat(np.arange(n_q), k)
        mj = top.ravel()
        qp = query.points[qi]
        # per query point: tangent angle and vote weight
        q_angle = np.arctan2(query.tangents[:, 1], query.tangents[:, 0])
        q_range = np.hypot(query.points[:, 0], query.points[:, 1])
        q_weight = 1.0 / (1.0 + q_range / self.range_scale)
        yaw = self.angles[mj] - q_angle[qi]
        c, s = np.cos(yaw), np.sin(yaw)
        tx = self.points[mj, 0] - (c * qp[:, 0] - s * qp[:, 1])
        ty = self.points[mj, 1] - (s * qp[:, 0] + c * qp[:, 1])
        bx = np.floor((tx - self._lo[0]) / self.bin_xy).astype(np.int64)
        by = np.floor((ty - self._lo[1]) / self.bin_xy).astype(np.int64)
        ba = np.floor(np.mod(yaw, 2.0 * math.pi) / self.bin_yaw).astype(np.int64) % self.n_yaw
        inside = (bx >= 1) & (bx < self._n_xy[0] - 1) & (by >= 1) & (by < self._n_xy[1] - 1)
        return Votes(qi=qi[inside], mj=mj[inside],
                     bins=np.column_stack((bx[inside], by[inside], ba[inside])),
                     weight=q_weight[qi[inside]])

    def peaks(self, votes: Votes, count: int) -> list[Peak]:
        """
        Return the ``count`` strongest local maxima of the 3 x 3 x 3 box-filtered histogram.

        Sparse: only occupied bins are touched, so the cost does not grow with the map.
        """
        if len(votes) == 0 or count <= 0:
            return []
        ny, na = int(self._n_xy[1]), self.n_yaw
        b = votes.bins
        code = (b[:, 0] * ny + b[:, 1]) * na + b[:, 2]
        uniq, inv = np.unique(code, return_inverse=True)
        inv = inv.ravel()
        w_bin = np.bincount(inv, weights=votes.weight)
        ub = np.column_stack((uniq // (ny * na), (uniq // na) % ny, uniq % na))
        # neighbour j of occupied bin i, or -1 where that neighbour is empty
        nb = ub[:, None, :] + _OFFSETS[None, :, :]
        nb[..., 2] %= na
        ncode = (nb[..., 0] * ny + nb[..., 1]) * na + nb[..., 2]
        j = np.minimum(np.searchsorted(uniq, ncode), len(uniq) - 1)
        nbr = np.where(uniq[j] == ncode, j, -1)
        smooth = np.where(nbr >= 0, w_bin[np.maximum(nbr, 0)], 0.0).sum(axis=1)
        around = np.where(nbr >= 0, smooth[np.maximum(nbr, 0)], -np.inf).max(axis=1)
        local_max = np.flatnonzero(smooth >= around)
        local_max = local_max[np.argsort(-smooth[local_max], kind='stable')][:count]
        out = []
        for i in local_max:
            bins = nbr[i][nbr[i] >= 0]
            members = np.flatnonzero(np.isin(inv, bins))
            bx, by, ba = ub[i]
            pose = (float(self._lo[0] + (bx + 0.5) * self.bin_xy),
                    float(self._lo[1] + (by + 0.5) * self.bin_xy),
                    float(math.remainder((ba + 0.5) * self.bin_yaw, 2.0 * math.pi)))
            out.append(Peak(strength=float(smooth[i]), pose=pose, members=members))
        return out


def direction_histogram(angles: np.ndarray, bins: int) -> np.ndarray:
    """Return normalized histogram of line directions (angles modulo pi), smoothed over +-1 bin."""
    b = np.floor(np.mod(angles, math.pi) / math.pi * bins).astype(np.int64) % bins
    h = np.bincount(b, minlength=bins).astype(float)
    h = h + 0.5 * (np.roll(h, 1) + np.roll(h, -1))
    return h / max(h.sum(), 1e-12)


def alignment_yaws(map_spectrum: np.ndarray, scan_angles: np.ndarray, count: int) -> np.ndarray:
    """
    Yaws (modulo a half turn) that best align a scan's wall directions with the map's.

    The ``count`` strongest local maxima of their circular cross-correlation. ``map_spectrum`` is
    ``np.fft.fft`` of the map's direction histogram (:meth:`PoseVoting.orientation_histogram`),
    computed once per map.
    """
    bins = len(map_spectrum)
    scan_hist = direction_histogram(scan_angles, bins)
    corr = np.real(np.fft.ifft(map_spectrum * np.conj(np.fft.fft(scan_hist))))
    peaks = np.flatnonzero((corr >= np.roll(corr, 1)) & (corr >= np.roll(corr, -1)))
    peaks = peaks[np.argsort(-corr[peaks], kind='stable')][:count]
    return peaks * (math.pi / bins)
