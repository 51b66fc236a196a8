#!/usr/bin/env python3
"""
Record the ROS 2 Jazzy names our launch and RViz files use, for the offline static tests.

``launch``, ``launch_ros``, nav2 and RViz are not installable from PyPI, so the tests check the
launch files (``test/test_launch_files.py``) against a snapshot of the names these projects
define at their ``jazzy`` branch: the exported classes of the launch modules we import, the
executables and declared parameters of the nav2 nodes we start, and RViz's display / tool /
panel classes. Run against git clones (work trees or bare git directories) of
ros2/launch, ros2/launch_ros, ros-navigation/navigation2 and ros2/rviz::

    scripts/snapshot_ros_names.py --launch DIR --launch-ros DIR --navigation2 DIR --rviz DIR

It writes ``test/data/ros_jazzy_names.yaml`` with each source's commit and date.
"""
from __future__ import annotations

import argparse
import ast
import datetime
from pathlib import Path
import re
import subprocess
import sys

import yaml

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / 'test' / 'data' / 'ros_jazzy_names.yaml'
BRANCH = 'jazzy'
MODULES = {   # python module -> (source repository, path of its __init__.py)
    'launch': ('launch', 'launch/launch/__init__.py'),
    'launch.actions': ('launch', 'launch/launch/actions/__init__.py'),
    'launch.conditions': ('launch', 'launch/launch/conditions/__init__.py'),
    'launch.substitutions': ('launch', 'launch/launch/substitutions/__init__.py'),
    'launch_ros.actions': ('launch_ros', 'launch_ros/launch_ros/actions/__init__.py'),
    'launch_ros.substitutions': ('launch_ros', 'launch_ros/launch_ros/substitutions/__init__.py'),
    'launch_ros.parameter_descriptions': ('launch_ros',
                                          'launch_ros/launch_ros/parameter_descriptions.py'),
}
NAV2_NODES = {   # package -> {executable: C++ sources declaring its parameters}
    'nav2_map_server': {'map_server': ['nav2_map_server/src/map_server/map_server.cpp']},
    'nav2_amcl': {'amcl': ['nav2_amcl/src/amcl_node.cpp']},
    'nav2_lifecycle_manager': {
        'lifecycle_manager': ['nav2_lifecycle_manager/src/lifecycle_manager.cpp']},
}
NAV2_COMMON = ['nav2_util/src/lifecycle_node.cpp']   # parameters of every nav2 lifecycle node
PARAM_RE = re.compile(r'(?:add_parameter|declare_parameter(?:_if_not_declared)?)\(\s*'
                      r'(?:[\w:>\-.]+\s*,\s*)?"([A-Za-z_][\w.]*)"')


class Source:
    """Read files of one git repository at the ``jazzy`` branch."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def _git(self, *args: str) -> str:
        return subprocess.run(['git', '-C', str(self.path), *args], capture_output=True,
                              text=True, check=True).stdout

    def read(self, relpath: str) -> str:
        """Return the text of ``relpath`` at the branch."""
        return self._git('show', f'{BRANCH}:{relpath}')

    def files(self, prefix: str) -> list[str]:
        """Paths under ``prefix`` at the branch."""
        return self._git('ls-tree', '-r', '--name-only', BRANCH, prefix).split()

    def origin(self) -> dict[str, str]:
        """Branch, commit and commit date."""
        commit, date = self._git('show', '-s', '--format=%H %cs', BRANCH).split()
        return {'branch': BRANCH, 'commit': commit, 'date': date}


def exported_names(text: str) -> list[str]:
    """``__all__`` of a module's source, else its top-level public names."""
    tree = ast.parse(text)
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == '__all__' for t in node.targets):
            return sorted(ast.literal_eval(node.value))
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            names.add(node.name)
        elif isinstance(node, ast.ImportFrom):
            names.update(a.asname or a.name for a in node.names)
    return sorted(n for n in names if not n.startswith('_'))


def cmake_executables(text: str) -> list[str]:
    """Targets of ``add_executable`` in a CMakeLists.txt, ``${var}`` resolved via ``set``."""
    variables = dict(re.findall(r'set\(\s*(\w+)\s+([\w-]+)\s*\)', text))
    out = []
    for target in re.findall(r'add_executable\(\s*([\w${}-]+)', text):
        match = re.fullmatch(r'\$\{(\w+)\}', target)
        out.append(variables.get(match.group(1), target) if match else target)
    return sorted(out)


def declared_parameters(texts: list[str]) -> list[str]:
    """Parameter names declared in C++ sources."""
    return sorted({name for text in texts for name in PARAM_RE.findall(text)})


def snapshot(launch: Source, launch_ros: Source, nav2: Source, rviz: Source) -> dict:
    """Return the snapshot document."""
    sources = {'launch': launch, 'launch_ros': launch_ros}
    modules = {mod: exported_names(sources[repo].read(path))
               for mod, (repo, path) in MODULES.items()}
    common = [nav2.read(p) for p in NAV2_COMMON]
    executables, parameters = {}, {}
    for package, nodes in NAV2_NODES.items():
        executables[package] = cmake_executables(nav2.read(f'{package}/CMakeLists.txt'))
        for exe, files in nodes.items():
            parameters[f'{package}/{exe}'] = declared_parameters(
                [nav2.read(p) for p in files] + common)
    plugins = rviz.read('rviz_default_plugins/plugins_description.xml')
    classes = set(re.findall(r'name="(rviz_default_plugins/\w+)"', plugins))
    for path in rviz.files('rviz_common/src'):
        if path.endswith('.cpp'):
            for name in re.findall(r'addBuiltInClass\(\s*"rviz_common",\s*"([\w ]+)"',
                                   rviz.read(path)):
                classes.add(f'rviz_common/{name}')
    return {
        'snapshot_taken': datetime.date.today().isoformat(),
        'sources': {'ros2/launch': launch.origin(), 'ros2/launch_ros': launch_ros.origin(),
                    'ros-navigation/navigation2': nav2.origin(), 'ros2/rviz': rviz.origin()},
        'python_modules': modules,
        'nav2_executables': executables,
        'nav2_parameters': parameters,
        'rviz_classes': sorted(classes),
    }


def main(argv: list[str] | None = None) -> int:
    """Command line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    for name in ('launch', 'launch-ros', 'navigation2', 'rviz'):
        parser.add_argument(f'--{name}', type=Path, required=True, help='git clone')
    parser.add_argument('-o', '--output', type=Path, default=OUT)
    args = parser.parse_args(argv)
    doc = snapshot(Source(args.launch), Source(args.launch_ros), Source(args.navigation2),
                   Source(args.rviz))
    header = ('# Names defined by ROS 2 Jazzy projects that launch/*.launch.py and\n'
              '# rviz/ssm_localization.rviz use, for the offline static tests\n'
              '# (test/test_launch_files.py). Written by scripts/snapshot_ros_names.py.\n')
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(header + yaml.safe_dump(doc, sort_keys=False, width=100))
    print(f'wrote {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
