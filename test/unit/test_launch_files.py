"""
Static checks of launch/*.launch.py and rviz/ssm_localization.rviz.

``launch``, ``launch_ros``, nav2 and RViz cannot be installed here (no PyPI wheels), so the
launch files are never executed by these tests. Instead each file is parsed with ``ast`` and
every name it relies on is checked: imports against the names ROS 2 Jazzy's launch modules
export, packages / executables / parameters of the nodes it starts against our setup.py and
params file or against nav2 Jazzy's sources, files it loads against the package, lifecycle
managers against the nodes they manage. The Jazzy names come from the committed snapshot
``test/data/ros_jazzy_names.yaml`` (written by ``scripts/snapshot_ros_names.py``; sources and
commits inside). test_colcon.py checks that colcon installs these files.
"""
from __future__ import annotations

import ast
import importlib
from pathlib import Path
import sys

from helpers import REPO
from launch_ast import const_value, LaunchFile, value_of
import pytest
import yaml

PKG = 'ssm_localization'
LAUNCH = REPO / 'launch'
RVIZ = REPO / 'rviz' / 'ssm_localization.rviz'
NAMES = yaml.safe_load((REPO / 'test' / 'data' / 'ros_jazzy_names.yaml').read_text())
AUTOMATIC_PARAMETERS = {'use_sim_time'}      # declared by every rclpy / rclcpp node
GLOBAL_LOCALIZER_ARGS = {'params_file', 'namespace', 'use_sim_time', 'autostart', 'index_file',
                         'localize_on_start', 'use_respawn', 'log_level'}
# the arguments of nav2_bringup's launch/localization_launch.py (navigation2, jazzy branch,
# f4108e5b1c2bce804a1aa0c7be6673a8eb4a1501): nav2_localization.launch.py takes each of them
NAV2_LOCALIZATION_ARGS = {'namespace', 'map', 'use_sim_time', 'autostart', 'params_file',
                          'use_composition', 'container_name', 'use_respawn', 'log_level'}


def _launch_files() -> list[Path]:
    return sorted(LAUNCH.glob('*.launch.py'))


def _console_scripts() -> set[str]:
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == 'entry_points':
            scripts = const_value(node.value)['console_scripts']
            return {s.split('=')[0].strip() for s in scripts}
    raise AssertionError('setup.py has no console_scripts')


def _data_file_globs() -> list[str]:
    tree = ast.parse((REPO / 'setup.py').read_text())
    globs = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id == 'glob':
            globs.append(const_value(node.args[0]))
    return globs


def _flat(d: dict, prefix: str = '') -> set[str]:
    out = set()
    for k, v in d.items():
        out |= _flat(v, f'{prefix}{k}.') if isinstance(v, dict) else {prefix + k}
    return out


def _our_parameters(node_name: str) -> set[str]:
    """
    Every parameter a node of ours declares.

    The generated params file lists them all (test_ros_params.py checks that against the running
    nodes).
    """
    doc = yaml.safe_load((REPO / 'config' / 'ssm_localization.yaml').read_text())
    return _flat(doc[node_name]['ros__parameters']) | AUTOMATIC_PARAMETERS


@pytest.fixture(params=[p.name for p in _launch_files()])
def launch_file(request) -> LaunchFile:
    return LaunchFile(LAUNCH / request.param)


def test_both_launch_files_exist():
    assert {p.name for p in _launch_files()} >= {'global_localizer.launch.py',
                                                 'nav2_localization.launch.py'}


def test_launch_file_defines_generate_launch_description(launch_file):
    assert 'generate_launch_description' in launch_file.functions
    assert not launch_file.functions['generate_launch_description'].args.args


