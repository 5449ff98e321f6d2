#!/usr/bin/env bash
# The paper's m_b scan on the heart: N = 1000, m_b = 64.13 ... 6413 W m^-3 (five values,
# half-decade steps), 4 seeds, the default schedule. Rerunning resumes.
#
#     bash studies/paper/mb_scan.sh [--dry-run] [CLUSTER] [OVERRIDE ...]   # arguments: _common.sh
source "$(dirname "$0")/_common.sh"
run_sweep mb_scan +sweep=mb_scan
collect mb_scan
