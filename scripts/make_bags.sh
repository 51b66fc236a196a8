#!/usr/bin/env bash
# Regenerate the committed maps/ and bags/ from the shared data, deterministically.
#   scripts/make_bags.sh [SHARED_DATA_DIR]     (default: ../shared/data beside the repository)
# Uses the package CLI (.venv/bin/ssm_localization; override with SSM=...).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DATA="${1:-$ROOT/../shared/data}"
SSM="${SSM:-$ROOT/.venv/bin/ssm_localization}"
CARMEN="$DATA/carmen"
cd "$ROOT"
mkdir -p maps bags

# Maps from the even scans of each CARMEN log (0.05 m); Intel's odd scans, every 5th, as queries
# (/map, /scan, /ground_truth, /odom).
"$SSM" convert-carmen "$CARMEN/intel-corrected.log.gz" -o maps --bag-out bags/intel_queries \
    --map-scans even --query-scans odd --every 5 --force --quiet
"$SSM" convert-carmen "$CARMEN/aces-corrected.log.gz" -o maps --no-bag --quiet
"$SSM" convert-carmen "$CARMEN/freiburg-079-corrected.log.gz" -o maps --no-bag --quiet

# Simulated queries on the nav2 depot map: clean 360-degree scans, and cluttered 180-degree ones.
"$SSM" simulate "$DATA/maps/depot.yaml" -o bags/depot_sim -n 30 --beams 360 --fov 360 \
    --noise 0.01 --clutter 0 --short-fraction 0 --seed 0 --force --quiet
"$SSM" simulate "$DATA/maps/depot.yaml" -o bags/depot_sim_clutter -n 20 --beams 360 \
    --fov 360 --noise 0.01 --clutter 8 --short-fraction 0.05 --seed 1 --force --quiet
"$SSM" simulate "$DATA/maps/depot.yaml" -o bags/depot_sim_fov180 -n 20 --beams 180 \
    --fov 180 --noise 0.01 --clutter 0 --short-fraction 0 --seed 2 --force --quiet

# Tracking bags with /odom and kidnaps (Intel protocol piece, ACES look-alike corridors); they use
# the maps written above.
"$ROOT/.venv/bin/python" scripts/make_track_bag.py --data "$DATA" --force

du -ab maps bags | sort -k2
