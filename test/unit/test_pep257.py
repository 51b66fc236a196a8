"""ament_pep257 over the package (docstring conventions of ROS 2's ament_python template)."""
from ament_pep257.main import main
from helpers import REPO
import pytest

EXCLUDE = ['build', 'install', 'log', 'out', 'bench_data', '.venv']


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257(monkeypatch):
    monkeypatch.chdir(REPO)
    rc = main(argv=['.', 'test', '--exclude', *EXCLUDE])
    assert rc == 0, 'Found code style errors / warnings'
