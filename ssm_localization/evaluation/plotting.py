"""
Figures people would rather see than read (PNG via matplotlib, imported on first use).

Figures are written atomically (nothing is left behind when saving fails); callers check the
path first with :func:`check_plot_path`, before the work that the figure shows.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from ..files.writing import atomic_files, check_output_file
from ..localization.localizer import AMBIGUOUS, FAILED, OK
from ..localization.tracker import RELOCALIZED
from ..mapping.topology import NODE_KIND_NAMES
from ..transforms import apply

#: file name endings matplotlib writes (the format follows the ending)
PLOT_SUFFIXES = ('.png', '.pdf', '.svg', '.svgz', '.jpg', '.jpeg', '.tif', '.tiff', '.webp',
                 '.eps', '.ps')


def check_plot_path(path: str | Path, inputs: Iterable[str | Path | None] = ()) -> Path:
    """``path`` after checking a figure can be written there, over none of ``inputs``."""
    p = check_output_file(path, 'plot file', inputs)
    if p.suffix.lower() not in PLOT_SUFFIXES:
        raise ValueError(f'plot file {p}: expected a name ending in {", ".join(PLOT_SUFFIXES)}')
    return p


def _save(plt, fig, path: str | Path, dpi: int) -> Path:
    """Write ``fig`` to ``path`` atomically and close it."""
    try:
        with atomic_files(check_plot_path(path), what='plot file') as (tmp,):
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)
    return Path(path)


def _pyplot():
    """
    Import matplotlib's pyplot on the Agg backend.

    matplotlib is optional: it is imported here only.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def _draw_map(ax, grid) -> tuple[float, float, float, float]:
    """Draw ``grid`` (OccupancyMap) on ``ax`` in map coordinates; return its extent."""
    h, w = grid.data.shape
    ox, oy, _ = grid.origin
    extent = (ox, ox + w * grid.resolution, oy, oy + h * grid.resolution)
    img = np.where(grid.data < 0, 0.75, 1.0 - np.clip(grid.data, 0, 100) / 100.0)
    ax.imshow(img, cmap='gray', origin='lower', extent=extent, vmin=0, vmax=1,
              interpolation='nearest')
    return extent


def _map_figure(grid, width: float, extra_height: float):
    """
    Return a figure showing ``grid`` (OccupancyMap) in map coordinates.

    ``(plt, fig, ax, extent)``.
    """
    plt = _pyplot()
    h, w = grid.data.shape
    fig, ax = plt.subplots(figsize=(width, width * h / max(w, 1) + extra_height))
    return plt, fig, ax, _draw_map(ax, grid)


def plot_replay(index, rows, path, title: str = '') -> None:
    """Map, topological nodes, ground truth and estimates (colored by status) of a replay."""
    plt, fig, ax, _ = _map_figure(index.map, 9, 0.5)
    ax.scatter(index.node_xy[:, 0], index.node_xy[:, 1], s=6, c='tab:blue', alpha=0.5,
               label='nodes')
    colors = {OK: 'tab:green', AMBIGUOUS: 'tab:orange', FAILED: 'tab:red'}
    gt = np.array([(r.gt_x, r.gt_y) for r in rows if r.has_truth])
    if len(gt):
        ax.scatter(gt[:, 0], gt[:, 1], s=28, facecolors='none', edgecolors='k',
                   label='ground truth')
    for status, color in colors.items():
        sel = [r for r in rows if r.status == status and not np.isnan(r.x)]
        if not sel:
            continue
        xy = np.array([(r.x, r.y) for r in sel])
        yaw = np.array([r.yaw for r in sel])
        ax.quiver(xy[:, 0], xy[:, 1], np.cos(yaw), np.sin(yaw), color=color, scale=40, width=0.003,
                  label=f'{status} ({len(sel)})')
        wrong = [r for r in sel if r.has_truth and not r.correct]
        for r in wrong:
            ax.plot([r.x, r.gt_x], [r.y, r.gt_y], color='tab:red', lw=0.8)
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(title or 'single-scan global localization')
    ax.legend(loc='upper right', fontsize=8)
    ax.set_aspect('equal')
    fig.tight_layout()
    _save(plt, fig, path, dpi=110)


