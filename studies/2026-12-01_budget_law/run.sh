#!/usr/bin/env bash
# fast's flatter budget law (anneal.steps_exponent 1.7) with the coarse exclusion map over the
# first 40 % of the moves (docs/findings/time-to-quality.md, "A flatter budget law becomes fast's"), resumable:
# every run is a checkpointed pipeline job, so rerunning this script after an interruption
# continues where it stopped (even inside an N = 6000 run). Rows go to OUT/rows.jsonl.
#
#     bash studies/2026-12-01_budget_law/run.sh [--dry-run] [OUT [PART ...]]   # default OUT: results/budget_law_study
#
# --dry-run prints the commands instead of running them (the tests run that). PART is 1 or 2
# below (default: both, in order), with the environment that has vasc_pipeline installed active
# (the script calls `python`):
# 1. N = 500, 1000 and 2000, seeds 0-3 (about 25 min of one core);
# 2. N = 6000, seeds 0 and 1 (an hour or more each on one core).
# Since 2026-12-01 these settings are `fast`'s own; they are spelled out so that the rows stay
# reproducible when the default changes again. The reference rows (`fast_v1`, and `fast, coarse_exclusion
# 2 over 0.3`, the default before) are in benchmarks/results/time_to_quality_rows.jsonl. Runs one
# job at a time (--workers 1); start a second copy with the other part to use both cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
source studies/_dry_run.sh  # from the repository root
OUT=${1:-results/budget_law_study}
PARTS=("${@:2}")
[ ${#PARTS[@]} -gt 0 ] || PARTS=(1 2)
T=(run python benchmarks/time_to_quality.py --out "$OUT" --workers 1 --anneal fast
   --label "fast, steps_exponent=1.7, coarse_exclusion_phase=0.4"
   --override anneal.steps_exponent=1.7 --override anneal.coarse_exclusion_phase=0.4)
for part in "${PARTS[@]}"; do
  case $part in
    1) "${T[@]}" --sizes 2000 1000 500 --seeds 0 1 2 3 ;;
    2) "${T[@]}" --sizes 6000 --seeds 0 1 ;;
    *) echo "PART must be 1 or 2, got '$part'" >&2; exit 2 ;;
  esac
done
