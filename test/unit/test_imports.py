"""
What importing the package loads and changes.

The localization core runs with numpy and scipy alone (numba, when installed, compiles one
loop), ``import ssm_localization`` loads nothing heavy and leaves the environment alone, the
console scripts set one BLAS thread before numpy loads, and every public name still resolves.
Each check runs in a fresh interpreter.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys

from helpers import REPO
import pytest
import ssm_localization
from ssm_localization.threads import THREAD_VARIABLES

#: what the localization core must not need
NOT_NEEDED = ('rclpy', 'tqdm', 'yaml', 'rosbags', 'matplotlib', 'PIL', 'mcap')


def _block(names: tuple[str, ...]) -> str:
    """Return code that makes ``names`` (top-level modules) unimportable."""
    return f"""
import sys
class Blocker:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {names!r}:
            raise ImportError('blocked for the test: ' + name)
sys.meta_path.insert(0, Blocker())
"""


LOCALIZE = """
import math
import numpy as np
import ssm_localization.localization
from ssm_localization.localization.localizer import GlobalLocalizer
from ssm_localization.localization.tracker import Tracker
from ssm_localization.mapping.index import build_index, load_index, save_index
from ssm_localization.mapping.occupancy import OccupancyMap
from ssm_localization.mapping.raycast import beam_angles, cast_rays

data = np.zeros((140, 200), np.int8)                       # 10 m x 7 m, two rooms
data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
data[:60, 80:82] = data[80:, 80:82] = 100                   # a wall with a door
data[20:30, 30:36] = data[100:112, 140:150] = data[40:44, 150:170] = 100
occ = OccupancyMap(data, 0.05, (0.0, 0.0, 0.0))
index = build_index(occ)
save_index(index, sys.argv[1])
index = load_index(sys.argv[1], expected_map=occ)
truth = (2.7, 4.1, 0.6)
angles = beam_angles(360)
ranges = cast_rays(occ.occupied_mask(), occ.resolution, occ.origin, [truth], angles, 20.0)[0]
loc = GlobalLocalizer(index).localize_scan(ranges, float(angles[0]), 2 * math.pi / 360)
res = Tracker(GlobalLocalizer(index)).track(
    type('Scan', (), dict(ranges=ranges, angle_min=float(angles[0]),
                          angle_increment=2 * math.pi / 360, range_min=0.0,
                          range_max=math.inf))())
print(json.dumps({'status': loc.status, 'pose': loc.pose, 'track': res.status,
                  'loaded': sorted({m.split('.')[0] for m in sys.modules})}))