def plot_track(grid, rows, path, kidnaps=(), title: str = '') -> None:
    """
    Plot a tracked replay.

    The map with the ground-truth path and the estimates by mode (top); the position error and
    the latency of every scan, with the kidnaps and relocalizations (below).
    """
    plt = _pyplot()
    aspect = grid.data.shape[0] / max(grid.data.shape[1], 1)
    fig, (ax, ax_err, ax_lat) = plt.subplots(
        3, 1, figsize=(9, 9 * aspect + 4.0),
        gridspec_kw={'height_ratios': [max(6.0 * aspect, 3.0), 1.0, 1.0]})
    _draw_map(ax, grid)
    gt = np.array([(r.gt_x, r.gt_y) for r in rows])
    ax.plot(gt[:, 0], gt[:, 1], '-', color='k', lw=0.6, alpha=0.6, label='ground truth')
    marks = {'tracked': ('tab:green', '.'), 'relocalized': ('tab:blue', 'o'),
             'lost': ('tab:red', 'x')}
    for mode, (color, marker) in marks.items():
        sel = np.array([(r.x, r.y) for r in rows if r.mode == mode and not np.isnan(r.x)])
        if len(sel):
            ax.plot(sel[:, 0], sel[:, 1], marker, color=color, ms=4, ls='none',
                    label=f'{mode} ({len(sel)})')
    for r in rows:
        if r.wrong:         # a confident wrong answer: a line to the truth
            ax.plot([r.x, r.gt_x], [r.y, r.gt_y], color='tab:red', lw=1.0)
    ax.set_title(title or 'tracking')
    ax.set_aspect('equal')
    ax.legend(loc='upper right', fontsize=8)
    k = np.arange(len(rows))
    err = np.hypot(gt[:, 0] - [r.x for r in rows], gt[:, 1] - [r.y for r in rows])
    ok = np.array([r.status == OK for r in rows])
    ax_err.semilogy(k[ok], np.maximum(err[ok], 1e-3), '.', color='tab:green', ms=3, label='ok')
    ax_err.semilogy(k[~ok], np.maximum(np.nan_to_num(err[~ok], nan=1e-3), 1e-3), 'x',
                    color='tab:orange', ms=4, label='not ok')
    ax_err.axhline(0.5, color='tab:red', lw=0.6)
    ax_err.set_ylabel('position error [m]')
    ax_lat.plot(k, [r.latency_ms for r in rows], '-', color='tab:gray', lw=0.7)
    ax_lat.set_ylabel('latency [ms]')
    ax_lat.set_xlabel('scan')
    for a in (ax_err, ax_lat):
        for j in kidnaps:
            a.axvline(j, color='tab:purple', lw=0.8, ls='--')
        for j in k[[r.mode == RELOCALIZED for r in rows]]:
            a.axvline(j, color='tab:blue', lw=0.4, alpha=0.5)
        a.set_xlim(-1, len(rows))
    ax_err.legend(loc='upper right', fontsize=7)
    fig.tight_layout()
    _save(plt, fig, path, dpi=110)


def plot_index(index, path, title: str = '', show_ids: bool = True) -> None:
    """Map, GVD and topological nodes (colored by kind, with their ids) of a ``MapIndex``."""
    plt, fig, ax, extent = _map_figure(index.map, 10, 0.8)
    h, w = index.map.data.shape
    gvd = np.ma.masked_where(~np.asarray(index.gvd_mask, dtype=bool), np.ones((h, w)))
    ax.imshow(gvd, cmap='autumn', origin='lower', extent=extent, alpha=0.6,
              interpolation='nearest')
    xy = np.asarray(index.node_xy).reshape(-1, 2)
    for a, b in np.asarray(getattr(index, 'edges', np.zeros((0, 2))), dtype=int).reshape(-1, 2):
        ax.plot(xy[[a, b], 0], xy[[a, b], 1], color='tab:gray', lw=0.5, alpha=0.6)
    kinds = np.asarray(index.node_kind)
    colors = ('tab:red', 'tab:green', 'tab:blue', 'tab:purple')
    for k, name in enumerate(NODE_KIND_NAMES):
        sel = kinds == k
        if sel.any():
            ax.scatter(xy[sel, 0], xy[sel, 1], s=18, c=colors[k % len(colors)], zorder=3,
                       label=f'{name} ({int(sel.sum())})')
    if show_ids and len(xy) <= 2000:
        size = 6 if len(xy) < 200 else 4
        for i, (x, y) in enumerate(xy):
            ax.annotate(str(i), (x, y), xytext=(2, 2), textcoords='offset points',
                        fontsize=size, zorder=4)
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(title or f'topological index: {len(xy)} nodes')
    if len(xy):
        ax.legend(loc='upper right', fontsize=8)
    ax.set_aspect('equal')
    fig.tight_layout()
    _save(plt, fig, path, dpi=120)


