"""``python -m ssm_localization``: the ``ssm_localization`` command line, as the console script."""
import sys

from .entry_points import ssm_localization

if __name__ == '__main__':
    sys.exit(ssm_localization())
