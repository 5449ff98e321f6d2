#!/usr/bin/env bash
# The organ-scale and fidelity measurements (docs/findings/performance.md and fidelity.md), resumable: every run is a
# checkpointed pipeline job, so rerunning this script after an interruption continues where
# it stopped (even inside a 5-hour N = 6000 run). Rows go to OUT/rows.jsonl.
#
#     bash studies/2026-11-23_organ_scale/run.sh [--dry-run] [OUT]   # default OUT: results/organ_scale
#
# --dry-run prints the commands instead of running them (the tests run that).
#
# 1. anneal=fast_v1 (the baseline) against the packing candidate at the same budget (x1) and
#    half of it (x0.5), N = 500, 1000, 2000, seeds 0-3 (seeds 0-1 first);
# 2. the organ-scale reference: fast_v1 at N = 6000, seeds 0 and 1 (about 5 h a run on one core).
# Runs one job at a time (--workers 1); start a second copy with the N = 6000 part to use
# both cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
source studies/_dry_run.sh  # from the repository root
OUT=${1:-results/organ_scale}
T=(run python benchmarks/time_to_quality.py --out "$OUT" --workers 1)
# The packing candidate on fast_v1's schedule and budget, as measured (fast has changed since).
PACK=(--anneal fast_v1 --label pack --override anneal.packing_steps_per_terminal=10000
      --override anneal.supply_T_start=null)
for seeds in "0 1" "2 3"; do
    for n in 500 1000 2000; do
        # shellcheck disable=SC2086  # seeds is a list
        "${T[@]}" --anneal fast_v1 --sizes "$n" --seeds $seeds
        "${T[@]}" "${PACK[@]}" --sizes "$n" --seeds $seeds
        "${T[@]}" "${PACK[@]}" --sizes "$n" --seeds $seeds --budgets 0.5
    done
done
"${T[@]}" --anneal fast_v1 --sizes 6000 --seeds 0 1