def plot_match(ref_xy, new_xy, pose, out, pairs=None, truth=None, title: str = ''):
    """
    Plot two panels: the scans as given, and aligned by the estimate.

    Left, the new scan drawn in the reference frame at ``truth`` if known (else unaligned); right,
    the new scan moved by the estimated ``pose`` over the reference, with the ``pairs`` (K, 2)
    correspondences (indices into ref_xy / new_xy) as segments. Writes a PNG to ``out`` and
    returns its path.
    """
    plt = _pyplot()
    ref = np.asarray(ref_xy, float).reshape(-1, 2)
    new = np.asarray(new_xy, float).reshape(-1, 2)
    fig, axes = plt.subplots(1, 2, figsize=(13, 6.2))
    ax = axes[0]
    ax.plot(ref[:, 0], ref[:, 1], '.', color='tab:red', ms=3, label='reference')
    ax.plot(new[:, 0], new[:, 1], '.', color='tab:blue', ms=3, label='new (as given)')
    ax.set_title('before matching')
    ax = axes[1]
    ok = pose is not None and np.all(np.isfinite(pose))
    moved = apply(pose, new) if ok else new
    if pairs is not None and len(pairs) and ok:
        pr = np.asarray(pairs, int)
        a, b = ref[pr[:, 0]], moved[pr[:, 1]]
        gap = np.full(len(pr), np.nan)     # one polyline, NaN-separated segments a -> b
        ax.plot(np.column_stack((a[:, 0], b[:, 0], gap)).ravel(),
                np.column_stack((a[:, 1], b[:, 1], gap)).ravel(), color='0.6', lw=0.6,
                label=f'{len(pr)} correspondences')
    ax.plot(ref[:, 0], ref[:, 1], '.', color='tab:red', ms=3, label='reference')
    ax.plot(moved[:, 0], moved[:, 1], '.', color='tab:blue', ms=3, label='new at estimate')
    if truth is not None:
        tt = apply(truth, new)
        ax.plot(tt[:, 0], tt[:, 1], '.', color='tab:green', ms=1.5, alpha=0.5,
                label='new at truth')
    ax.set_title('after matching' if ok else 'matching failed')
    for ax in axes:
        ax.plot(0, 0, 'k^', ms=8)
        ax.set_aspect('equal', adjustable='datalim')
        ax.grid(True, lw=0.3)
        ax.set_xlabel('x [m]')
        ax.legend(loc='best', fontsize=8)
    axes[0].set_ylabel('y [m]')
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(plt, fig, out, dpi=110)


def plot_soak(samples, warmup_s: float, path: str | Path) -> Path:
    """RSS and pose rate of a soak run over time: ``samples`` of (seconds, MB, poses/s)."""
    plt = _pyplot()
    t, rss, rate = (np.array(v, float) for v in zip(*samples)) if samples else ([], [], [])
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(t, rss, 'b-', label='node RSS (MB)')
    ax.axvline(warmup_s, color='grey', ls=':', label='end of warm-up')
    ax.set_xlabel('time (s)')
    ax.set_ylabel('RSS (MB)')
    ax.set_ylim(0, max(list(rss) + [1.0]) * 1.2)
    twin = ax.twinx()
    twin.plot(t, rate, 'g.', label='poses / s')
    twin.set_ylabel('poses / s')
    ax.legend(loc='lower left')
    twin.legend(loc='lower right')
    ax.set_title('global_localizer, continuous mode on a looping bag')
    return _save(plt, fig, path, 100)


def plot_reliability(tables, path: str | Path, min_count: int = 50) -> Path:
    """
    Draw reliability diagrams: mean reported confidence vs fraction right, per bin and split.

    ``tables`` maps a label (a split) to its ``calibration.reliability`` bins; bins with fewer
    than ``min_count`` answers are drawn hollow. The band around the diagonal is +-2 points; each
    bin's bar is the 95 % (Wilson) interval of its fraction right.
    """
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(tables), figsize=(5.0 * len(tables), 5.0), squeeze=False)
    for ax, (label, bins) in zip(axes[0], tables.items()):
        ax.fill_between([0, 1], [-0.02, 0.98], [0.02, 1.02], color='0.85', label='+-2 points')
        ax.plot([0, 1], [0, 1], 'k:', lw=1)
        used = [b for b in bins if b.count]
        for b in used:
            big = b.count >= min_count
            low, high = b.interval()
            ax.plot([b.mean_confidence] * 2, [low, high], '-', color='tab:blue', lw=1)
            ax.plot(b.mean_confidence, b.observed, 'o', ms=4 + 3 * np.log10(b.count),
                    mfc='tab:blue' if big else 'none', mec='tab:blue')
            ax.annotate(str(b.count), (b.mean_confidence, b.observed), fontsize=7,
                        xytext=(4, -10), textcoords='offset points')
        total = sum(b.count for b in used)
        ax.set(xlim=(-0.02, 1.02), ylim=(-0.02, 1.02), xlabel='reported confidence (bin mean)',
               ylabel='fraction right', title=f'{label} split: {total} answers')
        ax.legend(loc='upper left', fontsize=8)
    fig.tight_layout()
    return _save(plt, fig, path, dpi=110)