def test_launch_file_imports_exist(launch_file):
    """Every imported name exists in ROS 2 Jazzy (snapshot) or here (imported for real)."""
    modules = NAMES['python_modules']
    for module, name, line in launch_file.imports():
        where = f'{launch_file.path.name}:{line}: from {module} import {name}'
        top = module.split('.')[0]
        if top in ('launch', 'launch_ros'):
            assert module in modules, f'{where}: module not in the Jazzy snapshot'
            assert name in modules[module], f'{where}: {module} has no {name} in Jazzy'
        else:
            assert top in ('ament_index_python', PKG) or top in sys.stdlib_module_names, where
            assert hasattr(importlib.import_module(module), name), where
    for name in launch_file.plain_imports():
        assert name.split('.')[0] in sys.stdlib_module_names, name


def test_launch_arguments_are_declared_and_used(launch_file):
    declared = launch_file.declared_arguments()
    used = launch_file.used_arguments()
    assert used <= set(declared), f'used but not declared: {sorted(used - set(declared))}'
    assert set(declared) <= used, f'declared but never read: {sorted(set(declared) - used)}'
    assert GLOBAL_LOCALIZER_ARGS - {'params_file'} <= set(declared)
    assert all(declared[a] for a in declared), 'every argument has a default'
    if launch_file.path.name == 'global_localizer.launch.py':
        assert set(declared) == GLOBAL_LOCALIZER_ARGS
    else:
        assert NAV2_LOCALIZATION_ARGS <= set(declared), 'a drop-in for localization_launch.py'


def test_launched_packages_executables_and_parameters_exist(launch_file):
    ours = _console_scripts()
    nav2_exes = NAMES['nav2_executables']
    nav2_params = NAMES['nav2_parameters']
    nodes = launch_file.nodes()
    assert nodes
    for node in nodes:
        where = f'{launch_file.path.name}:{node.line}: {node.package}/{node.executable}'
        if node.package == PKG:
            assert node.executable in ours, f'{where}: no such console script in setup.py'
            assert node.action == 'LifecycleNode', f'{where}: our nodes are lifecycle nodes'
            allowed = _our_parameters(node.executable)
        else:
            assert node.package in nav2_exes, f'{where}: not a known nav2 package'
            assert node.executable in nav2_exes[node.package], f'{where}: no such executable'
            allowed = set(nav2_params[f'{node.package}/{node.executable}']) | \
                AUTOMATIC_PARAMETERS
        unknown = sorted(set(node.parameters) - allowed)
        assert not unknown, f'{where}: unknown parameters {unknown}'
        if node.executable in ('global_localizer', 'amcl'):   # tf listeners
            assert ('/tf', 'tf') in node.remappings and ('/tf_static', 'tf_static') in \
                node.remappings, f'{where}: tf topics must follow the namespace'


def test_lifecycle_managers_manage_launched_nodes_without_bonds_for_ours(launch_file):
    nodes = launch_file.nodes()
    names = {n.name: n for n in nodes}
    managers = [n for n in nodes if n.executable == 'lifecycle_manager']
    managed = set()
    for manager in managers:
        node_names = manager.parameters.get('node_names')
        assert node_names, f'{manager.name}: node_names missing'
        for name in node_names:
            assert name in names, f'{manager.name} manages {name}, which is not launched'
            managed.add(name)
            if names[name].package == PKG:
                # rclpy lifecycle nodes send no bond heartbeats: the manager must not wait
                assert manager.parameters.get('bond_timeout') == 0.0, manager.name
        assert isinstance(manager.parameters.get('autostart'), (bool, type(None)))
    for node in nodes:
        if node.package == PKG:
            if node.name in managed:
                assert node.parameters.get('autostart') is False, \
                    f'{node.name} is managed: it must not start itself'
        elif node.package != 'nav2_lifecycle_manager':
            assert node.name in managed, f'nav2 node {node.name} is managed by nobody'


def test_share_files_named_by_launch_files_exist_and_are_installed(launch_file):
    globs = _data_file_globs()
    files = launch_file.share_files()
    assert files
    for rel in files:
        assert (REPO / rel).is_file(), f'{launch_file.path.name} loads missing {rel}'
        assert any(Path(rel).match(g) for g in globs), f'setup.py does not install {rel}'


