"""
Every package.xml key resolves with rosdep for ROS 2 Jazzy on Ubuntu 24.04.

CI cannot fetch ros/rosdistro, so the check runs against the committed snapshot
``test/data/rosdep_jazzy_noble.yaml`` (rosdistro commit and dates inside), written by
``scripts/check_rosdep_keys.py --rosdistro DIR --write-snapshot``. The resolution logic itself is
tested here on a small rosdistro made in a temporary git repository.
"""
from __future__ import annotations

import importlib.util
import re
import subprocess
import sys

from helpers import REPO
import pytest
import yaml

SCRIPT = REPO / 'scripts' / 'check_rosdep_keys.py'


def _module():
    spec = importlib.util.spec_from_file_location('check_rosdep_keys', SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module      # dataclasses resolve annotations through sys.modules
    spec.loader.exec_module(module)
    return module


crk = _module()


def test_every_package_xml_key_resolves_in_the_snapshot():
    res = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True,
                         timeout=60)
    keys = crk.package_keys(REPO / 'package.xml')
    assert res.returncode == 0, res.stdout + res.stderr
    assert f'{len(keys)} of {len(keys)} keys resolve' in res.stdout
    for key in keys:
        assert re.search(rf'^\s+ok\s+{re.escape(key)}\s', res.stdout, re.M), key


def test_snapshot_provenance_and_the_key_that_does_not_exist():
    snap = yaml.safe_load(crk.SNAPSHOT.read_text())
    assert re.fullmatch(r'[0-9a-f]{40}', snap['rosdistro_commit'])
    assert re.fullmatch(r'\d{4}-\d\d-\d\d', str(snap['rosdistro_commit_date']))
    assert re.fullmatch(r'\d{4}-\d\d-\d\d', str(snap['snapshot_taken']))
    # the README's old install step named this key; rosdistro has no such key
    assert 'unresolved' in snap['keys']['python3-mcap-pip']
    assert 'python3-mcap-pip' not in crk.package_keys(REPO / 'package.xml')


def test_a_package_xml_with_an_unknown_key_fails(tmp_path, capsys):
    xml = tmp_path / 'package.xml'
    xml.write_text('<package format="3"><name>x</name><exec_depend>rclpy</exec_depend>'
                   '<exec_depend>python3-mcap-pip</exec_depend>'
                   '<test_depend>python3-not-a-key</test_depend></package>')
    assert crk.main(['--package-xml', str(xml)]) == 1
    out = capsys.readouterr().out
    assert re.search(r'MISSING\s+python3-mcap-pip', out)
    assert re.search(r'MISSING\s+python3-not-a-key\s+not in the snapshot', out)
    assert '1 of 3 keys resolve' in out


def _git(cwd, *args):
    subprocess.run(['git', '-C', str(cwd), *args], check=True, capture_output=True)


@pytest.fixture
def rosdistro(tmp_path):
    """Return a tiny rosdistro git repository covering the rule forms rosdep uses."""
    root = tmp_path / 'rosdistro'
    (root / 'rosdep').mkdir(parents=True)
    (root / 'jazzy').mkdir()
    (root / 'rosdep' / 'base.yaml').write_text(yaml.safe_dump({
        'plain-list': {'ubuntu': ['libplain']},
        'by-codename': {'ubuntu': {'jammy': ['old'], 'noble': ['new']}},
        'wildcard': {'ubuntu': {'*': ['any']}},
        'noble-null': {'ubuntu': {'jammy': ['old'], 'noble': None}},
        'jammy-only': {'ubuntu': {'jammy': ['old']}},
        'debian-only': {'debian': ['x']},
    }))
    (root / 'rosdep' / 'python.yaml').write_text(yaml.safe_dump({
        'python3-thing-pip': {'ubuntu': {'pip': {'packages': ['thing']}}},
        'python3-codename-pip': {'ubuntu': {'noble': {'pip': {'packages': ['cp']}}}},
    }))
    (root / 'jazzy' / 'distribution.yaml').write_text(yaml.safe_dump({'repositories': {
        'navigation2': {'release': {'packages': ['nav2_amcl', 'nav2_common'],
                                    'version': '1.3.0-1'}},
        'single': {'release': {'version': '0.1.0-1'}},
        'source_only': {'source': {'type': 'git'}},
    }}))
    _git(tmp_path, 'init', '-q', str(root))
    _git(root, 'add', '.')
    _git(root, '-c', 'user.name=t', '-c', 'user.email=t@t', 'commit', '-q', '-m', 'x')
    return root


def test_resolution_rules(rosdistro):
    keys = ['plain-list', 'by-codename', 'wildcard', 'noble-null', 'jammy-only', 'debian-only',
            'python3-thing-pip', 'python3-codename-pip', 'nav2_amcl', 'single', 'source_only',
            'absent']
    results, origin = crk.check_live(rosdistro, keys)
    got = {r.key: r for r in results}
    assert got['plain-list'].detail == 'apt: libplain'
    assert got['by-codename'].detail == 'apt: new'
    assert got['wildcard'].detail == 'apt: any'
    assert got['python3-thing-pip'].detail == 'pip: thing'
    assert got['python3-codename-pip'].detail == 'pip: cp'
    assert got['nav2_amcl'].ok and 'navigation2 1.3.0-1' in got['nav2_amcl'].detail
    assert got['single'].ok
    for key, reason in (('noble-null', 'noble: null'), ('jammy-only', 'not noble'),
                        ('debian-only', 'no ubuntu rule'), ('source_only', 'not in'),
                        ('absent', 'not in')):
        assert not got[key].ok and reason in got[key].reason, (key, got[key].reason)
    assert re.fullmatch(r'[0-9a-f]{40}', origin['commit'])


def test_live_check_reads_the_reported_commit_not_the_work_tree(rosdistro):
    (rosdistro / 'rosdep' / 'base.yaml').write_text(yaml.safe_dump({'plain-list': None}))
    results, origin = crk.check_live(rosdistro, ['plain-list'])
    assert results[0].ok and results[0].detail == 'apt: libplain'      # HEAD's, not the edit
    head = subprocess.run(['git', '-C', str(rosdistro), 'rev-parse', 'HEAD'], check=True,
                          capture_output=True, text=True).stdout.strip()
    assert origin['commit'] == head


def test_write_snapshot_round_trip(rosdistro, tmp_path, capsys):
    xml = tmp_path / 'package.xml'
    xml.write_text('<package format="3"><exec_depend>nav2_amcl</exec_depend>'
                   '<exec_depend>python3-thing-pip</exec_depend></package>')
    snap = tmp_path / 'snap.yaml'
    assert crk.main(['--package-xml', str(xml), '--rosdistro', str(rosdistro), '--snapshot',
                     str(snap), '--write-snapshot', '--also', 'noble-null']) == 0
    doc = yaml.safe_load(snap.read_text())
    assert set(doc['keys']) == {'nav2_amcl', 'python3-thing-pip', 'noble-null'}
    capsys.readouterr()
    assert crk.main(['--package-xml', str(xml), '--snapshot', str(snap)]) == 0
    assert '2 of 2 keys resolve' in capsys.readouterr().out
