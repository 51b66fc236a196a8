"""
Configuration dataclasses and YAML params files.

Modules here import nothing from the rest of the package but ``files/`` (bounded YAML reading),
so every layer can take its settings from here without an import cycle.
"""
from .localization import LocalizerConfig
from .mapping import IndexConfig, MapBuildConfig, TopologyConfig
from .matcher import HAND_WEIGHTS, LEARNED_WEIGHTS, MatcherConfig, PREPARE_FIELDS
from .params import (config_from_json, config_to_json, Configs, flatten, from_dict,
                     load_all_configs, load_configs, load_index_config, load_tracker_config,
                     load_yaml_mapping, unflatten)
from .simulation import SimulationConfig
from .tracking import TrackerConfig

__all__ = ['HAND_WEIGHTS', 'LEARNED_WEIGHTS', 'PREPARE_FIELDS', 'IndexConfig', 'LocalizerConfig',
           'MapBuildConfig', 'MatcherConfig', 'SimulationConfig', 'TopologyConfig',
           'TrackerConfig', 'Configs',
           'config_from_json', 'config_to_json', 'flatten', 'from_dict', 'load_all_configs',
           'load_configs',
           'load_index_config', 'load_tracker_config', 'load_yaml_mapping', 'unflatten']
