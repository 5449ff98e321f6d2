# Shared by the paper's study scripts: the cluster argument and the copy of a study's small
# outputs. Sourced, not run. Usage of every study script:
#
#     bash studies/paper/<study>.sh [--dry-run] [CLUSTER] [OVERRIDE ...]
#
# --dry-run: print the commands instead of running them (the tests run that).
# CLUSTER: local (default), slurm, or a scheduler address (tcp://host:8786, tls://host:8786).
# OVERRIDEs: any further Hydra overrides, passed to every command of the study.
# RUNS_DIR (default results/studies): where the run stores go (large; not tracked).
# PAPER_DIR (default results/paper): where the study's small outputs are copied (tracked).
set -euo pipefail

RUNS_DIR=${RUNS_DIR:-results/studies}
PAPER_DIR=${PAPER_DIR:-results/paper}
PYTHON=${PYTHON:-python}
# --dry-run, run (and merge): the studies' shared shell functions
source "$(dirname "${BASH_SOURCE[0]}")/../_dry_run.sh"

cluster_overrides() {
    case "${1:-local}" in
        local) echo "cluster=local" ;;
        slurm) echo "cluster=slurm" ;;
        tcp://*|tls://*|ucx://*) echo "cluster=address cluster.address=$1" ;;
        *) echo "studies/paper: unknown cluster '$1' (accepted: local, slurm, tcp://HOST:PORT, tls://HOST:PORT)" >&2
           return 2 ;;
    esac
}

CLUSTER_ARGS=$(cluster_overrides "${1:-local}")
[ $# -gt 0 ] && shift
EXTRA=("$@")

# run_sweep NAME OVERRIDE...: one sweep into $RUNS_DIR/NAME (resumes when rerun; the sweep
# reduces its runs at the end: summary.zarr, comparison CSVs, best trees, figures). The paper's
# studies run the paper's model (model=paper), whatever the package's default.
run_sweep() {
    local name=$1
    shift
    # shellcheck disable=SC2086  # CLUSTER_ARGS holds one or two overrides
    run "$PYTHON" -m vasc_pipeline model=paper "$@" $CLUSTER_ARGS "output_dir=$RUNS_DIR/$name" "${EXTRA[@]}"
}

# collect NAME: copy the small outputs of $RUNS_DIR/NAME to $PAPER_DIR/NAME (not the run stores).
collect() {
    local src=$RUNS_DIR/$1 dst=$PAPER_DIR/$1
    if [ -n "$DRY" ]; then echo "# collect $src into $dst"; return; fi
    mkdir -p "$dst"
    rm -rf "$dst/summary.zarr" "$dst/figures" "$dst/trees"
    cp -r "$src/summary.zarr" "$src/figures" "$src/trees" "$dst/"
    cp "$src"/comparison*.csv "$dst/"
    echo "studies/paper: $1 -> $dst"
}
