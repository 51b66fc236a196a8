#!/usr/bin/env python3
"""
Write the committed tracking bags from the shared CARMEN logs (deterministic).

- ``bags/intel_track``: the tracking benchmark's kidnap protocol (``ssm_localization bench
  track``, ``io/sequences.py``) on a short piece of the Intel log: the first 300 odd-numbered
  scans (1-2 m apart) with their raw odometry in an odom frame offset from the map frame, spliced
  into three segments of a fifth of them taken at 0, 2/5 and 4/5, the odometry going on across
  each join by a 10 cm step forward while the ground truth jumps; map: ``maps/intel.yaml``.
- ``bags/aces_lookalike``: ACES kidnaps into look-alike corridors, where a tracker that only
  verifies its own pose keeps a confident wrong one (the cases ``Tracker``'s cross-check is for):
  five scans before each kidnap, four after, in ``LOOKALIKE`` (odd-scan indices); restamped one
  second apart; map: ``maps/aces.yaml``.
Both maps are the committed ones, built from the even-numbered scans. Topics: ``/map``,
``/scan``, ``/odom``, ``/ground_truth``.

Usage::

    .venv/bin/python scripts/make_track_bag.py [--data ../shared/data] [--force]
"""
import argparse
from pathlib import Path

import numpy as np
from ssm_localization.io.bag_writer import write_bag
from ssm_localization.io.carmen import read_carmen_log
from ssm_localization.io.sequences import (kidnap_sequence, log_sequence, ScanSequence,
                                           splice_kidnaps)
from ssm_localization.mapping.map_io import load_map_yaml

ROOT = Path(__file__).resolve().parents[1]
#: odd-scan index pairs (before, after) of ACES kidnaps into look-alike places
LOOKALIKE = [(103, 24), (201, 182), (15, 89), (169, 173)]


def intel_track(data: Path) -> ScanSequence:
    """Return the kidnap protocol on the first 300 odd-numbered Intel scans."""
    log = read_carmen_log(data / 'carmen' / 'intel-corrected.log.gz')
    return kidnap_sequence(log_sequence(log, np.arange(1, len(log), 2)[:300], name='intel'))


def aces_lookalike(data: Path) -> ScanSequence:
    """Return the ACES look-alike kidnaps, restamped one second apart."""
    log = read_carmen_log(data / 'carmen' / 'aces-corrected.log.gz')
    seq = log_sequence(log, name='aces')
    spliced = splice_kidnaps(seq, LOOKALIKE, name='aces_lookalike')
    return spliced.restamped(seq.scans[0].stamp, 1.0)


BAGS = {'intel_track': (intel_track, 'intel'), 'aces_lookalike': (aces_lookalike, 'aces')}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--data', default=str(ROOT.parent / 'shared' / 'data'))
    parser.add_argument('--bags', nargs='+', default=list(BAGS), choices=list(BAGS))
    parser.add_argument('--force', action='store_true', help='overwrite the bags')
    args = parser.parse_args()
    for name in args.bags:
        make, map_name = BAGS[name]
        seq = make(Path(args.data))
        odom, truth = seq.by_stamp()
        grid = load_map_yaml(ROOT / 'maps' / f'{map_name}.yaml')
        path = write_bag(ROOT / 'bags' / name, map=grid, scans=seq.scans, ground_truth=truth,
                         odom=odom, overwrite=args.force)
        print(f'wrote {path}: {len(seq)} scans, kidnaps before scans {seq.kidnaps}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
