"""
Topological map of a grid map: brushfire distance, GVD and nodes (paper section III).

Algorithm (all vectorized numpy/scipy):

1. Brushfire: the Euclidean distance transform (``scipy.ndimage.distance_transform_edt``) of the
   free space gives every free cell its distance to the nearest obstacle cell (unknown cells and
   the outside of the map count as obstacles) and *which* obstacle cell that is (feature
   transform). Cells closer than ``min_clearance`` (the robot radius) are not traversable, so
   passages narrower than twice that are ignored.
2. GVD: a traversable cell is on the generalized Voronoi diagram when it and a neighbour have
   nearest obstacle cells far apart, i.e. it is equidistant to two distinct obstacle points
   (feature separation ``> ridge_ratio * clearance`` and > 3 cells). Walls are usually one
   connected obstacle, so obstacle *points*, not components, are compared. The ridge is thinned
   to a one-pixel, 8-connected skeleton (Guo-Hall parallel thinning); junctions and arcs come
   from its 8-neighbour graph (diagonal links that short-cut a 4-neighbour are dropped).
3. Pruning: spurs (terminal arcs, e.g. the bisectors running into concave room corners) shorter
   than ``max(min_spur_length, spur_factor * clearance of their junction)`` are removed, that
   limit times ``weak_spur_factor`` for weak arcs (obstacle points subtending < 60 deg on most
   pixels: wall noise); so are free-standing weak arcs and skeleton pieces shorter than
   ``min_spur_length``. Repeated until stable. Known limit: where a doorway opens into a room
   deeper than ~1/ridge_ratio door widths the arc through the door can break; the room's GVD
   then ends in dead-end nodes.
4. Nodes: *branch* nodes where three or more arcs meet (the paper's only kind; nodes closer than
   ``merge_radius`` are merged), plus configurable extras that cover places where branch nodes
   alone fail: *dead ends* of arcs, one *region* node (at the point of maximum clearance) for
   every GVD component / free region without a node, and *arc* nodes spaced at most
   ``arc_spacing`` apart along the GVD (farthest-point sampling by geodesic distance).
5. Edges link nodes whose GVD territories (geodesic Voronoi cells on the skeleton) touch.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
import math

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from .distance import BAND_ROWS, distances_from, feature_transform
from .occupancy import OccupancyMap
from ..config.mapping import TopologyConfig
from ..progress import ProgressCallback


class NodeKind(IntEnum):
    """Why a node exists (stored as a small int)."""

    BRANCH = 0    # three or more GVD arcs meet (paper section III)
    DEAD_END = 1  # end of a GVD arc
    REGION = 2    # a GVD component / free region that would otherwise have no node
    ARC = 3       # sampled along a long GVD arc


NODE_KIND_NAMES: tuple[str, ...] = tuple(k.name.lower() for k in NodeKind)


@dataclass(frozen=True, eq=False)
class Topology:
    """
    Nodes and GVD of a map.

    ``node_cell`` are (row, col) grid cells, ``clearance`` (H, W) the brushfire distance in metres
    (0 on obstacles), ``edges`` (E, 2) node index pairs.
    """

    node_xy: np.ndarray
    node_kind: np.ndarray
    node_cell: np.ndarray
    node_clearance: np.ndarray
    edges: np.ndarray
    gvd_mask: np.ndarray
    clearance: np.ndarray

    def __len__(self) -> int:
        return len(self.node_xy)

    def kind_counts(self) -> dict[str, int]:
        return count_kinds(self.node_kind)


def count_kinds(node_kind: np.ndarray) -> dict[str, int]:
    """``{kind name: number of nodes}`` for an array of :class:`NodeKind` values."""
    counts = np.bincount(np.asarray(node_kind, dtype=np.int64), minlength=len(NODE_KIND_NAMES))
    return {name: int(counts[i]) for i, name in enumerate(NODE_KIND_NAMES)}


# --------------------------------------------------------------------------- 8-neighbourhoods
# Ring order x1..x8 = E, NE, N, NW, W, SW, S, SE (bit i = x_{i+1}); rows grow northwards.

def _bits(n: int) -> list[bool]:
    return [bool(n >> i & 1) for i in range(8)]


def _guo_hall(n: int, first: bool) -> bool:
    """Return True when the centre pixel may be deleted (Guo & Hall 1989, two-subiteration A1)."""
    x = _bits(n) + _bits(n)[:1]  # x[0..8], x[8] = x1
    c = sum((not x[2 * i]) and (x[2 * i + 1] or x[2 * i + 2]) for i in range(4))
    n1 = sum(x[2 * k] or x[2 * k + 1] for k in range(4))
    n2 = sum(x[2 * k + 1] or x[2 * k + 2] for k in range(4))
    if c != 1 or not 2 <= min(n1, n2) <= 3:
        return False
    if first:
        return not ((x[1] or x[2] or not x[7]) and x[0])
    return not ((x[5] or x[6] or not x[3]) and x[4])


_LUT_THIN = (np.array([_guo_hall(n, True) for n in range(256)]),
             np.array([_guo_hall(n, False) for n in range(256)]))


def _ring(w: int) -> np.ndarray:
    return np.array([1, w + 1, w, w - 1, -1, -w - 1, -w, -w + 1], dtype=np.int64)


def _codes(mask: np.ndarray, idx: np.ndarray, ring: np.ndarray) -> np.ndarray:
    code = np.zeros(len(idx), dtype=np.uint8)
    for i, o in enumerate(ring):
        code |= mask[idx + o].view(np.uint8) << np.uint8(i)
    return code


def _thin(mask: np.ndarray, ring: np.ndarray) -> None:
    """Guo-Hall thinning of the flat bool ``mask`` in place (pixels must not touch the edge)."""
    idx = np.flatnonzero(mask)
    while idx.size:
        changed = False
        for lut in _LUT_THIN:
            dele = lut[_codes(mask, idx, ring)]
            if dele.any():
                mask[idx[dele]] = False
                idx = idx[~dele]
                changed = True
        if not changed:
            break


def _graph(idx: np.ndarray, mask: np.ndarray, w: int):
    """
    Sparse symmetric 8-neighbour graph over the sorted flat pixel indices ``idx``.

    Returns the csr graph (weights in cells) and each undirected edge once (``er``, ``ec``).
    """
    rows, cols, wts = [], [], []
    # A diagonal step is redundant (and would short-circuit junctions) when the two pixels
    # share a 4-neighbour on the skeleton.
    for o, length, via in ((1, 1.0, ()), (w, 1.0, ()), (w + 1, math.sqrt(2), (1, w)),
                           (w - 1, math.sqrt(2), (-1, w))):
        nb = idx + o
        ok = mask[nb]
        for v in via:
            ok &= ~mask[idx + v]
        rows.append(np.flatnonzero(ok))
        cols.append(np.searchsorted(idx, nb[ok]))
        wts.append(np.full(int(ok.sum()), length))
    r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(wts)
    n = len(idx)
    g = coo_matrix((np.concatenate((v, v)), (np.concatenate((r, c)), np.concatenate((c, r)))),
                   shape=(n, n)).tocsr()
    return g, r, c


@dataclass
class _Skeleton:
    idx: np.ndarray        # flat indices (padded grid) of skeleton pixels, sorted
    graph: object          # csr (n, n), edge weights in cells
    er: np.ndarray         # edge endpoints (each undirected edge once)
    ec: np.ndarray
    junction: np.ndarray   # bool (n,)
    endpoint: np.ndarray   # bool (n,)
    arc: np.ndarray        # arc label per pixel, -1 on junction pixels
    n_arcs: int
    cluster: np.ndarray    # junction-cluster label per pixel, -1 elsewhere
    n_clusters: int
    adj: np.ndarray        # (M, 2) unique (arc, cluster) contacts
    width: int             # of the padded grid the flat indices refer to


def _components(n: int, er: np.ndarray, ec: np.ndarray,
                keep: np.ndarray) -> tuple[int, np.ndarray]:
    sel = keep[er] & keep[ec]
    g = coo_matrix((np.ones(int(sel.sum())), (er[sel], ec[sel])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    out = np.full(n, -1, dtype=np.int64)
    _, out[keep] = np.unique(lab[keep], return_inverse=True)
    return int(out.max()) + 1 if keep.any() else 0, out


def _analyse(mask: np.ndarray, w: int) -> _Skeleton:
    idx = np.flatnonzero(mask)
    graph, er, ec = _graph(idx, mask, w)
    n = len(idx)
    degree = np.bincount(er, minlength=n) + np.bincount(ec, minlength=n)
    junction = degree >= 3
    endpoint = degree <= 1
    n_arcs, arc = _components(n, er, ec, ~junction)
    n_cl, cluster = _components(n, er, ec, junction)
    a = np.concatenate((arc[er], arc[ec]))
    c = np.concatenate((cluster[ec], cluster[er]))
    ok = (a >= 0) & (c >= 0)
    adj = np.unique(np.column_stack((a[ok], c[ok])), axis=0) if ok.any() \
        else np.zeros((0, 2), dtype=np.int64)
    return _Skeleton(idx, graph, er, ec, junction, endpoint, arc, n_arcs, cluster, n_cl, adj,
                     w)


def _to_cells(res: float):
    """Convert metres -> cells, rounded to 4 decimals (area: apply it twice)."""
    return lambda metres: round(float(metres) / res, 4)


# --------------------------------------------------------------------------- main entry

#: rounds of spur pruning (each round re-thins the skeleton); it is stable long before
MAX_PRUNE_ROUNDS = 20


def build_topology(occ_map: OccupancyMap, config: TopologyConfig | None = None,
                   progress: ProgressCallback | None = None) -> Topology:
    """Brushfire distance, GVD and nodes of ``occ_map`` (see the module docstring)."""
    cfg = config or TopologyConfig()
    report = progress or (lambda done, total, label: None)
    steps = 5
    # Every length is compared in cells, as the grid gives it, with the settings converted once
    # and rounded: a resolution that differs in its 8th digit (float32 over the wire, a decimal
    # in a YAML file) gives the same topology instead of flipping a comparison at a boundary.
    cells = _to_cells(occ_map.resolution)
    report(0, steps, 'brushfire')
    free, dist, feat = _brushfire(occ_map, cfg.free_thresh)
    traversable = free & (dist >= max(cells(cfg.min_clearance), 1.0))
    report(1, steps, 'gvd')
    ridge, strength = _ridge(traversable, dist, feat, cfg.ridge_ratio)
    del feat
    _fill_free_holes(ridge, free)
    width = free.shape[1]
    mask = ridge.ravel()
    ring = _ring(width)
    _thin(mask, ring)
    report(2, steps, 'prune')
    dflat = dist.ravel()
    sk = _prune(mask, ring, width, dflat, strength.ravel(), cells(cfg.min_spur_length), cfg)
    del strength
    report(3, steps, 'nodes')
    nodes, kinds = _select_nodes(sk, dflat, traversable, width, cells, cfg)
    report(4, steps, 'edges')
    edges = _edges(sk, nodes)
    topology = _topology(occ_map, nodes, kinds, edges, mask, dist)
    report(steps, steps, 'done')
    return topology


def _brushfire(occ_map: OccupancyMap,
               free_thresh: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Step 1: the free cells of the padded grid (the outside is an obstacle), their distance.

    Returns ``free`` (H+2, W+2) bool, ``dist`` the distance in cells of every cell to the
    nearest obstacle cell and ``feat`` (2, H+2, W+2) int32, the row and column of that cell.
    """
    h, w = occ_map.shape
    free = np.zeros((h + 2, w + 2), dtype=bool)
    free[1:-1, 1:-1] = occ_map.free_mask(free_thresh)
    # scipy's transform with its distances costs about 40 bytes per cell; the feature transform
    # alone and the distances made from it band by band (bit for bit the same) about 17
    feat = feature_transform(~free)
    return free, distances_from(feat), feat


