"""topology: brushfire, GVD and nodes on maps with a known answer (paper section III)."""
from __future__ import annotations

from helpers import shared_data
import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra
from ssm_localization import load_map_yaml, OccupancyMap, TopologyConfig
from ssm_localization.bench.synthetic import office_map
from ssm_localization.mapping import topology
from ssm_localization.mapping.topology import build_topology, NODE_KIND_NAMES, NodeKind

RES = 0.05
ONLY_BRANCHES = TopologyConfig(dead_end_nodes=False, region_nodes=False, arc_spacing=0.0)


def _grid(kind: str) -> OccupancyMap:
    d = np.full((200, 200), 100, np.int8)
    if kind == 'plus':    # two 2 m corridors crossing at (5, 5) m
        d[80:120, 10:190] = 0
        d[10:190, 80:120] = 0
    elif kind == 'T':     # horizontal corridor on top, stem downwards
        d[120:160, 10:190] = 0
        d[10:160, 80:120] = 0
    elif kind == 'ring':  # a 2 m wide square ring corridor
        d[20:180, 20:180] = 0
        d[60:140, 60:140] = 100
    elif kind == 'room':
        d[10:190, 10:150] = 0
    return OccupancyMap(d, RES, (0.0, 0.0, 0.0))


def test_plus_has_one_branch_at_the_crossing():
    topo = build_topology(_grid('plus'), ONLY_BRANCHES)
    assert topo.node_kind.tolist() == [NodeKind.BRANCH]
    assert np.linalg.norm(topo.node_xy[0] - (5.0, 5.0)) < 0.15
    # the GVD runs along both corridor centre lines
    assert topo.gvd_mask[100, 30:170].sum() + topo.gvd_mask[99, 30:170].sum() >= 130


def test_t_has_one_branch():
    topo = build_topology(_grid('T'), ONLY_BRANCHES)
    assert topo.node_kind.tolist() == [NodeKind.BRANCH]
    x, y = topo.node_xy[0]
    assert abs(x - 5.0) < 0.15
    assert 6.4 < y < 7.1  # equidistant to the far wall and the two corners (~ 1 m / 4 below)


def test_ring_has_no_branch_but_extras_give_nodes():
    ring = _grid('ring')
    assert len(build_topology(ring, ONLY_BRANCHES)) == 0
    topo = build_topology(ring)  # defaults: extras on
    counts = topo.kind_counts()
    assert counts['branch'] == 0
    assert counts['region'] == 1 and counts['arc'] >= 8
    # arc nodes are spaced at most arc_spacing apart along the 24 m loop
    assert len(topo) >= 24.0 / TopologyConfig().arc_spacing
    # all nodes lie on the loop centre line (1 m from the walls, more at the corners)
    assert (topo.node_clearance >= 0.95).all() and (topo.node_clearance <= 1.45).all()
    assert np.median(topo.node_clearance) == pytest.approx(1.0, abs=0.05)
    # the nodes form one cycle: every node has exactly two neighbours
    deg = np.bincount(topo.edges.ravel(), minlength=len(topo))
    assert (deg == 2).all()


def test_plus_extras_dead_ends_and_arcs():
    topo = build_topology(_grid('plus'))
    counts = topo.kind_counts()
    assert counts['branch'] == 1 and counts['dead_end'] == 4
    dead = topo.node_xy[topo.node_kind == NodeKind.DEAD_END]
    # one dead end near the end of each arm
    for end in ((0.5, 5.0), (9.5, 5.0), (5.0, 0.5), (5.0, 9.5)):
        assert np.linalg.norm(dead - end, axis=1).min() < 1.0
    # edges connect the branch node to every arm
    branch = int(np.flatnonzero(topo.node_kind == NodeKind.BRANCH)[0])
    assert (topo.edges == branch).any(axis=1).sum() == 4


def test_rectangular_room_prunes_corner_spurs():
    topo = build_topology(_grid('room'))
    counts = topo.kind_counts()
    assert counts['branch'] == 0  # the bisectors into the four corners are spurs
    assert len(topo) >= 1


def test_narrow_passage_below_min_clearance_is_ignored():
    d = np.full((100, 200), 100, np.int8)
    d[10:90, 10:90] = 0
    d[10:90, 110:190] = 0
    d[48:52, 90:110] = 0  # a 0.2 m slot joins the rooms
    m = OccupancyMap(d, RES)
    topo = build_topology(m, TopologyConfig(min_clearance=0.2))
    assert not topo.gvd_mask[:, 92:108].any()
    assert (topo.node_xy[:, 0] < 4.5).any() and (topo.node_xy[:, 0] > 5.5).any()
    assert not ((topo.node_xy[:, 0] > 4.6) & (topo.node_xy[:, 0] < 5.4)).any()


def test_clearance_is_brushfire_distance():
    topo = build_topology(_grid('room'))
    # cell (100, 30) is 21 cells from the left wall (column 9), farther from all others
    assert topo.clearance[100, 30] == pytest.approx(21 * RES, abs=1e-6)
    assert topo.clearance[0, 0] == 0.0
    assert topo.gvd_mask.shape == (200, 200)


def test_unknown_counts_as_obstacle():
    m = _grid('plus')
    d = m.data.copy()
    d[d == 100] = -1
    a = build_topology(OccupancyMap(d, RES), ONLY_BRANCHES)
    assert len(a) == 1 and np.linalg.norm(a.node_xy[0] - (5.0, 5.0)) < 0.15


def test_empty_map_and_all_free_map():
    full = OccupancyMap(np.full((50, 50), 100, np.int8), RES)
    topo = build_topology(full)
    assert len(topo) == 0 and topo.edges.shape == (0, 2) and not topo.gvd_mask.any()
    free = OccupancyMap(np.zeros((60, 60), np.int8), RES)  # the map border bounds it
    topo = build_topology(free)
    assert len(topo) >= 1 and topo.kind_counts()['branch'] == 0


