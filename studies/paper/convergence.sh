#!/usr/bin/env bash
# The paper's convergence test: the 2-D plane, 64 terminals, 8 seeds, final cost against the
# number of proposed moves (1e4 ... 1e9) for the paper's schedule and for anneal=fast, one
# output directory each (a directory holds one configuration), then both on one plot
# ($PAPER_DIR/convergence.png). Rerunning resumes.
#
#     bash studies/paper/convergence.sh [--dry-run] [CLUSTER] [OVERRIDE ...]   # arguments: _common.sh
source "$(dirname "$0")/_common.sh"
STEPS="[10000,100000,1000000,10000000,100000000,1000000000]"
# "fast" here is anneal=fast_v1: the default schedule when this study ran (anneal=fast until
# 2026-11-25), frozen under that name so the study stays reproducible.
for schedule in paper fast; do
    preset=$schedule
    [ "$schedule" = fast ] && preset=fast_v1
    run_sweep "convergence_$schedule" +sweep=convergence "anneal=$preset" "sweep.steps=$STEPS"
    collect "convergence_$schedule"
done
run "$PYTHON" -m vasc_pipeline.figures convergence "$PAPER_DIR/convergence.png" \
    "paper=$RUNS_DIR/convergence_paper" "fast=$RUNS_DIR/convergence_fast"
