"""
Configuration dataclasses and YAML params files.

Modules here import nothing from the rest of the package but ``files/`` (bounded YAML reading),
so every layer can take its settings from here without an import cycle. The dataclasses and
their conversions (``convert.py``) need only the standard library; the names of ``params.py``
(YAML files -> configs) are imported on first use, so that PyYAML is loaded only by code that
reads a params file.
"""
from .convert import config_from_json, config_to_json, flatten, from_dict, unflatten
from .localization import LocalizerConfig
from .mapping import IndexConfig, MapBuildConfig, TopologyConfig
from .matcher import HAND_WEIGHTS, LEARNED_WEIGHTS, MatcherConfig, PREPARE_FIELDS
from .simulation import SimulationConfig
from .tracking import TrackerConfig

#: names of ``params.py``, imported from there on first use
PARAMS_NAMES = ('Configs', 'load_all_configs', 'load_configs', 'load_index_config',
                'load_tracker_config', 'load_yaml_mapping')

__all__ = ['HAND_WEIGHTS', 'LEARNED_WEIGHTS', 'PREPARE_FIELDS', 'IndexConfig', 'LocalizerConfig',
           'MapBuildConfig', 'MatcherConfig', 'SimulationConfig', 'TopologyConfig',
           'TrackerConfig', 'Configs',
           'config_from_json', 'config_to_json', 'flatten', 'from_dict', 'load_all_configs',
           'load_configs',
           'load_index_config', 'load_tracker_config', 'load_yaml_mapping', 'unflatten']


def __getattr__(name: str):
    """Return a name of ``params.py`` (PEP 562: called only for names not found here)."""
    if name in PARAMS_NAMES:
        from . import params
        return getattr(params, name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(PARAMS_NAMES))
