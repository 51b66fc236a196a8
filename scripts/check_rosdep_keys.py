#!/usr/bin/env python3
"""
Check that every package.xml key resolves with rosdep for ROS 2 Jazzy on Ubuntu 24.04 (noble).

A key resolves when it is a package released in rosdistro's ``jazzy/distribution.yaml`` or a
rosdep key of ``rosdep/base.yaml`` / ``rosdep/python.yaml`` with a rule for Ubuntu noble.

Two modes:

- against a ros/rosdistro checkout (a work tree or a bare git directory; reads ``HEAD``)::

      scripts/check_rosdep_keys.py --rosdistro DIR [--write-snapshot]

  ``--write-snapshot`` records the resolution of every key (and of the ``--also`` keys) with the
  rosdistro commit in ``test/data/rosdep_jazzy_noble.yaml``;
- offline, against that committed snapshot (what the tests run; CI cannot fetch rosdistro)::

      scripts/check_rosdep_keys.py

Prints one line per key and exits 1 when a key does not resolve (or is not in the snapshot).
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
import datetime
from pathlib import Path
import subprocess
import sys
from typing import Any
import xml.etree.ElementTree as ET

import yaml

REPO = Path(__file__).resolve().parents[1]
SNAPSHOT = REPO / 'test' / 'data' / 'rosdep_jazzy_noble.yaml'
DISTRO, OS, CODENAME = 'jazzy', 'ubuntu', 'noble'
ROSDEP_FILES = ('rosdep/base.yaml', 'rosdep/python.yaml')
DISTRIBUTION_FILE = f'{DISTRO}/distribution.yaml'
DEPEND_TAGS = ('depend', 'build_depend', 'buildtool_depend', 'exec_depend', 'test_depend',
               'build_export_depend', 'buildtool_export_depend', 'doc_depend')
INSTALLERS = ('apt', 'pip', 'source')
# keys looked up although package.xml does not name them (recorded in the snapshot, not required)
ALSO = ('python3-mcap-pip', 'python3-mcap', 'mcap-ros2-support')


@dataclass(frozen=True)
class Resolution:
    """How a key resolves (``ok``), or why it does not (``reason``)."""

    key: str
    ok: bool
    source: str = ''
    detail: str = ''
    reason: str = ''

    def line(self) -> str:
        """One line of the report."""
        if self.ok:
            return f'  ok       {self.key:<28} {self.source:<28} {self.detail}'
        return f'  MISSING  {self.key:<28} {self.reason}'

    def as_record(self) -> dict[str, str]:
        """Return the snapshot entry."""
        if self.ok:
            return {'source': self.source, 'resolves_to': self.detail}
        return {'unresolved': self.reason}


def package_keys(package_xml: Path) -> list[str]:
    """Every dependency key of a package.xml, in file order, without duplicates."""
    root = ET.parse(package_xml).getroot()
    keys: list[str] = []
    for element in root:
        if element.tag in DEPEND_TAGS and element.text and element.text.strip() not in keys:
            keys.append(element.text.strip())
    return keys


def released_packages(distribution: dict[str, Any]) -> dict[str, tuple[str, str]]:
    """``{package: (repository, release version)}`` of a rosdistro distribution.yaml."""
    out: dict[str, tuple[str, str]] = {}
    for repo, entry in (distribution.get('repositories') or {}).items():
        release = (entry or {}).get('release')
        if not release or not release.get('version'):
            continue
        for package in release.get('packages') or [repo]:
            out[package] = (repo, str(release['version']))
    return out


def _installer_rule(rule: Any) -> str | None:
    """'apt: a b' / 'pip: x' for a resolved rule, None when it gives nothing to install."""
    if isinstance(rule, list):
        return 'apt: ' + ' '.join(map(str, rule)) if rule else None
    if isinstance(rule, str):
        return f'apt: {rule}'
    if isinstance(rule, dict):
        for installer in INSTALLERS:
            if installer in rule:
                packages = (rule[installer] or {}).get('packages') or []
                return f'{installer}: ' + ' '.join(map(str, packages)) if packages else None
    return None


def os_rule(entry: Any) -> tuple[str | None, str]:
    """Return the Ubuntu noble resolution of one rosdep entry: ``(rule text or None, reason)``."""
    if not isinstance(entry, dict) or OS not in entry:
        return None, f'no {OS} rule'
    rule = entry[OS]
    if rule is None:
        return None, f'{OS}: null'
    if isinstance(rule, dict) and not any(k in rule for k in INSTALLERS):
        if CODENAME in rule:
            rule = rule[CODENAME]
        elif '*' in rule:
            rule = rule['*']
        else:
            return None, f'{OS} rule lists {", ".join(map(str, rule))} but not {CODENAME}'
        if rule is None:
            return None, f'{OS} {CODENAME}: null'
    text = _installer_rule(rule)
    return (text, '') if text else (None, f'{OS} {CODENAME} rule installs nothing')


def resolve(key: str, rosdep: dict[str, dict[str, Any]],
            released: dict[str, tuple[str, str]]) -> Resolution:
    """Resolve one key against rosdep files (``{file: data}``) and the released packages."""
    if key in released:
        repo, version = released[key]
        return Resolution(key, True, DISTRIBUTION_FILE, f'ros-{DISTRO}-{key.replace("_", "-")} '
                                                        f'(repository {repo} {version})')
    reasons = []
    for name, data in rosdep.items():
        if key in data:
            text, reason = os_rule(data[key])
            if text:
                return Resolution(key, True, name, text)
            reasons.append(f'{name}: {reason}')
    if not reasons:
        reasons.append(f'not in {", ".join(rosdep)} nor released in {DISTRIBUTION_FILE}')
    return Resolution(key, False, reason='; '.join(reasons))


def _git(rosdistro: Path, *args: str) -> str:
    return subprocess.run(['git', '-C', str(rosdistro), *args], capture_output=True, text=True,
                          check=True).stdout


def check_live(rosdistro: Path, keys: list[str]) -> tuple[list[Resolution], dict[str, str]]:
    """Resolve ``keys`` against a rosdistro checkout at HEAD; also return its commit and date."""
    commit, date = _git(rosdistro, 'show', '-s', '--format=%H %cs', 'HEAD').split()
    rosdep = {relpath: yaml.safe_load(_git(rosdistro, 'show', f'{commit}:{relpath}')) or {}
              for relpath in ROSDEP_FILES}
    distribution = _git(rosdistro, 'show', f'{commit}:{DISTRIBUTION_FILE}')
    released = released_packages(yaml.safe_load(distribution) or {})
    return [resolve(k, rosdep, released) for k in keys], {'commit': commit, 'date': date}


def check_snapshot(snapshot: dict[str, Any], keys: list[str]) -> list[Resolution]:
    """Resolve ``keys`` from a snapshot written by ``--write-snapshot``."""
    recorded = snapshot.get('keys') or {}
    out = []
    for key in keys:
        entry = recorded.get(key)
        if entry is None:
            out.append(Resolution(key, False, reason='not in the snapshot: check it against a '
                                                     'rosdistro checkout with --rosdistro DIR '
                                                     '--write-snapshot'))
        elif 'unresolved' in entry:
            out.append(Resolution(key, False, reason=str(entry['unresolved'])))
        else:
            out.append(Resolution(key, True, str(entry['source']), str(entry['resolves_to'])))
    return out


def snapshot_text(results: list[Resolution], origin: dict[str, str]) -> str:
    """Return the snapshot file: header comment, provenance, one record per key."""
    doc = {
        'rosdistro_commit': origin['commit'],
        'rosdistro_commit_date': origin['date'],
        'snapshot_taken': datetime.date.today().isoformat(),
        'platform': f'ROS 2 {DISTRO}, {OS} {CODENAME}',
        'files': [*ROSDEP_FILES, DISTRIBUTION_FILE],
        'keys': {r.key: r.as_record() for r in results},
    }
    header = ('# Rosdep keys of package.xml (and a few looked up for the README), resolved\n'
              '# against ros/rosdistro at the commit below. Written by\n'
              '# scripts/check_rosdep_keys.py --rosdistro DIR --write-snapshot; read by\n'
              '# test/test_rosdep_keys.py (CI cannot fetch rosdistro). Refresh it when\n'
              '# package.xml gains a key.\n')
    return header + yaml.safe_dump(doc, sort_keys=False, width=100)


def main(argv: list[str] | None = None) -> int:
    """Command line entry point; exit status 0 when every key resolves."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--package-xml', type=Path, default=REPO / 'package.xml')
    parser.add_argument('--rosdistro', type=Path, help='ros/rosdistro checkout (or git dir)')
    parser.add_argument('--snapshot', type=Path, default=SNAPSHOT)
    parser.add_argument('--write-snapshot', action='store_true',
                        help='with --rosdistro: record the result in --snapshot')
    parser.add_argument('--also', nargs='*', default=list(ALSO),
                        help='extra keys to look up and record (not required to resolve)')
    args = parser.parse_args(argv)
    keys = package_keys(args.package_xml)
    if args.rosdistro is not None:
        extra_keys = [k for k in args.also if k not in keys]
        results, origin = check_live(args.rosdistro, keys + extra_keys)
        print(f'{args.package_xml}: {len(keys)} keys; ros/rosdistro {origin["commit"][:12]} '
              f'({origin["date"]}), ROS 2 {DISTRO} on {OS} {CODENAME}')
        if args.write_snapshot:
            args.snapshot.parent.mkdir(parents=True, exist_ok=True)
            args.snapshot.write_text(snapshot_text(results, origin))
            print(f'snapshot written to {args.snapshot}')
        extra = results[len(keys):]
        results = results[:len(keys)]
    else:
        if not args.snapshot.is_file():
            print(f'error: snapshot {args.snapshot} not found', file=sys.stderr)
            return 2
        snapshot = yaml.safe_load(args.snapshot.read_text()) or {}
        results = check_snapshot(snapshot, keys)
        extra = []
        print(f'{args.package_xml}: {len(keys)} keys; snapshot of ros/rosdistro '
              f'{str(snapshot.get("rosdistro_commit", "?"))[:12]} '
              f'({snapshot.get("rosdistro_commit_date", "?")}, taken '
              f'{snapshot.get("snapshot_taken", "?")}), ROS 2 {DISTRO} on {OS} {CODENAME}')
    for result in results:
        print(result.line())
    if extra:
        print('looked up as well (not in package.xml):')
        for result in extra:
            print(result.line())
    missing = [r.key for r in results if not r.ok]
    print(f'{len(results) - len(missing)} of {len(results)} keys resolve'
          + (f'; unresolved: {", ".join(missing)}' if missing else ''))
    return 1 if missing else 0


if __name__ == '__main__':
    sys.exit(main())
