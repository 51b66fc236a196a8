"""
The package builds with colcon like any ament_python package.

package.xml declares what the ROS adapters import.
"""
from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

from helpers import REPO, venv_bin
from launch_ast import LaunchFile
import pytest

PKG = 'ssm_localization'


def _colcon() -> str:
    exe = venv_bin('colcon')
    if exe.exists():
        return str(exe)
    found = shutil.which('colcon')
    if not found:
        pytest.skip('colcon is not installed (pip install colcon-common-extensions)')
    return found


def test_colcon_build_installs_nodes_and_ament_index(tmp_path):
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE='1')
    cmd = [_colcon(), '--log-base', str(tmp_path / 'log'), 'build',
           '--base-paths', str(REPO), '--build-base', str(tmp_path / 'build'),
           '--install-base', str(tmp_path / 'install'), '--packages-select', PKG]
    res = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    logs = sorted((tmp_path / 'log').glob(f'**/{PKG}/stderr.log'))
    detail = res.stdout[-3000:] + res.stderr[-3000:] + ''.join(p.read_text()[-3000:] for p in logs)
    assert res.returncode == 0, detail
    prefix = tmp_path / 'install' / PKG
    for script in ('global_localizer', 'map_indexer', 'ssm_localization'):
        path = prefix / 'lib' / PKG / script
        assert path.is_file() and os.access(path, os.X_OK), f'missing {path}'
    assert (prefix / 'share/ament_index/resource_index/packages' / PKG).is_file()
    assert (prefix / 'share' / PKG / 'package.xml').is_file()
    assert (prefix / 'share' / PKG / 'config' / 'ssm_localization.yaml').is_file()
    # launch files, the files they load, and the RViz config (see test_launch_files.py)
    share = prefix / 'share' / PKG
    launch_files = sorted((REPO / 'launch').glob('*.launch.py'))
    assert launch_files
    for path in launch_files:
        assert (share / 'launch' / path.name).is_file(), f'{path.name} is not installed'
        for rel in LaunchFile(path).share_files():
            assert (share / rel).is_file(), f'{rel} (loaded by {path.name}) is not installed'
    assert (share / 'rviz' / 'ssm_localization.rviz').is_file()
    examples = sorted(p.name for p in (REPO / 'config' / 'examples').glob('*.yaml'))
    assert examples and all((share / 'config' / 'examples' / e).is_file() for e in examples)
    # the installed entry point resolves and runs (a bad parameter makes it exit at once)
    pytest.importorskip('rclpy', reason='rclpy is needed to run the installed node')
    site = next((prefix / 'lib').glob('python3*/site-packages'))
    # package data: the confidence model the localizer loads at import
    assert (site / PKG / 'config' / 'confidence_model.json').is_file()
    # the launch files' helper module comes with the installed package
    helper = subprocess.run([sys.executable, '-c', 'import ssm_localization.ros.launch_support '
                             'as m; print(m.__file__)'], env=dict(env, PYTHONPATH=str(site)),
                            capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert helper.returncode == 0 and str(site) in helper.stdout, helper.stderr
    run = subprocess.run([str(prefix / 'lib' / PKG / 'global_localizer'), '--ros-args', '-p',
                          'mode:=sideways'], env=dict(env, PYTHONPATH=str(site)),
                         capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert run.returncode == 2 and 'mode must be one of' in run.stderr, run.stderr
    assert 'Traceback' not in run.stderr


def _ros_imports() -> set[str]:
    """Top-level ROS packages imported by ssm_localization/ros/*.py."""
    import importlib.util
    names: set[str] = set()
    for path in (REPO / PKG / 'ros').glob('*.py'):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split('.')[0])
            elif isinstance(node, ast.Import):
                names.update(a.name.split('.')[0] for a in node.names)
    stdlib = set(sys.stdlib_module_names)
    third_party = {'numpy', 'scipy', 'yaml', 'PIL', 'rosbags', 'mcap', 'matplotlib', PKG}
    out = set()
    for name in names - stdlib - third_party:
        if importlib.util.find_spec(name) is not None:
            out.add(name)
    return out


def test_package_xml_declares_the_ros_packages_the_adapters_import():
    root = ET.parse(REPO / 'package.xml').getroot()
    declared = {e.text.strip() for e in root
                if e.tag in ('depend', 'exec_depend', 'build_depend') and e.text}
    missing = sorted(_ros_imports() - declared)
    assert not missing, f'package.xml lacks <exec_depend> for: {", ".join(missing)}'
    assert root.find('export/build_type').text.strip() == 'ament_python'
    assert (REPO / 'resource' / PKG).is_file()
