"""
The package's import graph (built with ``ast``, nothing is imported).

Layers, no cycles, ROS only in ``ros/``, few function-level imports. Each check also runs on a
deliberately broken package.
"""
from __future__ import annotations

import ast
from dataclasses import dataclass, field
from pathlib import Path

from helpers import REPO
import pytest

PKG = 'ssm_localization'
NODE_MODULES = {f'{PKG}.ros.global_localizer', f'{PKG}.ros.map_indexer', f'{PKG}.ros.play'}
ROS_PACKAGES = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'std_msgs', 'std_srvs',
                'geometry_msgs', 'nav_msgs', 'sensor_msgs', 'visualization_msgs', 'tf2_ros',
                'launch', 'launch_ros', 'ament_index_python'}
#: optional heavy dependencies a function may import on first use
OPTIONAL = {'matplotlib', 'rosbags', 'mcap', 'tqdm'}
#: function-level imports of the package's own modules that are allowed: (importer, imported)
LAZY_OWN = {(f'{PKG}.cli.play_cmd', f'{PKG}.ros.play'),    # rclpy only for `ssm_localization play`
            (f'{PKG}.bench.soak', f'{PKG}.ros.soak'),     # ... and for `bench soak`
            (f'{PKG}.config', f'{PKG}.config.params'),    # PyYAML only for params files
            # the console scripts set one BLAS thread before the command loads numpy
            (f'{PKG}.entry_points', f'{PKG}.cli.main'),
            (f'{PKG}.entry_points', f'{PKG}.ros.global_localizer'),
            (f'{PKG}.entry_points', f'{PKG}.ros.map_indexer')}
MAX_FUNCTION_IMPORTS = 14   # each one listed above by name
#: data flows one way: a module imports only from lower layers (or its own subpackage)
LAYERS = [
    {'threads', 'files', 'compiled'},
    {'transforms', 'progress', 'config'},
    {'matching'},
    {'mapping'},
    {'localization', 'io'},
    {'evaluation'},
    {'cli', 'bench', 'ros', 'demo', 'entry_points', '__init__', '__main__'},
]
TOP = len(LAYERS) - 1


@dataclass
class Import:
    importer: str
    target: str          # absolute dotted name (an own module, or a third-party module)
    line: int
    in_function: bool


@dataclass
class Graph:
    modules: set[str]
    imports: list[Import] = field(default_factory=list)
    runs: list[Import] = field(default_factory=list)    # packages an import runs first

    def own(self, function_level: bool | None = None,
            packages: bool = False) -> dict[str, set[str]]:
        """
        Return ``{module: {own modules it imports}}``.

        Module- and function-level imports by default; ``packages``: with the packages whose
        ``__init__`` an import runs first (what an import cycle may pass through).
        """
        edges: dict[str, set[str]] = {m: set() for m in self.modules}
        for imp in self.imports + (self.runs if packages else []):
            if imp.target in self.modules and (function_level is None
                                               or imp.in_function == function_level):
                edges[imp.importer].add(imp.target)
        return edges


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix('').parts)
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def build_graph(root: Path) -> Graph:
    """
    Return every import statement of the package under ``root``.

    ``root`` is a directory named like the package.
    """
    files = {module_name(root, p): p for p in sorted(root.rglob('*.py'))}
    graph = Graph(set(files))
    for mod, path in files.items():
        is_pkg = path.name == '__init__.py'
        tree = ast.parse(path.read_text(), str(path))
        in_function: set[int] = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                in_function.update(id(n) for n in ast.walk(node) if n is not node)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = mod.split('.') if is_pkg else mod.split('.')[:-1]
                    base = base[:len(base) - node.level + 1]
                    src = '.'.join(base + ([node.module] if node.module else []))
                else:
                    src = node.module
                # ``from pkg import module``: that module; ``from module import name``: module
                targets = [f'{src}.{a.name}' if f'{src}.{a.name}' in files else src
                           for a in node.names]
            else:
                continue
            for target in dict.fromkeys(targets):
                graph.imports.append(Import(mod, target, node.lineno, id(node) in in_function))
            # importing ``a.b.c`` runs the package ``a.b`` first (its ``__init__``), unless the
            # importer is inside it (then it is running already)
            for package in dict.fromkeys(p for t in targets for p in _packages_of(t, files)
                                         if not (mod == p or mod.startswith(p + '.'))):
                graph.runs.append(Import(mod, package, node.lineno, id(node) in in_function))
    return graph


