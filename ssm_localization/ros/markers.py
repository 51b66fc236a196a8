"""
visualization_msgs/MarkerArray views of a MapIndex and of the last localization.

The array always starts with a DELETEALL marker, so re-publishing replaces what RViz shows.
Namespaces: ``nodes`` (spheres colored by node kind), ``node_ids`` (text), ``gvd`` (points),
``candidates`` (arrows colored by rank, best = green), ``scan`` (the matched scan, points).
"""
from __future__ import annotations

from typing import Any, Sequence

from geometry_msgs.msg import Point
import numpy as np
from ssm_localization.mapping.topology import NODE_KIND_NAMES
from ssm_localization.ros.conversions import pose_msg, time_msg
from ssm_localization.transforms import apply, compose
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

# Node kind -> RGB; kinds the topology module uses are matched by name (case-insensitive
# substring), anything else gets a palette color by its rank among the kinds present.
_KIND_COLORS = {
    'branch': (0.10, 0.45, 0.95),
    'junction': (0.10, 0.45, 0.95),
    'dead': (0.95, 0.35, 0.10),
    'end': (0.95, 0.35, 0.10),
    'arc': (0.15, 0.75, 0.30),
    'region': (0.75, 0.25, 0.85),
    'extra': (0.95, 0.80, 0.10),
}
_PALETTE = [(0.10, 0.45, 0.95), (0.95, 0.35, 0.10), (0.15, 0.75, 0.30), (0.75, 0.25, 0.85),
            (0.95, 0.80, 0.10), (0.10, 0.80, 0.85), (0.55, 0.35, 0.20), (0.50, 0.50, 0.50)]


def _color(rgb: Sequence[float], a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(a))


def _point(x: float, y: float, z: float = 0.0) -> Point:
    return Point(x=float(x), y=float(y), z=float(z))


def kind_name(kind: Any) -> str:
    """Return a node kind as a name (``mapping.topology.NODE_KIND_NAMES`` for integer codes)."""
    if isinstance(kind, (int, np.integer)) and not isinstance(kind, bool):
        if 0 <= int(kind) < len(NODE_KIND_NAMES):
            return NODE_KIND_NAMES[int(kind)]
    return str(kind).lower()


def kind_color(kind: Any, kinds_present: Sequence[Any]) -> tuple[float, float, float]:
    """RGB of a node kind (a name or an integer code)."""
    name = kind_name(kind)
    for key, rgb in _KIND_COLORS.items():
        if key in name:
            return rgb
    ordered = sorted({kind_name(k) for k in kinds_present} | {name})
    return _PALETTE[ordered.index(name) % len(_PALETTE)]


def rank_color(rank: int, count: int) -> tuple[float, float, float]:
    """Green for the best candidate, through yellow to red for the worst shown."""
    t = 0.0 if count <= 1 else rank / (count - 1)
    return (min(1.0, 2.0 * t), min(1.0, 2.0 * (1.0 - t)), 0.1)


def _base(frame_id: str, stamp: Any, ns: str, mid: int, mtype: int) -> Marker:
    m = Marker()
    m.header.frame_id = frame_id
    m.header.stamp = time_msg(stamp)
    m.ns = ns
    m.id = mid
    m.type = mtype
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    m.frame_locked = False
    return m


def delete_all(frame_id: str, stamp: Any = 0) -> Marker:
    m = Marker()
    m.header.frame_id = frame_id
    m.header.stamp = time_msg(stamp)
    m.action = Marker.DELETEALL
    return m


def gvd_points(index, max_points: int = 20000) -> np.ndarray:
    """World coordinates of GVD cells, evenly subsampled to at most ``max_points``."""
    mask = getattr(index, 'gvd_mask', None)
    if mask is None:
        return np.zeros((0, 2))
    rows, cols = np.nonzero(np.asarray(mask, dtype=bool))
    if rows.size > max_points > 0:
        keep = np.linspace(0, rows.size - 1, max_points).astype(int)
        rows, cols = rows[keep], cols[keep]
    if rows.size == 0:
        return np.zeros((0, 2))
    return np.asarray(index.map.cell_to_world(rows, cols), dtype=np.float64).reshape(-1, 2)