def _ridge(traversable: np.ndarray, dist: np.ndarray, feat: np.ndarray,
           ridge_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Step 2: the ridge of the feature transform, neighbours with far-apart nearest obstacles.

    Returns the ridge (bool, the shape of ``traversable``) and its strength, the separation of
    the nearest obstacle points over the clearance (float32, 0 off the ridge).
    """
    rows, cols = traversable.shape
    ridge = np.zeros_like(traversable)
    strength = np.zeros(traversable.shape, dtype=np.float32)
    # band by band (rows of the first cell of each pair), so the temporaries stay small
    for b0 in range(0, rows, BAND_ROWS):
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            b1 = min(b0 + BAND_ROWS, rows - dr)
            if b1 <= b0:
                continue
            sp = (slice(b0, b1), slice(max(0, -dc), cols - max(0, dc)))
            sq = (slice(b0 + dr, b1 + dr), slice(max(0, dc), cols + min(0, dc)))
            both = traversable[sp] & traversable[sq]
            sep2 = ((feat[0][sp] - feat[0][sq]).astype(np.int64) ** 2
                    + (feat[1][sp] - feat[1][sq]).astype(np.int64) ** 2)
            dmax = np.maximum(dist[sp], dist[sq])
            on = both & (sep2 > np.maximum(9.0, (ridge_ratio * dmax) ** 2))
            ridge[sp] |= on
            ridge[sq] |= on
            ratio = np.where(on, np.sqrt(sep2, dtype=np.float32) / np.maximum(dmax, 1.0), 0.0)
            np.maximum(strength[sp], ratio, out=strength[sp])
            np.maximum(strength[sq], ratio, out=strength[sq])
    return ridge, strength


def _fill_free_holes(ridge: np.ndarray, free: np.ndarray) -> None:
    """
    Fill, in place, the holes of the ridge that hold only free cells.

    A GVD loop always encloses an obstacle; staircase walls make tiny loops around free cells,
    which thinning would keep as cycles.
    """
    holes, n_holes = ndimage.label(~ridge)
    if n_holes > 1:
        keep = np.bincount(holes[~free], minlength=n_holes + 1) > 0
        keep[0] = True
        ridge |= ~keep[holes]


def _prune(mask: np.ndarray, ring: np.ndarray, w: int, dflat: np.ndarray, sflat: np.ndarray,
           min_spur: float, cfg: TopologyConfig) -> _Skeleton:
    """
    Step 3: remove spurs and noise from the thinned skeleton ``mask`` in place, until stable.

    Returns the analysis of the pruned skeleton.
    """
    for _ in range(MAX_PRUNE_ROUNDS):
        sk = _analyse(mask, w)
        if sk.idx.size == 0:
            return sk
        drop = (_spur_pixels(sk, dflat, sflat, min_spur, cfg)
                | _lone_cluster_pixels(sk, min_spur)
                | _small_component_pixels(sk, min_spur))
        if not drop.any():
            return sk
        mask[sk.idx[drop]] = False
        _thin(mask, ring)
    return _analyse(mask, w)


def _spur_pixels(sk: _Skeleton, dflat: np.ndarray, sflat: np.ndarray, min_spur: float,
                 cfg: TopologyConfig) -> np.ndarray:
    """
    Pixels of spurs: arcs with a free end, touching at most one junction, shorter than a limit.

    The limit is ``max(min_spur, spur_factor * clearance of the junction)``, times
    ``weak_spur_factor`` for weak arcs (nearest obstacle points subtending < 60 deg on most
    pixels: mostly wall noise); a free-standing weak arc is always a spur.
    """
    arc_len = np.bincount(sk.arc[sk.arc >= 0], minlength=sk.n_arcs).astype(float)
    has_end = np.bincount(sk.arc[sk.endpoint & (sk.arc >= 0)], minlength=sk.n_arcs) > 0
    n_adj = np.bincount(sk.adj[:, 0], minlength=sk.n_arcs)
    cl_clear = np.zeros(max(sk.n_clusters, 1))
    if sk.n_clusters:
        np.maximum.at(cl_clear, sk.cluster[sk.junction], dflat[sk.idx[sk.junction]])
    limit = np.full(sk.n_arcs, min_spur)
    one = np.flatnonzero(n_adj == 1)
    if one.size:
        first = np.searchsorted(sk.adj[:, 0], one)
        limit[one] = np.maximum(min_spur, cfg.spur_factor * cl_clear[sk.adj[first, 1]])
    on_arc = sk.arc >= 0
    weak = np.bincount(sk.arc[on_arc], weights=sflat[sk.idx[on_arc]] < 1.0,
                       minlength=sk.n_arcs) > 0.5 * np.maximum(arc_len, 1)
    limit = np.where(weak, limit * cfg.weak_spur_factor, limit)
    limit[weak & (n_adj == 0)] = np.inf
    spur = has_end & (n_adj <= 1) & (arc_len < limit)
    return spur[np.maximum(sk.arc, 0)] & (sk.arc >= 0)


def _lone_cluster_pixels(sk: _Skeleton, min_spur: float) -> np.ndarray:
    """Pixels of small junction clusters whose arcs were all pruned earlier (noise)."""
    lone = np.zeros(max(sk.n_clusters, 1), dtype=bool)
    if sk.n_clusters:
        lone[:sk.n_clusters] = np.bincount(sk.adj[:, 1], minlength=sk.n_clusters) == 0
        cl_size = np.bincount(sk.cluster[sk.junction], minlength=sk.n_clusters)
        lone[:sk.n_clusters] &= cl_size < min_spur
    return lone[np.maximum(sk.cluster, 0)] & (sk.cluster >= 0)


def _small_component_pixels(sk: _Skeleton, min_spur: float) -> np.ndarray:
    """Pixels of whole skeleton components shorter than a spur (tiny loops, specks)."""
    _, comp = connected_components(sk.graph, directed=False)
    small = np.bincount(comp) < min_spur
    return small[comp]


def _topology(occ_map: OccupancyMap, nodes: np.ndarray, kinds: list[int], edges: np.ndarray,
              mask: np.ndarray, dist: np.ndarray) -> Topology:
    """Return the :class:`Topology` of the padded-grid results, in map cells and metres."""
    h, w = occ_map.shape
    wp = w + 2
    res = occ_map.resolution
    rows, cols = nodes // wp - 1, nodes % wp - 1
    clearance = np.empty((h, w), dtype=np.float32)
    for r0 in range(0, h, BAND_ROWS):           # band by band: no float64 copy of the map
        r1 = min(r0 + BAND_ROWS, h)
        clearance[r0:r1] = dist[1 + r0:1 + r1, 1:-1] * res
    return Topology(node_xy=occ_map.cell_to_world(rows, cols).reshape(-1, 2),
                    node_kind=np.asarray(kinds, dtype=np.int8),
                    node_cell=np.column_stack((rows, cols)).astype(np.int64).reshape(-1, 2),
                    node_clearance=(dist.ravel()[nodes] * res).astype(np.float64),
                    edges=edges, gvd_mask=mask.reshape(h + 2, wp)[1:-1, 1:-1].copy(),
                    clearance=clearance)


def _merge(cands: np.ndarray, score: np.ndarray, w: int, radius_cells: float) -> np.ndarray:
    """Greedy merge: keep the highest-score candidate, drop others within the radius."""
    if cands.size <= 1 or radius_cells <= 0:
        return cands
    order = np.argsort(-score, kind='stable')
    c = cands[order]
    pts = np.column_stack((c // w, c % w)).astype(float)
    tree = cKDTree(pts)
    alive = np.ones(len(c), dtype=bool)
    for i in range(len(c)):
        if alive[i]:
            near = tree.query_ball_point(pts[i], radius_cells)
            alive[near] = False
            alive[i] = True
    return c[alive]


def _far_from(cands: np.ndarray, existing: list[int], w: int, radius_cells: float) -> np.ndarray:
    if cands.size == 0 or not existing or radius_cells <= 0:
        return cands
    e = np.asarray(existing)
    tree = cKDTree(np.column_stack((e // w, e % w)).astype(float))
    d, _ = tree.query(np.column_stack((cands // w, cands % w)).astype(float))
    return cands[d > radius_cells]


def _select_nodes(sk: _Skeleton, dflat: np.ndarray, traversable: np.ndarray, w: int,
                  to_cells, cfg: TopologyConfig) -> tuple[np.ndarray, list[int]]:
    """
    Step 4: the nodes (flat padded cells) and their kinds, in the order they are chosen.

    Each kind after the branch nodes fills what the ones before it leave uncovered.
    """
    nodes: list[int] = []
    kinds: list[int] = []
    rad = to_cells(cfg.merge_radius)

    def add(cells, kind):
        nodes.extend(int(c) for c in cells)
        kinds.extend([int(kind)] * len(cells))

    if sk.n_clusters:
        add(_branch_nodes(sk, dflat, w, rad), NodeKind.BRANCH)
    if cfg.dead_end_nodes and sk.idx.size:
        add(_dead_end_nodes(sk, dflat, w, rad, nodes), NodeKind.DEAD_END)
    if cfg.region_nodes:
        if sk.idx.size:
            add(_gvd_component_nodes(sk, dflat, nodes), NodeKind.REGION)
        min_cells = to_cells(to_cells(cfg.min_region_area))
        add(_free_region_nodes(sk, dflat, traversable, w, nodes, min_cells), NodeKind.REGION)
    if cfg.arc_spacing > 0 and sk.idx.size:
        add(_arc_nodes(sk, nodes, to_cells(cfg.arc_spacing) / 2.0), NodeKind.ARC)
    return np.asarray(nodes, dtype=np.int64), kinds


def _on_skeleton(sk: _Skeleton, nodes) -> tuple[np.ndarray, np.ndarray]:
    """
    Positions of ``nodes`` (flat cells) in ``sk.idx``, and which of them are skeleton pixels.

    ``pos[on]`` are the skeleton indices of the nodes on the skeleton.
    """
    cells = np.asarray(nodes, dtype=np.int64)
    pos = np.searchsorted(sk.idx, cells)
    on = pos < len(sk.idx)
    on[on] &= sk.idx[pos[on]] == cells[on]
    return pos, on


def _branch_nodes(sk: _Skeleton, dflat: np.ndarray, w: int, radius: float) -> np.ndarray:
    """Junction clusters touching three or more arcs, each at its max-clearance pixel, merged."""
    degree = np.bincount(sk.adj[:, 1], minlength=sk.n_clusters)
    jpix = np.flatnonzero(sk.junction)
    order = jpix[np.lexsort((-dflat[sk.idx[jpix]], sk.cluster[jpix]))]
    cl = sk.cluster[order]
    best = order[np.r_[True, cl[1:] != cl[:-1]]]  # max clearance pixel per cluster
    best = best[degree[sk.cluster[best]] >= 3]
    cells = sk.idx[best]
    return _merge(cells, dflat[cells], w, radius)


def _dead_end_nodes(sk: _Skeleton, dflat: np.ndarray, w: int, radius: float,
                    nodes: list[int]) -> np.ndarray:
    """Return the ends of GVD arcs, merged, away from the nodes chosen so far."""
    cells = sk.idx[sk.endpoint]
    return _far_from(_merge(cells, dflat[cells], w, radius), nodes, w, radius)


def _gvd_component_nodes(sk: _Skeleton, dflat: np.ndarray, nodes: list[int]) -> np.ndarray:
    """One node at the max-clearance pixel of every GVD component that has no node yet."""
    n_comp, comp = connected_components(sk.graph, directed=False)
    has = np.zeros(n_comp, dtype=bool)
    pos, on = _on_skeleton(sk, nodes)
    has[comp[pos[on]]] = True
    d = dflat[sk.idx]
    order = np.lexsort((-d, comp))
    first = order[np.r_[True, comp[order][1:] != comp[order][:-1]]]
    return sk.idx[first[~has[comp[first]]]]


def _free_region_nodes(sk: _Skeleton, dflat: np.ndarray, traversable: np.ndarray, w: int,
                       nodes: list[int], min_cells: float) -> list[int]:
    """
    One node at the max-clearance cell of every traversable region without node or GVD.

    Regions smaller than ``min_cells`` cells are left out.
    """
    lab, n_reg = ndimage.label(traversable, structure=np.ones((3, 3), dtype=bool))
    if not n_reg:
        return []
    labf = lab.ravel()
    area = np.bincount(labf, minlength=n_reg + 1)
    has = np.zeros(n_reg + 1, dtype=bool)
    has[labf[np.asarray(nodes, dtype=np.int64)]] = True
    if sk.idx.size:
        has[labf[sk.idx]] = True
    want = np.flatnonzero(~has & (area >= max(min_cells, 1)))
    want = want[want > 0]
    best = []
    if want.size:
        d2 = dflat.reshape(lab.shape)
        boxes = ndimage.find_objects(lab)
        for lbl in want:
            sl = boxes[lbl - 1]
            sub = np.where(lab[sl] == lbl, d2[sl], -1.0)
            r, c = np.unravel_index(int(np.argmax(sub)), sub.shape)
            best.append((r + sl[0].start) * w + c + sl[1].start)
    return best


def _arc_nodes(sk: _Skeleton, nodes: list[int], half_spacing: float) -> np.ndarray:
    """
    Nodes along the GVD so that no skeleton pixel is farther than ``half_spacing`` from one.

    Farthest-point sampling by geodesic distance on the skeleton, from the nodes chosen so far:
    the pixel farthest from every node becomes one (the first of equals), until none is
    farther than ``half_spacing``. A new node lowers distances only within its geodesic reach,
    no shorter than the straight line: so its Dijkstra runs on the rows of skeleton pixels
    within that reach (a contiguous run of the row-major pixels) and the distances are updated
    there only; the farthest pixel is found from the maximum of each block of
    :data:`_FPS_BLOCK` pixels. The same nodes as a Dijkstra over the whole skeleton per node,
    at a cost that grows with the reach instead of the map.
    """
    pos, on = _on_skeleton(sk, nodes)
    src = np.unique(pos[on])
    n = len(sk.idx)
    if src.size:
        geo = dijkstra(sk.graph, directed=True, indices=src, min_only=True)
    else:
        geo = np.full(n, np.inf)
    if n == 0:
        return sk.idx[:0]
    rows = sk.idx // sk.width
    blocks = _BlockMax(geo)
    new = []
    while True:
        k = blocks.argmax()
        if not geo[k] > half_spacing:
            break
        new.append(k)
        lim = geo[k]
        if np.isfinite(lim):
            a = int(np.searchsorted(rows, rows[k] - math.ceil(lim), side='left'))
            b = int(np.searchsorted(rows, rows[k] + math.ceil(lim), side='right'))
        else:
            a, b = 0, n
        dk = dijkstra(sk.graph[a:b, a:b], directed=True, indices=k - a, limit=lim)
        np.minimum(geo[a:b], dk, out=geo[a:b])
        blocks.update(a, b)
    return sk.idx[new]


#: pixels per block of the farthest-point sampling's running maximum
_FPS_BLOCK = 2048


class _BlockMax:
    """The first index of the largest value of an array, kept per block as parts change."""

    def __init__(self, values: np.ndarray) -> None:
        self.values = values
        n = len(values)
        self.n_blocks = -(-n // _FPS_BLOCK)
        padded = np.full(self.n_blocks * _FPS_BLOCK, -np.inf)
        padded[:n] = values
        self.block_max = padded.reshape(self.n_blocks, _FPS_BLOCK).max(axis=1)

    def update(self, a: int, b: int) -> None:
        """Refresh the maxima of the blocks holding ``values[a:b]``."""
        for blk in range(a // _FPS_BLOCK, (b - 1) // _FPS_BLOCK + 1):
            self.block_max[blk] = self.values[blk * _FPS_BLOCK:(blk + 1) * _FPS_BLOCK].max()

    def argmax(self) -> int:
        """Return the first index of the largest value (as ``np.argmax`` of the values)."""
        blk = int(np.argmax(self.block_max))
        lo = blk * _FPS_BLOCK
        return lo + int(np.argmax(self.values[lo:lo + _FPS_BLOCK]))


def _edges(sk: _Skeleton, nodes: np.ndarray) -> np.ndarray:
    """Step 5: pairs of nodes whose geodesic territories on the GVD touch."""
    if sk.idx.size == 0 or nodes.size < 2:
        return np.zeros((0, 2), dtype=np.int64)
    pos, on = _on_skeleton(sk, nodes)
    if on.sum() < 2:
        return np.zeros((0, 2), dtype=np.int64)
    node_of = np.full(len(sk.idx), -1, dtype=np.int64)
    node_of[pos[on]] = np.flatnonzero(on)
    _, _, sources = dijkstra(sk.graph, directed=True, indices=pos[on], min_only=True,
                             return_predecessors=True)
    owner = np.where(sources >= 0, node_of[np.maximum(sources, 0)], -1)
    a, b = owner[sk.er], owner[sk.ec]
    ok = (a >= 0) & (b >= 0) & (a != b)
    if not ok.any():
        return np.zeros((0, 2), dtype=np.int64)
    pairs = np.sort(np.column_stack((a[ok], b[ok])), axis=1)
    return np.unique(pairs, axis=0)
