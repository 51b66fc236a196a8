"""
ssm_localization: single-scan global localization with spectral scan matching (Park & Park).

The public Python API is re-exported here; import it from ``ssm_localization`` (the module paths
below it may change). Each name is imported on first use (PEP 562), so ``import
ssm_localization`` loads nothing heavy and the localization core needs only numpy and scipy:
PyYAML, Pillow, tqdm, rosbags and matplotlib are loaded by the names that read files, draw
progress bars, read bags or plot. Layers, each importing only the ones before it:

- ``config``: settings dataclasses and YAML params files;
- ``matching``: spectral scan matching (paper section II), ``match_scans``;
- ``mapping``: map files, GVD topology, ray casting and the topological index (section III);
- ``localization``: global localization on an index (section IV), refinement, verification,
  and tracking with odometry (``Tracker``);
- ``io``: rosbag2 bags, CARMEN logs, simulated scans;
- ``evaluation``: offline replay against ground truth, figures;
- ``cli``, ``bench``, ``ros``: the command line, benchmarks and ROS 2 nodes.
"""
from __future__ import annotations

import importlib

__version__ = '0.1.0'

#: public name -> the module (below this package) it comes from
_EXPORTS = {
    # settings
    'IndexConfig': 'config', 'LocalizerConfig': 'config', 'MapBuildConfig': 'config',
    'MatcherConfig': 'config', 'SimulationConfig': 'config', 'TopologyConfig': 'config',
    'TrackerConfig': 'config', 'load_configs': 'config.params',
    'load_index_config': 'config.params', 'load_tracker_config': 'config.params',
    # scan matching
    'MatchResult': 'matching.matcher', 'match_features': 'matching.matcher',
    'match_scans': 'matching.matcher', 'ScanFeatures': 'matching.features',
    'prepare_scan': 'matching.features',
    # maps and the index
    'MapIndex': 'mapping.index', 'build_index': 'mapping.index', 'load_index': 'mapping.index',
    'save_index': 'mapping.index', 'NodeKind': 'mapping.topology',
    'OccupancyMap': 'mapping.occupancy', 'occupancy_map_from_msg': 'mapping.occupancy',
    'load_map_yaml': 'mapping.map_io', 'save_map_yaml': 'mapping.map_io',
    # localization
    'GlobalLocalizer': 'localization.localizer', 'Localization': 'localization.localizer',
    'Tracker': 'localization.tracker', 'TrackResult': 'localization.tracker',
    # data
    'BagData': 'io.bag_records', 'BagError': 'io.bag_records', 'ScanRecord': 'io.bag_records',
    'iter_scans': 'io.bag_reader', 'read_bag': 'io.bag_reader', 'write_bag': 'io.bag_writer',
    'convert_carmen': 'io.carmen', 'read_carmen_log': 'io.carmen',
    'simulate': 'io.simulate', 'simulate_bag': 'io.simulate',
    # evaluation
    'ResultRow': 'evaluation.replay', 'replay_scans': 'evaluation.replay',
    'summarize': 'evaluation.replay', 'write_results_csv': 'evaluation.replay',
    'TrackRow': 'evaluation.tracking', 'summarize_track': 'evaluation.tracking',
    'track_scans': 'evaluation.tracking',
}

__all__ = ['__version__', *sorted(_EXPORTS)]


def __getattr__(name: str):
    """Import a public name on first use (PEP 562: called only for names not found here)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'{__name__}.{module}'), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