def test_nav2_params_file_names_existing_nav2_parameters():
    doc = yaml.safe_load((REPO / 'config' / 'nav2_localization.yaml').read_text())
    known = {'map_server': 'nav2_map_server/map_server', 'amcl': 'nav2_amcl/amcl'}
    assert set(doc) == set(known)
    for node, key in known.items():
        names = _flat(doc[node]['ros__parameters'])
        unknown = sorted(names - set(NAMES['nav2_parameters'][key]) - AUTOMATIC_PARAMETERS)
        assert not unknown, f'{node}: not nav2 Jazzy parameters: {unknown}'


# ---------------------------------------------------------------------------- RViz

EXPECTED_QOS = {   # topic -> (durability, reliability) the publishers offer
    'map': ('Transient Local', 'Reliable'),              # nav2 map_server
    'amcl_pose': ('Transient Local', 'Reliable'),        # nav2 amcl
    'scan': ('Volatile', 'Best Effort'),                 # sensor data
}


def _displays(doc: dict) -> list[dict]:
    out = []
    stack = list(doc['Visualization Manager']['Displays'])
    while stack:
        display = stack.pop()
        out.append(display)
        stack.extend(display.get('Displays', []))
    return out


def test_rviz_config_uses_known_classes_and_the_map_frame():
    doc = yaml.safe_load(RVIZ.read_text())
    classes = set(NAMES['rviz_classes'])
    used = [d['Class'] for d in _displays(doc)]
    used += [t['Class'] for t in doc['Visualization Manager']['Tools']]
    used += [p['Class'] for p in doc['Panels']]
    used.append(doc['Visualization Manager']['Views']['Current']['Class'])
    unknown = sorted(set(used) - classes)
    assert not unknown, f'not RViz Jazzy classes: {unknown}'
    assert doc['Visualization Manager']['Global Options']['Fixed Frame'] == 'map'


def test_rviz_config_shows_our_topics_with_matching_qos():
    doc = yaml.safe_load(RVIZ.read_text())
    topics = {d['Topic']['Value']: d for d in _displays(doc) if 'Topic' in d}
    for topic in ('map', 'global_pose', 'candidates', 'topological_map'):
        assert topic in topics, f'{topic} is not shown'
    # relative names: rviz2 --ros-args -r __ns:=/robot1 shows robot1's topics
    assert not [t for t in topics if t.startswith('/')], 'absolute topic names'
    latched = ('global_pose', 'candidates', 'topological_map')
    expected = {**EXPECTED_QOS, **{t: ('Transient Local', 'Reliable') for t in latched}}
    for topic, (durability, reliability) in expected.items():
        if topic in topics:
            qos = topics[topic]['Topic']
            assert qos['Durability Policy'] == durability, topic
            assert qos['Reliability Policy'] == reliability, topic


def test_nodes_follow_nav2_bringup_conventions(launch_file):
    """
    Namespace pushed once, use_sim_time left to SetParameter, respawn and log level.

    A node given ``namespace=namespace`` ends up in ``/robot1/robot1`` under nav2_bringup's
    ``PushROSNamespace``; a ``use_sim_time`` in a node's parameters overrides a parent's
    ``SetParameter``.
    """
    for node in launch_file.nodes():
        assert 'use_sim_time' not in node.parameters, f'{node.name}: use SetParameter'
    for _, call in [*launch_file._calls('Node'), *launch_file._calls('LifecycleNode')]:
        kw = {k.arg: k.value for k in call.keywords}
        name = value_of(kw['name'], launch_file.constants)
        namespace = kw.get('namespace')
        assert not (isinstance(namespace, ast.Name) and namespace.id == 'namespace'), \
            f'{name}: namespace through node_namespace()'
        assert 'arguments' in kw, f'{name}: --log-level'
        if value_of(kw['executable'], launch_file.constants) != 'lifecycle_manager':
            assert 'respawn' in kw, f'{name}: use_respawn'