def index_markers(index, frame_id: str, stamp: Any = 0, max_gvd_points: int = 20000,
                  node_scale: float = 0.25, labels: bool = True,
                  kind_text: bool = False) -> list[Marker]:
    """Markers of an index: GVD points, node spheres colored by kind, node id labels."""
    markers: list[Marker] = []
    res = float(getattr(index.map, 'resolution', 0.05))
    pts = gvd_points(index, max_gvd_points)
    if len(pts):
        gvd = _base(frame_id, stamp, 'gvd', 0, Marker.POINTS)
        gvd.scale.x = gvd.scale.y = max(res, 0.02)
        gvd.color = _color((0.6, 0.6, 0.6), 0.8)
        gvd.points = [_point(x, y, 0.01) for x, y in pts]
        markers.append(gvd)
    node_xy = np.asarray(index.node_xy, dtype=np.float64).reshape(-1, 2)
    kinds = list(np.asarray(getattr(index, 'node_kind', np.zeros(len(node_xy))))) \
        if len(node_xy) else []
    if len(node_xy):
        nodes = _base(frame_id, stamp, 'nodes', 0, Marker.SPHERE_LIST)
        nodes.scale.x = nodes.scale.y = nodes.scale.z = node_scale
        present = sorted({kind_name(k) for k in kinds})
        nodes.points = [_point(x, y, 0.05) for x, y in node_xy]
        nodes.colors = [_color(kind_color(k, present)) for k in kinds]
        nodes.color = _color((1.0, 1.0, 1.0))
        markers.append(nodes)
        if labels:
            for i, (x, y) in enumerate(node_xy):
                text = _base(frame_id, stamp, 'node_ids', i, Marker.TEXT_VIEW_FACING)
                text.pose.position = _point(x, y, 0.3)
                text.scale.z = node_scale
                text.color = _color((1.0, 1.0, 1.0), 0.9)
                text.text = f'{i} {kind_name(kinds[i])}' if kind_text else str(i)
                markers.append(text)
    return markers


def localization_markers(localization, frame_id: str, stamp: Any = 0, top_n: int = 5,
                         scan_xy_laser: np.ndarray | None = None,
                         laser_pose=(0.0, 0.0, 0.0), node_xy: np.ndarray | None = None,
                         max_scan_points: int = 5000) -> list[Marker]:
    """Markers of a localization: top-N candidate poses (by rank) and the scan in the map frame."""
    markers: list[Marker] = []
    cands = list(getattr(localization, 'candidates', None) or [])[:max(int(top_n), 0)]
    for rank, cand in enumerate(cands):
        pose = getattr(cand, 'pose', None)
        if pose is None or not np.all(np.isfinite(np.asarray(pose, dtype=float))):
            continue
        rgb = rank_color(rank, len(cands))
        arrow = _base(frame_id, stamp, 'candidates', rank, Marker.ARROW)
        arrow.pose = pose_msg(pose)
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.6, 0.1, 0.1
        arrow.color = _color(rgb)
        markers.append(arrow)
        label = _base(frame_id, stamp, 'candidate_labels', rank, Marker.TEXT_VIEW_FACING)
        label.pose.position = _point(pose[0], pose[1], 0.45)
        label.scale.z = 0.2
        label.color = _color(rgb)
        label.text = f'#{rank + 1} node {getattr(cand, "node", -1)} ' \
                     f'score {float(getattr(cand, "score", float("nan"))):.3g}'
        if rank == 0:               # the answer's own calibrated confidence
            label.text += (f' | {getattr(localization, "status", "")} P(right) '
                           f'{float(getattr(localization, "confidence", float("nan"))):.3f}')
        markers.append(label)
        node = getattr(cand, 'node', -1)
        if node_xy is not None and node is not None and 0 <= int(node) < len(node_xy):
            link = _base(frame_id, stamp, 'candidate_links', rank, Marker.LINE_LIST)
            link.scale.x = 0.03
            link.color = _color(rgb, 0.6)
            nx, ny = node_xy[int(node)]
            link.points = [_point(nx, ny, 0.05), _point(pose[0], pose[1], 0.05)]
            markers.append(link)
    pose = getattr(localization, 'pose', None)
    if scan_xy_laser is not None and len(scan_xy_laser) and pose is not None \
            and np.all(np.isfinite(np.asarray(pose, dtype=float))):
        pts = apply(compose(pose, laser_pose), np.asarray(scan_xy_laser, dtype=float))
        if len(pts) > max_scan_points:
            pts = pts[np.linspace(0, len(pts) - 1, max_scan_points).astype(int)]
        scan = _base(frame_id, stamp, 'scan', 0, Marker.POINTS)
        scan.scale.x = scan.scale.y = 0.06
        scan.color = _color((1.0, 0.1, 0.1))
        scan.points = [_point(x, y, 0.1) for x, y in pts]
        markers.append(scan)
    return markers


def marker_array(markers: Sequence[Marker], frame_id: str, stamp: Any = 0) -> MarkerArray:
    """DELETEALL followed by ``markers``."""
    return MarkerArray(markers=[delete_all(frame_id, stamp), *markers])
