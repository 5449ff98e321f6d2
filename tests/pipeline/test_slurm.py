"""cluster=slurm against a real scheduler: a one-node Slurm on this machine (.ci/slurm.sh starts
one; CI always does). A sweep completes through sbatch worker jobs and is reduced, a worker job
cancelled mid-run is replaced and its run resumes from its checkpoint to the same tree, and the
dry run's job script is one the real sbatch accepts.

Where no Slurm answers these tests skip, saying why, except with VASC_REQUIRE_SLURM=1 (as
.ci/run sets it), where a missing Slurm fails them.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO, TIMEOUT, cli, finish, store_attrs

from vasc_pipeline import config, job, sweep
from vasc_pipeline.store import RunStore

pytestmark = pytest.mark.slurm


def _slurm_missing() -> str | None:
    """Why these tests cannot run here, or None."""
    for tool in ("sbatch", "squeue", "scancel", "sinfo"):
        if shutil.which(tool) is None:
            return f"{tool} is not on PATH (no Slurm client; bash .ci/slurm.sh installs and starts a one-node Slurm)"
    try:
        import cryptography  # noqa: F401
        import dask_jobqueue  # noqa: F401
    except ImportError as exc:
        return f"{exc.name} is not installed (pip install -e '.[test]')"
    state = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True, timeout=30)
    if state.returncode != 0 or not any(s in state.stdout for s in ("idle", "mixed", "allocated")):
        return f"no Slurm node answers (sinfo: {(state.stdout + state.stderr).strip() or 'nothing'})"
    return None


@pytest.fixture(scope="module", autouse=True)
def slurm():
    why = _slurm_missing()
    if why is not None:
        if os.environ.get("VASC_REQUIRE_SLURM") == "1":
            pytest.fail(f"VASC_REQUIRE_SLURM=1 but {why}")
        pytest.skip(why)


SLURM = [
    "cluster=slurm",
    "cluster.allow_insecure=true",  # the scheduler listens on this machine only
    "cluster.slurm.memory=1GB",
    "cluster.slurm.walltime=00:30:00",
    "cluster.dashboard_address=null",
    "cluster.startup_timeout=120",
]
SMALL_SWEEP = [
    "+sweep=smoke",
    "sweep.n_terminals=[16]",
    "sweep.m_b=[641.3,6413.0]",
    "sweep.seeds=[0]",
    "anneal.steps=100000",
]


def _running_worker_jobs() -> list[str]:
    """Slurm job ids of the running dask worker jobs (dask-jobqueue names them dask-worker)."""
    out = subprocess.run(["squeue", "-h", "-t", "R", "-o", "%i %j"], capture_output=True, text=True, timeout=30).stdout
    return [line.split()[0] for line in out.splitlines() if "dask-worker" in line]


def _trees(output_dir: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    out = {}
    for path in sorted((output_dir / "runs").glob("*.zarr")):
        tree = RunStore.open(path, mode="r").read_tree()
        out[path.name] = (tree["parent"], tree["position"])
    return out


def test_a_sweep_completes_through_sbatch_workers_and_is_reduced(tmp_path):
    code, output = finish(cli(*SMALL_SWEEP, f"output_dir={tmp_path}", *SLURM, "cluster.n_workers=2"))
    assert code == 0, output
    assert "reduced 2 complete runs in 2 cells" in output, output
    assert (tmp_path / "summary.zarr").is_dir() and list((tmp_path / "trees").glob("*.vtp"))
    for path in (tmp_path / "runs").glob("*.zarr"):
        assert RunStore.open(path, mode="r").attrs["status"] == "complete"
    # The same trees as on the local cluster: a run is a function of (config, seed) only.
    local = tmp_path / "local"
    code, output = finish(
        cli(*SMALL_SWEEP, f"output_dir={local}", "cluster.n_workers=1", "cluster.dashboard_address=null")
    )
    assert code == 0, output
    on_slurm, on_local = _trees(tmp_path), _trees(local)
    assert on_slurm.keys() == on_local.keys() and len(on_slurm) == 2
    for name, (parent, position) in on_slurm.items():
        np.testing.assert_array_equal(parent, on_local[name][0])
        np.testing.assert_array_equal(position, on_local[name][1])


@pytest.mark.slow  # a worker job cancelled and replaced: about 40 s; the sbatch path itself runs by default
def test_a_cancelled_worker_job_is_replaced_and_the_run_resumes_to_the_same_tree(tmp_path):
    run = [
        "tissue=sphere",
        "n_terminals=48",
        "anneal=fast_v1",
        "anneal.steps=6000000",
        "anneal.trace_every=100000",
        "checkpoint.every_seconds=1",
        "cluster.retries=3",
    ]
    proc = cli(*run, f"output_dir={tmp_path}", *SLURM, "cluster.n_workers=1")
    (j,) = sweep.expand(config.compose([*run, f"output_dir={tmp_path}"]))
    store = Path(j.store)
    deadline = time.monotonic() + TIMEOUT
    cancelled = None
    try:
        while time.monotonic() < deadline and proc.poll() is None:  # a checkpoint, then cancel the worker
            try:  # the store's root metadata appears once the job has created it
                checkpointed = store_attrs(store).get("steps_done", 0) > 0
            except (OSError, ValueError):
                checkpointed = False
            if checkpointed:
                jobs = _running_worker_jobs()
                if jobs:
                    cancelled = jobs[0]
                    subprocess.run(["scancel", cancelled], check=True, timeout=30)
                    break
            time.sleep(0.2)
        assert cancelled is not None, "no checkpoint and running worker job seen in time"
        steps_at_cancel = RunStore.open(store, mode="r").attrs["steps_done"]
        code, output = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert code == 0, output
    a = RunStore.open(store, mode="r").attrs
    assert a["status"] == "complete" and a["steps_done"] == 6_000_000
    assert 0 < steps_at_cancel < 6_000_000
    # It resumed from a checkpoint (not from scratch): the store records where each session started.
    starts = [entry["step"] for entry in a["resumes"]]
    assert len(starts) >= 2 and starts[0] == 0 and starts[-1] > 0, (starts, output)
    # The same tree as one uninterrupted run of the same config and seed.
    reference = tmp_path / "reference"
    (r,) = sweep.expand(config.compose([*run, f"output_dir={reference}"]))
    job.run_job(r)
    expected, got = RunStore.open(r.store, mode="r").read_tree(), RunStore.open(store, mode="r").read_tree()
    np.testing.assert_array_equal(got["parent"], expected["parent"])
    np.testing.assert_array_equal(got["position"], expected["position"])


def test_the_dry_runs_job_script_is_one_sbatch_accepts(tmp_path):
    code, output = finish(
        cli("tissue=sphere", "n_terminals=16", f"output_dir={tmp_path}", *SLURM, "cluster.dry_run=true")
    )
    assert code == 0, output
    assert not (tmp_path / "runs").exists()
    assert "#!" in output and "distributed.cli.dask_worker" in output, output
    start = output.index("#!")
    script = output[start : output.index("\n", output.index("distributed.cli.dask_worker", start))]
    assert "#SBATCH" in script, output
    path = tmp_path / "job.sh"
    path.write_text(script + "\n")
    # --test-only: the real scheduler validates the script and says when it would start; nothing is queued.
    test = subprocess.run(["sbatch", "--test-only", str(path)], capture_output=True, text=True, timeout=30, cwd=REPO)
    assert test.returncode == 0, test.stdout + test.stderr
    assert "to start at" in test.stdout + test.stderr, test.stdout + test.stderr