def _packages_of(target: str, files: dict[str, Path]) -> list[str]:
    """Return the own packages that importing ``target`` runs before it, outermost first."""
    parts = target.split('.')
    return [name for name in ('.'.join(parts[:i]) for i in range(2, len(parts)))
            if name in files and files[name].name == '__init__.py']


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as ``[a, b, ..., a]``, or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for n in sorted(edges.get(m, ())):
            if state.get(n) == 1:
                return stack[stack.index(n):] + [n]
            if n not in state and (found := visit(n)):
                return found
        stack.pop()
        state[m] = 2
        return None
    for m in sorted(edges):
        if m not in state and (found := visit(m)):
            return found
    return None


def layer_of(mod: str) -> tuple[int, str]:
    """(layer index, top-level part) of an own module."""
    part = mod.split('.')[1] if '.' in mod else '__init__'
    for i, names in enumerate(LAYERS):
        if part in names:
            return i, part
    raise AssertionError(f'{mod}: not in any layer of test_layout.LAYERS')


def violations(graph: Graph) -> list[str]:
    """Everything that breaks the layout rules, one line each (empty: the layout is sound)."""
    out = []
    cycle = find_cycle(graph.own(packages=True))
    if cycle:
        out.append('import cycle: ' + ' -> '.join(cycle))
    lazy = [i for i in graph.imports if i.in_function]
    if len(lazy) > MAX_FUNCTION_IMPORTS:
        out.append(f'{len(lazy)} function-level imports (at most {MAX_FUNCTION_IMPORTS})')
    for imp in graph.imports:
        where = f'{imp.importer}:{imp.line}'
        top = imp.target.split('.')[0]
        own = imp.target in graph.modules or top == PKG
        if imp.in_function and not ((imp.importer, imp.target) in LAZY_OWN
                                    or (not own and top in OPTIONAL)):
            out.append(f'{where}: function-level import of {imp.target} (allowed: '
                       f'{", ".join(sorted(OPTIONAL))} and {sorted(LAZY_OWN)})')
        if imp.importer in NODE_MODULES and imp.target in NODE_MODULES:
            out.append(f'{where}: node module imports node module {imp.target}')
        in_ros = imp.importer.startswith(f'{PKG}.ros.') or imp.importer == f'{PKG}.ros'
        if not in_ros and (imp.importer, imp.target) not in LAZY_OWN:
            if top in ROS_PACKAGES or top.endswith(('_msgs', '_srvs', '_interfaces')):
                out.append(f'{where}: the ROS-free core imports {imp.target}')
            elif imp.target.startswith(f'{PKG}.ros.') or imp.target == f'{PKG}.ros':
                out.append(f'{where}: the ROS-free core imports {imp.target}')
        if imp.target in graph.modules and imp.target != PKG:
            (li, part_i), (lt, part_t) = layer_of(imp.importer), layer_of(imp.target)
            if lt > li or (lt == li and part_i != part_t and li != TOP):
                out.append(f'{where}: {part_i} (layer {li}) imports {imp.target} '
                           f'({part_t}, layer {lt}): imports go to lower layers only')
        if imp.target == PKG and imp.importer != PKG:
            out.append(f'{where}: imports the package itself (its re-exports are for users)')
    return out


@pytest.fixture(scope='module')
def graph() -> Graph:
    return build_graph(REPO / PKG)


def test_the_package_layout_breaks_no_rule(graph):
    assert len(graph.modules) > 40 and len(graph.imports) > 200     # the graph was built
    assert violations(graph) == []


def test_no_import_cycle_even_through_function_level_imports(graph):
    assert find_cycle(graph.own(packages=True)) is None


def test_node_modules_do_not_import_each_other(graph):
    edges = graph.own()
    assert NODE_MODULES <= graph.modules
    for node in NODE_MODULES:
        assert not edges[node] & NODE_MODULES, node


def test_the_core_does_not_import_ros(graph):
    core = [i for i in graph.imports if not i.importer.startswith(f'{PKG}.ros')
            and (i.importer, i.target) not in LAZY_OWN]
    assert core
    assert not [i for i in core if i.target.split('.')[0] in ROS_PACKAGES
                or i.target.startswith(f'{PKG}.ros')]


def test_function_level_imports_are_few_and_optional(graph):
    lazy = [i for i in graph.imports if i.in_function]
    assert len(lazy) <= MAX_FUNCTION_IMPORTS, [f'{i.importer}:{i.line}' for i in lazy]
    for imp in lazy:
        assert (imp.target.split('.')[0] in OPTIONAL
                or (imp.importer, imp.target) in LAZY_OWN), f'{imp.importer}:{imp.line}'


