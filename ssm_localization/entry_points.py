"""
The console scripts: one BLAS thread (``threads.py``), then the command.

``setup.py`` points ``ssm_localization``, ``global_localizer`` and ``map_indexer`` here. Each
function imports its command only after :func:`~.threads.limit_blas_threads`: the import loads
numpy, and BLAS reads its thread variables once, when numpy loads it.
"""
from __future__ import annotations

from .threads import limit_blas_threads


def ssm_localization() -> int:
    """Run the ``ssm_localization`` command line."""
    limit_blas_threads()
    from .cli.main import main
    return main()


def global_localizer() -> int:
    """Run the ``global_localizer`` node (``ros2 run ssm_localization global_localizer``)."""
    limit_blas_threads()
    from .ros.global_localizer import main
    return main()


def map_indexer() -> int:
    """Run the ``map_indexer`` node (``ros2 run ssm_localization map_indexer``)."""
    limit_blas_threads()
    from .ros.map_indexer import main
    return main()
