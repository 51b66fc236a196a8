"""
ssm_localization: single-scan global localization with spectral scan matching (Park & Park).

The public Python API is re-exported here; import it from ``ssm_localization`` (the module paths
below it may change). Layers, each importing only the ones before it:

- ``config``: settings dataclasses and YAML params files;
- ``matching``: spectral scan matching (paper section II), ``match_scans``;
- ``mapping``: map files, GVD topology, ray casting and the topological index (section III);
- ``localization``: global localization on an index (section IV), refinement, verification,
  and tracking with odometry (``Tracker``);
- ``io``: rosbag2 bags, CARMEN logs, simulated scans;
- ``evaluation``: offline replay against ground truth, figures;
- ``cli``, ``bench``, ``ros``: the command line, benchmarks and ROS 2 nodes.
"""
__version__ = '0.1.0'

from . import threads  # noqa: F401,I100 - first: sets the BLAS threads before numpy loads
from .config import (IndexConfig, load_configs, load_index_config, load_tracker_config,
                     LocalizerConfig, MapBuildConfig, MatcherConfig, SimulationConfig,
                     TopologyConfig, TrackerConfig)
from .evaluation.replay import replay_scans, ResultRow, summarize, write_results_csv
from .evaluation.tracking import summarize_track, track_scans, TrackRow
from .io.bag_reader import iter_scans, read_bag
from .io.bag_records import BagData, BagError, ScanRecord
from .io.bag_writer import write_bag
from .io.carmen import convert_carmen, read_carmen_log
from .io.simulate import simulate, simulate_bag
from .localization.localizer import GlobalLocalizer, Localization
from .localization.tracker import Tracker, TrackResult
from .mapping.index import build_index, load_index, MapIndex, save_index
from .mapping.map_io import load_map_yaml, occupancy_map_from_msg, OccupancyMap, save_map_yaml
from .mapping.topology import NodeKind
from .matching.features import prepare_scan, ScanFeatures
from .matching.matcher import match_features, match_scans, MatchResult

__all__ = [
    '__version__',
    # settings
    'IndexConfig', 'LocalizerConfig', 'MapBuildConfig', 'MatcherConfig', 'SimulationConfig',
    'TopologyConfig', 'TrackerConfig', 'load_configs', 'load_index_config',
    'load_tracker_config',
    # scan matching
    'MatchResult', 'ScanFeatures', 'match_features', 'match_scans', 'prepare_scan',
    # maps and the index
    'MapIndex', 'NodeKind', 'OccupancyMap', 'build_index', 'load_index', 'load_map_yaml',
    'occupancy_map_from_msg', 'save_index', 'save_map_yaml',
    # localization
    'GlobalLocalizer', 'Localization', 'TrackResult', 'Tracker',
    # data
    'BagData', 'BagError', 'ScanRecord', 'convert_carmen', 'iter_scans', 'read_bag',
    'read_carmen_log', 'simulate', 'simulate_bag', 'write_bag',
    # evaluation
    'ResultRow', 'TrackRow', 'replay_scans', 'summarize', 'summarize_track', 'track_scans',
    'write_results_csv',
]
