#!/usr/bin/env bash
# One tree on several workers (anneal.parts), heart, today's `fast`: the measurements of this
# study that take hours, resumable. Every run is a checkpointed pipeline job of
# benchmarks/time_to_quality.py: rerun the same command after an interruption (SIGTERM, a
# session's end) and it continues inside the run where it stopped. Rows go to OUT/rows.jsonl
# and are merged into rows.jsonl beside this script after each part.
#
#     bash studies/2026-12-02_parts/run.sh [--dry-run] [OUT [PART ...]]
#
# --dry-run prints the commands instead of running them (the tests run that).
# OUT defaults to results/studies/parts; PART (default all, in this order):
#   share     N = 2000, K = 2, anneal.part_share 0.9 / 0.95 / 0.99, seeds 0, 1, one thread
#             (the trees do not depend on the thread count; only their quality is read)
#   n6000     N = 6000, the serial run (one core) and K = 2, 4, 8 on 2 threads, seeds 0, 1: the
#             wall-time target, so the machine must hold nothing else
#   n20000    N = 20 000, K = 4 on 2 threads, seed 0: the organ-scale run (hours; spans sessions)
#   calibrate the cost model's calibration point, N = 6000, K = 4, seed 0, one thread (not
#             resumable: about an hour in one go)
#   check     the cost model's check at N = 2000, seed 0: its calibration at K = 4 and 8 (K = 2 is
#             calibrated by parts_cost_model.py at N = 1000 and 2000), then K = 2, 4, 8 measured on 1
#             and 2 threads, and the comparison (half an hour; the machine must hold nothing else)
#   budget    time to quality: K = 2 given more moves than the serial run, seeds 0, 1; N = 2000 at
#             1.12 and 1.25 times the budget (part_share 0.9 and 0.99) on one thread, then N = 6000
#             at 1.25 with part_share 0.99 on 2 threads (the machine must hold nothing else); a
#             third seed at N = 6000, serial and in parts on one thread (costs only)
# Run with the environment that has vasc_pipeline installed (the script calls `python`).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here/../.."
source "$here/../_dry_run.sh"
OUT=${1:-results/studies/parts}
PARTS=("${@:2}")
[ ${#PARTS[@]} -gt 0 ] || PARTS=(share n6000 n20000 calibrate check budget)
T=(run python benchmarks/time_to_quality.py --out "$OUT" --anneal fast)
for part in "${PARTS[@]}"; do
  case $part in
    share)
      for share in 0.9 0.95 0.99; do
        "${T[@]}" --sizes 2000 --seeds 0 1 --parts 2 --workers 1 \
          --override anneal.part_share=$share --label "fast-parts2-share$share"
      done ;;
    n6000)
      "${T[@]}" --sizes 6000 --seeds 0 1 --workers 1
      for k in 2 4 8; do "${T[@]}" --sizes 6000 --seeds 0 1 --parts $k --workers 2; done ;;
    n20000)
      "${T[@]}" --sizes 20000 --seeds 0 --parts 4 --workers 2 ;;
    calibrate)
      run python benchmarks/parts_cost_model.py --out "$OUT/cost_model" --sizes 6000 --parts 4 --seeds 0
      merge "$OUT/cost_model/rows.jsonl" "$here/cost_model_rows.jsonl" ;;
    check)
      run python benchmarks/parts_cost_model.py --out "$OUT/cost_model" --sizes 2000 --parts 4 8 --seeds 0
      for k in 2 4 8; do
        for w in 1 2; do "${T[@]}" --sizes 2000 --seeds 0 --parts $k --workers $w --label "check-parts$k-w$w"; done
      done
      run python benchmarks/parts_cost_model.py --out "$OUT/cost_model" --check "$OUT/rows.jsonl" ;;
    budget)
      for b in 1.12 1.25; do "${T[@]}" --sizes 2000 --seeds 0 1 --parts 2 --workers 1 --budgets $b; done
      more=(--parts 2 --budgets 1.25 --override anneal.part_share=0.99)  # the time-to-quality setting
      "${T[@]}" "${more[@]}" --sizes 2000 --seeds 0 1 --workers 1 --label fast-parts2-w1-share0.99
      "${T[@]}" "${more[@]}" --sizes 6000 --seeds 0 1 --workers 2 --label fast-parts2-w2-share0.99
      "${T[@]}" --sizes 6000 --seeds 2 --workers 1
      "${T[@]}" "${more[@]}" --sizes 6000 --seeds 2 --workers 1 --label fast-parts2-w1-share0.99 ;;
    *) echo "PART must be share, n6000, n20000, calibrate, check or budget, got '$part'" >&2; exit 2 ;;
  esac
  [ -n "$DRY" ] || [ -f "$OUT/rows.jsonl" ] || continue
  merge "$OUT/rows.jsonl" "$here/rows.jsonl"
done
