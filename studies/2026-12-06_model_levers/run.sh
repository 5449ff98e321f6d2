#!/usr/bin/env bash
# Levers of a physiological coronary model, measured alone and combined on the heart under
# today's `fast` schedule, N = 1000 and 2000, seeds 0 and 1 (the paper's model, read literally,
# is the baseline: its size-scan stores are scored as they are, nothing re-run).
#
#   reach0     bifurcations on or in the heart (tissue.bifurcation_reach=0)
#   cut04      vessels under 0.4 mm diameter run in the myocardium (physics.r_cutoff=2e-4)
#   g73        the Huo-Kassab flow-diameter law D ~ Q^(3/7) (physics.gamma=7/3)
#   A          reach0 + cut04 + g73, the split between the arteries free
#   A_share    A with the pig's split fixed (tissue.inlet_share=[0.62,0.38], nearest start)
#   A_near     A, free split, each ostium starting with its nearest terminals
#   A_cco      A from a CCO tree (anneal.init=cco), free split
#   A_cut02    A with the intramural cutoff at 0.2 mm diameter
#   A_cut08    A with the intramural cutoff at 0.8 mm diameter
#   A_band     A with the split held in a band, 0.62 +- 0.15 of the terminals to the LCA
#              (tissue.inlet_share_tolerance=0.15, nearest start): the trees trade subtrees inside it
#   cco        our CCO growth (method=cco) under the paper's physics, and cco_phys under the
#              physiological model's (gamma 7/3, cutoff 0.4 mm): the constructive baseline
#   P_hot      model=physiological (A_band) at N = 4000 started at T = 16 W, the temperature the
#              anneal calibrates at N = 1000 (at N = 4000 it calibrates 1.6-2.4 W, too cold for
#              the trunks, whose barriers do not shrink with N)
#
# Resumable: every run is a checkpointed pipeline job; rerun the same command to continue.
# Rows of finished runs land in OUT/rows.jsonl and are merged into rows.jsonl beside this
# script after each part; summarise.py scores every store (inlet shares, bifurcations off the
# heart, terminal pressures, the errors against Kassab) into scored.jsonl and prints the table.
#
#     bash studies/2026-12-06_model_levers/run.sh [--dry-run] [OUT [LEVER ...]]
#
# --dry-run prints the commands instead of running them (the tests run that).
# OUT defaults to results/studies/model_levers (run stores stay out of git); LEVER defaults to
# every lever above, in order. One job at a time (WORKERS=1, the default): start a second copy
# with other levers, or set WORKERS=2, to use both cores.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here/../.."
source "$here/../_dry_run.sh"
OUT=${1:-results/studies/model_levers}
LEVERS=("${@:2}")
[ ${#LEVERS[@]} -gt 0 ] || LEVERS=(A A_share A_cco A_near g73 reach0 cut04 A_cut02 A_cut08 A_band cco cco_phys)
REACH0=(--override tissue.bifurcation_reach=0)
G73=(--override physics.gamma=2.3333333333333335)
SHARE=(--override "tissue.inlet_share=[0.62,0.38]" --override tissue.inlet_assignment=nearest)
cut() { echo --override "physics.r_cutoff=$1"; }
for lever in "${LEVERS[@]}"; do
  base=paper sizes=(1000 2000)
  case $lever in
    reach0) o=("${REACH0[@]}") ;;
    cut04) o=($(cut 2e-4)) ;;
    g73) o=("${G73[@]}") ;;
    A) o=("${REACH0[@]}" "${G73[@]}" $(cut 2e-4)) ;;
    A_share) o=("${REACH0[@]}" "${G73[@]}" $(cut 2e-4) "${SHARE[@]}") ;;
    A_near) o=("${REACH0[@]}" "${G73[@]}" $(cut 2e-4) --override tissue.inlet_assignment=nearest) ;;
    A_cco) o=("${REACH0[@]}" "${G73[@]}" $(cut 2e-4) --override anneal.init=cco) ;;
    A_cut02) o=("${REACH0[@]}" "${G73[@]}" $(cut 1e-4)) ;;
    A_cut08) o=("${REACH0[@]}" "${G73[@]}" $(cut 4e-4)) ;;
    cco) o=(--override method=cco) ;;
    cco_phys) o=(--override method=cco "${G73[@]}" $(cut 2e-4)) ;;
    A_band) o=("${REACH0[@]}" "${G73[@]}" $(cut 2e-4) "${SHARE[@]}" --override tissue.inlet_share_tolerance=0.15) ;;
    P_hot) base=physiological sizes=(4000) o=(--override anneal.T_start=16) ;;
    *) echo "LEVER must be one of reach0 cut04 g73 A A_share A_near A_cco A_cut02 A_cut08 A_band cco cco_phys P_hot, got '$lever'" >&2; exit 2 ;;
  esac
  # every lever is a change to a named model (the paper's, unless the lever says otherwise)
  run python benchmarks/time_to_quality.py --out "$OUT" --workers "${WORKERS:-1}" --anneal fast --sizes "${sizes[@]}" \
    --seeds 0 1 --label "$lever" --override "model=$base" "${o[@]}"
  merge "$OUT/rows.jsonl" "$here/rows.jsonl"
done
