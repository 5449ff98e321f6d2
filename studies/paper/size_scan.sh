#!/usr/bin/env bash
# The paper's size scan on the heart: N = 500, 1000, 2000, 4000, 6000, m_b = 641.3, 4 seeds,
# the default schedule. Rerunning resumes.
#
#     bash studies/paper/size_scan.sh [--dry-run] [CLUSTER] [OVERRIDE ...]   # arguments: _common.sh
source "$(dirname "$0")/_common.sh"
run_sweep size_scan +sweep=size_scan
collect size_scan
