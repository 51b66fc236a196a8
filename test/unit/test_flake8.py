"""ament_flake8 over the package (ROS 2 style: ament's flake8 configuration and plugins)."""
import subprocess
import sys

from helpers import REPO
import pytest

# generated or third-party trees that may sit in a developer's checkout
EXCLUDE = ['build', 'install', 'log', 'out', 'bench_data']
# In a fresh interpreter: flake8 forks worker processes, and a fork of a test process in which
# rclpy / DDS threads already run can crash in the child.
RUN = ('import sys; from ament_flake8.main import main_with_errors; '
       'rc, errors = main_with_errors(argv=sys.argv[1:]); sys.exit(rc)')


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    res = subprocess.run([sys.executable, '-c', RUN, '--exclude', *EXCLUDE], cwd=REPO,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, f'code style errors / warnings:\n{res.stdout}\n{res.stderr}'
