"""
Where the benchmarks and the demo find the shared data sets (CARMEN logs, nav2 maps).

``--data DIR``, else the environment variable ``SSM_LOCALIZATION_DATA``, else ``shared/data``
beside the current directory (the layout of a source checkout, run from its root). Nothing is
looked up relative to the installed package, which may live anywhere (``colcon build``).
"""
from __future__ import annotations

import os
from pathlib import Path

#: environment variable naming the data directory
DATA_ENV = 'SSM_LOCALIZATION_DATA'
#: help of the ``--data`` options
DATA_HELP = (f'directory of the shared data sets (carmen/, maps/); default: ${DATA_ENV}, else '
             'shared/data beside the current directory')


def default_data_dir() -> Path:
    """Return ``$SSM_LOCALIZATION_DATA``, else ``shared/data`` beside the current directory."""
    env = os.environ.get(DATA_ENV)
    return Path(env) if env else Path.cwd().parent / 'shared' / 'data'


def data_dir(arg: str | Path | None = None) -> Path:
    """
    Return the data directory: ``arg`` if given, else :func:`default_data_dir`.

    ``FileNotFoundError`` naming ``--data`` and the environment variable when it is not a
    directory.
    """
    path = Path(arg) if arg else default_data_dir()
    if not path.is_dir():
        raise FileNotFoundError(f'data directory not found: {path} (pass --data DIR or set '
                                f'{DATA_ENV})')
    return path
