#!/usr/bin/env bash
# The coarse exclusion map early in a run (anneal.coarse_exclusion_*; docs/findings/coarse-exclusion.md,
# "A coarse exclusion map early in a run") against the default it replaced, resumable: every run is
# a checkpointed pipeline job, so rerunning this script after an interruption continues where
# it stopped (even inside an N = 6000 run). Rows go to OUT/rows.jsonl.
#
#     bash studies/2026-11-27_coarse_exclusion/run.sh [--dry-run] [OUT [PART ...]]   # default OUT: results/coarse_exclusion
#
# PART is 1, 2 or 3 below (default: all three, in order); e.g. `... results/coarse_exclusion 3`
# continues only the full-budget N = 6000 runs. --dry-run prints the commands instead of running
# them (the tests run that).
#
# with the environment that has vasc_pipeline installed active (the script calls `python`).
#
# 1. equal moves at N = 500, 1000 and 2000, seeds 0-3;
# 2. N = 6000 at 0.37 of the budget (about an hour of one quiet core for the default), seeds
#    0 and 1;
# 3. N = 6000 at the full budget, seeds 0 and 1 (about 3 h each beside another job).
# From 2026-11-27 (later) to 2026-12-01 these settings were `fast`'s own; the budget law of then
# (anneal.steps_exponent 2) is spelled out, so that the rows stay reproducible.
# The old default's rows for the same runs are in benchmarks/results/time_to_quality_rows.jsonl
# (`fast (2026-11-26, two-part), p_swap=0.3`, the default's settings before the coarse map): its
# trajectories are deterministic, so only their wall times would change, and wall times taken
# one after the other on a shared machine are no paired comparison (the coarse part's speed is
# measured in docs/findings/coarse-exclusion.md). Runs one job at a time (--workers 1).
set -euo pipefail
cd "$(dirname "$0")/../.."
source studies/_dry_run.sh  # from the repository root
OUT=${1:-results/coarse_exclusion}
PARTS=("${@:2}")
[ ${#PARTS[@]} -gt 0 ] || PARTS=(1 2 3)
T=(run python benchmarks/time_to_quality.py --out "$OUT" --workers 1 --anneal fast)
COARSE=(--label "fast, coarse_exclusion 2 over 0.3" --override anneal.coarse_exclusion_factor=2
        --override anneal.coarse_exclusion_phase=0.3 --override anneal.steps_exponent=2)
for part in "${PARTS[@]}"; do
  case $part in
    1) "${T[@]}" "${COARSE[@]}" --sizes 500 1000 2000 --seeds 0 1 2 3 ;;
    2) "${T[@]}" "${COARSE[@]}" --sizes 6000 --seeds 0 1 --budgets 0.37 ;;
    3) "${T[@]}" "${COARSE[@]}" --sizes 6000 --seeds 0 1 ;;
    *) echo "PART must be 1, 2 or 3, got '$part'" >&2; exit 2 ;;
  esac
done