"""


def _python(code: str, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-c', code, *args], capture_output=True, text=True,
                          timeout=300, env=env)


@pytest.mark.parametrize('numba', [True, False], ids=['with_numba', 'numpy_alone'])
def test_the_localization_core_runs_with_numpy_and_scipy_alone(tmp_path, numba):
    """
    Index, save, load, localize and track with rclpy, tqdm, PyYAML, ... unimportable.

    numba (a requirement) compiles the search's loop; without it the search runs in numpy.
    """
    blocked = NOT_NEEDED if numba else NOT_NEEDED + ('numba',)
    res = _python(_block(blocked) + 'import json\n' + LOCALIZE, str(tmp_path / 'index.npz'))
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out['status'] == 'ok' and out['track'] == 'ok', out
    assert math_close(out['pose'], (2.7, 4.1, 0.6))
    assert not set(blocked) & set(out['loaded'])
    assert ('numba' in out['loaded']) == numba
    assert ('numba is not installed' in res.stderr) == (not numba)


def math_close(pose, truth, tol: float = 0.05) -> bool:
    return all(abs(a - b) < tol for a, b in zip(pose, truth))


def test_the_block_itself_works():
    """The blocked imports really fail (else the test above could not fail)."""
    for name in NOT_NEEDED + ('numba',):
        res = _python(_block(NOT_NEEDED + ('numba',)) + f'import {name}\n')
        assert res.returncode != 0 and 'blocked for the test' in res.stderr, name


def test_importing_the_package_loads_nothing_heavy_and_keeps_the_environment():
    code = ('import json, os, sys\nbefore = dict(os.environ)\nimport ssm_localization\n'
            'print(json.dumps({"same": dict(os.environ) == before, '
            '"loaded": sorted({m.split(".")[0] for m in sys.modules})}))')
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    res = _python(code, env=env)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out['same']
    assert not {'numpy', 'scipy', *NOT_NEEDED} & set(out['loaded'])


def test_every_public_name_resolves():
    for name in ssm_localization.__all__:
        assert getattr(ssm_localization, name) is not None, name
    assert set(ssm_localization.__all__) <= set(dir(ssm_localization))
    from ssm_localization.localization.localizer import GlobalLocalizer
    from ssm_localization.mapping.map_io import OccupancyMap
    assert ssm_localization.GlobalLocalizer is GlobalLocalizer
    assert ssm_localization.OccupancyMap is OccupancyMap      # re-exported by map_io
    with pytest.raises(AttributeError, match='no_such_name'):
        ssm_localization.no_such_name   # noqa: B018


def test_config_loads_params_names_on_first_use():
    from ssm_localization import config
    from ssm_localization.config.params import load_configs
    assert config.load_configs is load_configs
    with pytest.raises(AttributeError):
        config.no_such_name   # noqa: B018


@pytest.mark.parametrize('preset', [None, '3'])
def test_console_scripts_set_one_blas_thread_before_numpy_loads(preset):
    """The console scripts' wrapper sets the thread variables first; a user's value is kept."""
    code = ('import json, os, sys\nfrom ssm_localization import entry_points\n'
            'early = "numpy" in sys.modules\nsys.argv = ["ssm_localization", "--help"]\n'
            'try:\n    entry_points.ssm_localization()\nexcept SystemExit:\n    pass\n'
            'print(json.dumps({"early": early, "numpy": "numpy" in sys.modules, '
            '"env": [os.environ.get(v) for v in ' + repr(THREAD_VARIABLES) + ']}))')
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    if preset:
        env['OPENBLAS_NUM_THREADS'] = preset
    res = _python(code, env=env)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert not out['early'] and out['numpy']
    assert out['env'] == [preset or '1', '1', '1']


def test_the_installed_console_scripts_go_through_the_wrapper():
    from importlib.metadata import entry_points
    scripts = {ep.name: ep.value for ep in entry_points(group='console_scripts')
               if ep.value.startswith('ssm_localization')}
    assert scripts == {
        'ssm_localization': 'ssm_localization.entry_points:ssm_localization',
        'global_localizer': 'ssm_localization.entry_points:global_localizer',
        'map_indexer': 'ssm_localization.entry_points:map_indexer'}


def test_python_dash_m_runs_the_command_line_and_the_versions_agree():
    """``python -m ssm_localization`` is the console script; package.xml, setup.py agree."""
    res = subprocess.run([sys.executable, '-m', 'ssm_localization', '--version'],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f'ssm_localization {ssm_localization.__version__}'
    xml = re.findall(r'<version>([^<]+)</version>', (REPO / 'package.xml').read_text())
    setup = re.findall(r"version='([^']+)'", (REPO / 'setup.py').read_text())
    assert xml == setup == [ssm_localization.__version__]
    res = subprocess.run([sys.executable, '-m', 'ssm_localization'], capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 2 and 'required: COMMAND' in res.stderr and not res.stdout


def test_every_module_imports_on_its_own():
    """Each module, imported first in a process (as a script or a user would), loads."""
    code = ('import importlib, json, pathlib, sys\n'
            'root = pathlib.Path(sys.argv[1])\n'
            'names = sorted(".".join(p.relative_to(root.parent).with_suffix("").parts)'
            '.removesuffix(".__init__") for p in root.rglob("*.py"))\n'
            'bad = {}\n'
            'for name in names:\n'
            '    for m in [m for m in sys.modules if m.split(".")[0] == "ssm_localization"]:\n'
            '        del sys.modules[m]\n'
            '    try:\n'
            '        importlib.import_module(name)\n'
            '    except ImportError as exc:\n'
            '        bad[name] = str(exc)\n'
            'print(json.dumps({"n": len(names), "bad": bad}))\n')
    res = subprocess.run([sys.executable, '-c', code, str(REPO / 'ssm_localization')],
                         capture_output=True, text=True, timeout=300, cwd=REPO)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.splitlines()[-1])
    assert out['n'] > 100 and out['bad'] == {}