def test_every_stage_of_the_paper_has_its_folder(graph):
    for folder in ('config', 'matching', 'mapping', 'localization', 'io', 'evaluation', 'cli',
                   'bench', 'ros'):
        assert f'{PKG}.{folder}' in graph.modules, folder


# ------------------------------------------------------------------ the checks can fail

def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / PKG
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    for sub in {p.parent for p in root.rglob('*.py')}:
        (sub / '__init__.py').touch()
    return root


def test_checks_find_a_broken_layout(tmp_path):
    lazy_mpl = ''.join(f'def f{i}():\n    import matplotlib\n'
                       for i in range(MAX_FUNCTION_IMPORTS + 1))
    root = _package(tmp_path, {
        'matching/scan.py': 'from .matcher import match\n',
        'matching/matcher.py': 'def match():\n    from .scan import x\n',     # hidden cycle
        'mapping/index.py': 'from ..localization import localizer\n',         # upwards
        'localization/localizer.py': 'import rclpy\n',                       # ROS in the core
        'io/bags.py': 'def read():\n    import numpy\n',                     # not optional
        'evaluation/plotting.py': lazy_mpl,                                   # one too many
        'ros/map_indexer.py': 'from ssm_localization.ros import global_localizer\n',
        'ros/global_localizer.py': 'import rclpy\n',
        'ros/play.py': '',
        'transforms.py': 'from ssm_localization import match_scans\n',
    })
    found = '\n'.join(violations(build_graph(root)))
    assert 'import cycle: ssm_localization.matching.matcher -> ssm_localization.matching.scan' \
        in found
    assert 'ssm_localization.mapping.index:1: mapping (layer 3) imports ' \
           'ssm_localization.localization.localizer' in found
    assert 'ssm_localization.localization.localizer:1: the ROS-free core imports rclpy' in found
    assert 'ssm_localization.io.bags:2: function-level import of numpy' in found
    assert (f'{MAX_FUNCTION_IMPORTS + 3} function-level imports '
            f'(at most {MAX_FUNCTION_IMPORTS})') in found
    assert 'ssm_localization.ros.map_indexer:1: node module imports node module ' \
           'ssm_localization.ros.global_localizer' in found
    assert 'ssm_localization.transforms:1: imports the package itself' in found


def test_checks_pass_a_sound_layout(tmp_path):
    root = _package(tmp_path, {
        'config/matcher.py': 'import dataclasses\n',
        'matching/matcher.py': 'from ..config import matcher\nfrom . import scan\n',
        'matching/scan.py': 'import numpy\n',
        'evaluation/plotting.py': 'def plot():\n    import matplotlib.pyplot\n',
        'cli/play_cmd.py': 'def run():\n    from ..ros.play import play_bag\n',
        'ros/play.py': 'import rclpy\nfrom ssm_localization.matching import matcher\n',
        'ros/global_localizer.py': 'from ssm_localization.ros import qos\n',
        'ros/qos.py': 'import rclpy\n',
        'ros/map_indexer.py': 'from ssm_localization.ros.qos import LATCHED\n',
    })
    graph = build_graph(root)
    assert graph.own()[f'{PKG}.matching.matcher'] == {f'{PKG}.config.matcher',
                                                      f'{PKG}.matching.scan'}
    assert violations(graph) == []


def test_a_cycle_through_a_package_init_is_found(tmp_path):
    # bench/localize imports cli/arguments, which runs cli/__init__ first; that imports
    # cli/bench_cmd, which imports bench/localize: importing bench.localize alone fails
    root = _package(tmp_path, {
        'bench/localize.py': 'from ..cli.arguments import positive_int\n',
        'cli/arguments.py': 'import argparse\n',
        'cli/bench_cmd.py': 'from ..bench import localize\n',
    })
    (root / 'cli' / '__init__.py').write_text('from . import bench_cmd\n')
    found = '\n'.join(violations(build_graph(root)))
    assert 'import cycle: ssm_localization.bench.localize -> ssm_localization.cli -> ' \
           'ssm_localization.cli.bench_cmd -> ssm_localization.bench.localize' in found
    (root / 'cli' / '__init__.py').write_text('')      # the package runs nothing: no cycle
    assert violations(build_graph(root)) == []
