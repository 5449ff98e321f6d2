#!/usr/bin/env bash
# The exclusion term's grid over N = 500-6000 on the heart, today's `fast` (steps_exponent 1.7,
# coarse map over 40 %), four variants, each one value for every N:
#   a   the supply grid's voxel (R_supply / 4, which follows N): tissue.exclusion_voxel_size=null
#   b   the exclusion grid fixed at the N = 500 voxel (1.153 mm)
#   b'  ... fixed at the N = 6000 voxel (0.504 mm), so N = 6000 is run a's, bit for bit
#   c   both grids fixed at the N = 6000 voxel (tissue.voxel_size), so N = 6000 is again a's
# Resumable: every run is a checkpointed pipeline job; rerun the same command to continue (even
# inside an N = 6000 run). Rows go to OUT/rows.jsonl and are merged into rows.jsonl beside this
# script after each part; summarise.py prints the tables of the README here.
#
#     bash studies/2026-12-02_exclusion_grid/run.sh [--dry-run] [OUT [PART ...]]
#
# --dry-run prints the commands instead of running them (the tests run that).
# OUT defaults to results/exclusion_grid_study; PART (default all, in order) is VARIANT:SIZES,
# SIZES "small" (N = 500, 1000, 2000, seeds 0-3) or "large" (N = 4000 and 6000, seeds 0, 1).
# Run with the environment that has vasc_pipeline installed (the script calls `python`), one
# job at a time (--workers 1); start a second copy with other parts to use both cores.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here/../.."
source "$here/../_dry_run.sh"
OUT=${1:-results/exclusion_grid_study}
PARTS=("${@:2}")
[ ${#PARTS[@]} -gt 0 ] || PARTS=(b:small a:small bp:small c:small b:large a:large bp:large c:large)
VOXEL_500=0.0011533753893850243   # the heart's R_supply / 4 at N = 500 (m)
VOXEL_6000=0.0005037831043371895  # ... at N = 6000
FAST=(--anneal fast --override anneal.steps_exponent=1.7 --override anneal.coarse_exclusion_phase=0.4)
for part in "${PARTS[@]}"; do
  variant=${part%%:*}
  case ${part#*:} in
    small) sizes=(--sizes 500 1000 2000 --seeds 0 1 2 3) ;;
    large) sizes=(--sizes 4000 6000 --seeds 0 1) ;;
    *) echo "PART must be VARIANT:small or VARIANT:large, got '$part'" >&2; exit 2 ;;
  esac
  case $variant in
    a) grid=(--label "exclusion grid a, supply grid" --override tissue.exclusion_voxel_size=null) ;;
    b) grid=(--label "exclusion grid b, 1.153 mm" --override tissue.exclusion_voxel_size=$VOXEL_500) ;;
    bp) grid=(--label "exclusion grid b-prime, 0.504 mm" --override tissue.exclusion_voxel_size=$VOXEL_6000) ;;
    c) grid=(--label "exclusion grid c, both 0.504 mm" --override tissue.voxel_size=$VOXEL_6000 --override tissue.exclusion_voxel_size=null) ;;
    *) echo "VARIANT must be a, b, bp or c, got '$variant'" >&2; exit 2 ;;
  esac
  if [ "${part#*:}" = large ] && [ "$variant" != a ] && [ "$variant" != b ]; then
    sizes=(--sizes 4000 --seeds 0 1)  # N = 6000 of b' and c is a's run: the same grids, bit for bit
  fi
  run python benchmarks/time_to_quality.py --out "$OUT" --workers 1 "${FAST[@]}" "${grid[@]}" "${sizes[@]}"
  # Every OUT this study has used, into the one rows file (parts may run in two OUTs side by side).
  merge "$OUT/rows.jsonl" "$here/rows.jsonl"
done
