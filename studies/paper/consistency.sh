#!/usr/bin/env bash
# The paper's consistency figure: 2-D plane trees (64 terminals) of several seeds after 1e4,
# 1e6, 1e8 and 5e9 proposed moves of the paper's schedule; as moves grow, trees of different
# seeds should become alike. Rerunning resumes. (5e9 moves: about 5 hours a run on one core.)
#
#     bash studies/paper/consistency.sh [--dry-run] [CLUSTER] [OVERRIDE ...]   # arguments: _common.sh
source "$(dirname "$0")/_common.sh"
run_sweep consistency +sweep=convergence anneal=paper sweep.name=consistency \
    "sweep.steps=[10000,1000000,100000000,5000000000]" "sweep.seeds=[0,1,2,3]"
collect consistency