def test_config_validation_and_kind_names():
    assert NODE_KIND_NAMES == ('branch', 'dead_end', 'region', 'arc')
    with pytest.raises(ValueError, match='min_clearance'):
        TopologyConfig(min_clearance=-1.0)
    with pytest.raises(ValueError, match='free_thresh'):
        TopologyConfig(free_thresh=120)


@pytest.mark.parametrize('name', ['depot', 'tb3_sandbox', 'turtlebot3_world', 'empty_room'])
def test_shared_maps(name):
    m = load_map_yaml(shared_data('maps', f'{name}.yaml'))
    topo = build_topology(m)
    assert len(topo) > 0
    # every node is traversable: free and at least min_clearance from obstacles
    r, c = topo.node_cell.T
    assert (m.free_mask()[r, c]).all()
    assert (topo.node_clearance >= TopologyConfig().min_clearance - 1e-9).all()
    counts = topo.kind_counts()
    if name == 'empty_room':
        assert counts['branch'] == 0 and len(topo) >= 2  # nodes only from the extras
    else:
        assert counts['branch'] >= 5


@pytest.mark.parametrize('angle', [0.35, 0.7, 0.87, 1.22])
def test_rotated_plus_staircase_walls(angle):
    """Walls at odd angles are pixel staircases: still one branch node and four dead ends."""
    n = 300
    yy, xx = (np.mgrid[0:n, 0:n] + 0.5) * RES
    cx = cy = n * RES / 2
    u = (xx - cx) * np.cos(angle) + (yy - cy) * np.sin(angle)
    v = -(xx - cx) * np.sin(angle) + (yy - cy) * np.cos(angle)
    free = ((np.abs(u) < 6) & (np.abs(v) < 0.5)) | ((np.abs(v) < 6) & (np.abs(u) < 0.5))
    topo = build_topology(OccupancyMap(np.where(free, 0, 100).astype(np.int8), RES))
    counts = topo.kind_counts()
    assert counts['branch'] == 1 and counts['dead_end'] == 4
    assert np.linalg.norm(topo.node_xy[topo.node_kind == NodeKind.BRANCH][0] - (cx, cy)) < 0.2


@pytest.mark.parametrize('res', [0.025, 0.1])
@pytest.mark.parametrize('width', [0.6, 3.0])
def test_corridor_widths_and_resolutions(res, width):
    n = int(round(12 / res))
    hw, c, a = int(round(width / 2 / res)), n // 2, int(round(1 / res))
    plus = np.full((n, n), 100, np.int8)
    plus[c - hw:c + hw, a:n - a] = 0
    plus[a:n - a, c - hw:c + hw] = 0
    ell = np.full((n, n), 100, np.int8)
    ell[c - hw:c + hw, a:c + hw] = 0
    ell[a:c + hw, c - hw:c + hw] = 0
    assert build_topology(OccupancyMap(plus, res)).kind_counts()['branch'] == 1
    topo = build_topology(OccupancyMap(ell, res))
    assert topo.kind_counts()['branch'] == 0 and topo.kind_counts()['dead_end'] == 2


@pytest.mark.parametrize('name', ['depot', 'turtlebot3_world'])
def test_a_resolution_off_in_its_8th_digit_gives_the_same_nodes(name):
    """
    Lengths are compared in cells with the settings rounded once.

    No comparison flips when the resolution changes by far less than a cell (the case: the
    float32 resolution of a map message).
    """
    occ = load_map_yaml(shared_data('maps', f'{name}.yaml'))
    base = build_topology(occ)
    for factor in (1.0 + 3e-7, 1.0 - 3e-7):
        other = build_topology(OccupancyMap(occ.data, occ.resolution * factor, occ.origin))
        a = np.sort(np.ravel_multi_index(occ.world_to_cell(base.node_xy), occ.shape))
        b = np.sort(np.ravel_multi_index(occ.world_to_cell(other.node_xy), occ.shape))
        assert np.array_equal(a, b), factor
        assert np.array_equal(np.sort(base.node_kind), np.sort(other.node_kind))


def _sequential_arc_nodes(sk, nodes, half_spacing):
    """Farthest-point sampling as first written: a Dijkstra over the whole skeleton per node."""
    pos, on = topology._on_skeleton(sk, nodes)
    src = np.unique(pos[on])
    geo = (dijkstra(sk.graph, directed=True, indices=src, min_only=True) if src.size
           else np.full(len(sk.idx), np.inf))
    new = []
    while True:
        k = int(np.argmax(geo))
        if not geo[k] > half_spacing:
            break
        new.append(k)
        lim = geo[k] if np.isfinite(geo[k]) else np.inf
        np.minimum(geo, dijkstra(sk.graph, directed=True, indices=k, limit=lim), out=geo)
    return sk.idx[new]


@pytest.mark.parametrize('seed', [0, 1])
def test_arc_nodes_are_those_of_the_sequential_sampling(monkeypatch, seed):
    """The banded sampling picks the very nodes of a whole-skeleton Dijkstra per node."""
    occ = office_map(size=40.0, seed=seed)
    fast = build_topology(occ)
    monkeypatch.setattr(topology, '_arc_nodes', _sequential_arc_nodes)
    slow = build_topology(occ)
    assert fast.kind_counts()['arc'] > 20
    assert np.array_equal(fast.node_xy, slow.node_xy)
    assert np.array_equal(fast.node_kind, slow.node_kind)
    assert np.array_equal(fast.edges, slow.edges)
