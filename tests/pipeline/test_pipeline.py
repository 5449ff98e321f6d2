"""The pipeline with real processes and real stores: LocalCluster, SIGKILL and resume, a killed
worker, an existing scheduler, bad input, two concurrent sweeps, the command line.

Every run is compared bit for bit with :func:`vasc_pipeline.engine.run` (an uninterrupted run
in this process) of the same job config. Jobs are tiny: 300k proposals on 16/24 terminals.
"""

from __future__ import annotations

import hashlib
import io
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from helpers import ENV, TIMEOUT, cli, finish, free_port, store_attrs  # noqa: E402

from vasc_pipeline import config, engine, job, store, sweep
from vasc_pipeline.config.frozen import thawed
from vasc_pipeline.model.tree import Tree, check_tree
from vasc_pipeline.pipeline import orchestrate

pytestmark = pytest.mark.integration  # the pipeline end to end (tests/conftest.py)

SMALL = [
    "+sweep=smoke",
    "sweep.n_terminals=[16,24]",
    "sweep.m_b=[641.3]",
    "sweep.seeds=[0,1]",
    "anneal.steps=300000",
    "anneal.trace_every=20000",
    "checkpoint.every_seconds=0.1",
    "cluster.dashboard_address=null",
]

_references: dict[str, engine.RunResult] = {}


def small(out: Path, *extra: str) -> config.RunConfig:
    return config.compose([*SMALL, f"output_dir={out}", *extra])


def reference(j: sweep.Job) -> engine.RunResult:
    """The uninterrupted run of a job (cached by config hash: output_dir is not part of it)."""
    key = store.config_hash(j.config)
    if key not in _references:
        _references[key] = engine.run(j.config, seed=j.coords["seed"])
    return _references[key]


def assert_runs_match_references(cfg: config.RunConfig) -> None:
    """Every run complete, readable by xarray, invariant-clean and bit-identical to its reference."""
    for j in sweep.expand(cfg):
        s = store.RunStore.open(j.store, mode="r")
        assert s.status == "complete", j.run_id
        ref = reference(j)
        tree = s.read_tree()
        np.testing.assert_array_equal(tree["parent"], ref.tree.parent, err_msg=j.run_id)
        np.testing.assert_array_equal(tree["position"], ref.tree.position, err_msg=j.run_id)
        check_tree(
            Tree(tree["parent"], ref.tree.children, tree["position"], ref.tree.n_downstream, 1), ref.problem.tissue
        )
        trace = xr.open_zarr(j.store, group="trace")
        np.testing.assert_array_equal(trace["total"].values, ref.trace["total"])
        a = s.attrs
        assert a["steps_done"] == j.config["anneal"]["steps"] and a["cost"] == ref.costs
        for k, v in a["cost"].items():
            assert a["cost_recomputed"][k] == pytest.approx(v, rel=1e-9, abs=1e-300), (j.run_id, k)


def results_snapshot(out: Path) -> dict[str, str]:
    """Content hash of every file of every run store (the lock and Hydra's logs are not results)."""
    return {
        str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted((out / "runs").rglob("*"))
        if p.is_file() and ".locks" not in p.parts
    }


def wait_for(predicate, what: str, timeout: float = TIMEOUT, proc: subprocess.Popen | None = None):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"process exited ({proc.returncode}) before {what}:\n{proc.stderr.read()}")
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def checkpointed_running_run(out: Path, n_checkpoints: int = 1) -> Path | None:
    """A still running run store with at least ``n_checkpoints`` committed checkpoints past step 0."""
    for p in sorted((out / "runs").glob("*.zarr")):
        try:
            a = store_attrs(p)
            n = sum(1 for c in (p / "checkpoints").iterdir() if c.name <= (a.get("checkpoint") or ""))
        except (OSError, ValueError):
            continue
        if a["status"] == "running" and a["steps_done"] > 0 and n >= n_checkpoints:
            return p
    return None


# -- a LocalCluster with two process workers --------------------------------------------------


def test_smoke_end_to_end_on_a_local_cluster(tmp_path):
    cfg = small(tmp_path, "cluster.n_workers=2")
    log = io.StringIO()
    result = orchestrate.run_sweep(cfg, stream=log, progress_interval=0.5)
    assert sorted(result.complete) == sorted(j.run_id for j in sweep.expand(cfg))
    assert result.failed == {} and result.resumed == []
    text = log.getvalue()
    assert "runs 4/4" in text and "steps/s" in text and "ETA" in text and "best cost per cell: sphere-N16" in text
    assert "4 completed now" in text and str(tmp_path / "runs") in text
    assert_runs_match_references(cfg)
    # Running the same command again skips every complete run and starts no cluster.
    before = results_snapshot(tmp_path)
    again = orchestrate.run_sweep(cfg, stream=io.StringIO())
    assert again.runs == [] and len(again.skipped) == 4
    assert results_snapshot(tmp_path) == before


# -- crashes ----------------------------------------------------------------------------------


# Runs of SMALL last ~0.4 s on a quiet machine: too short to catch one reliably with two
# checkpoints behind it. This test's runs are five times longer.
LONGER = [a if not a.startswith("anneal.steps=") else "anneal.steps=1500000" for a in SMALL]


def test_sigkill_of_the_sweep_then_rerun_resumes_and_ends_bit_identical(tmp_path):
    args = [*LONGER, f"output_dir={tmp_path}", "cluster.n_workers=2"]
    proc = cli(*args, start_new_session=True)
    try:
        victim = wait_for(lambda: checkpointed_running_run(tmp_path, 2), "two checkpoints", proc=proc)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the sweep, its scheduler and its workers, at once
        proc.wait()
    killed_at = store_attrs(victim)["steps_done"]
    assert 0 < killed_at < 1500000
    # A checkpoint broken by the crash (or later) must be survived: corrupt the newest one, so
    # that the rerun falls back to the previous one (still past step 0).
    newest = store_attrs(victim)["checkpoint"]
    chunk = next(
        p for p in (victim / "checkpoints" / newest / "position").rglob("*") if p.name != "zarr.json" and p.is_file()
    )
    chunk.write_bytes(chunk.read_bytes()[:3])
    code, output = finish(cli(*args))
    assert code == 0, output
    assert "falling back to the previous good checkpoint" in output
    resumes = store_attrs(victim)["resumes"]
    assert resumes[0]["step"] == 0 and resumes[-1]["step"] > 0, resumes  # resumed, not restarted
    assert "resumed from a checkpoint" in output
    assert_runs_match_references(config.compose([*LONGER, f"output_dir={tmp_path}"]))


def test_a_killed_worker_resumes_its_job_from_the_checkpoint(tmp_path):
    from distributed import Client, LocalCluster

    cfg = small(tmp_path)
    outcome: dict = {}
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):

        def sweep_thread():
            try:
                outcome["result"] = orchestrate.run_sweep(cfg, client=client, stream=io.StringIO())
            except BaseException as exc:  # surfaced by the assertion below
                outcome["error"] = exc

        thread = threading.Thread(target=sweep_thread)
        thread.start()

        def victim_on_a_worker():
            """(run store, worker) of a checkpointed run still processing; None if there is none now.

            Looked up together and polled: a run seen running may finish before its worker is
            asked, and then another run (or the next poll) is taken.
            """
            victim = checkpointed_running_run(tmp_path)
            if victim is None:
                return None
            key = f"vasc-run-{victim.name.removesuffix('.zarr')}-"
            processing = client.processing().items()
            worker = next((addr for addr, keys in processing if any(k.startswith(key) for k in keys)), None)
            return None if worker is None else (victim, worker)

        victim, worker = wait_for(victim_on_a_worker, "a checkpointed run on a worker")
        os.kill(client.run(os.getpid, workers=[worker])[worker], signal.SIGKILL)
        thread.join(TIMEOUT)
    assert "error" not in outcome, outcome.get("error")
    result = outcome["result"]
    assert result.failed == {} and len(result.complete) == 4
    summary = next(r for r in result.runs if r["run_id"] == victim.name.removesuffix(".zarr"))
    assert summary["resumed_from"] and summary["resumed_from"] > 0  # from its checkpoint, not step 0
    assert summary["session_steps"] == 300000 - summary["resumed_from"]
    assert_runs_match_references(cfg)


# -- an existing scheduler -------------------------------------------------------------------


@pytest.mark.slow  # ~20 s; the local cluster and Slurm paths stay in the default suite
def test_an_existing_scheduler_by_address_gives_the_same_results(tmp_path):
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask_cli = [sys.executable, "-m", "dask"]
    procs = [
        subprocess.Popen(
            [*dask_cli, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            env=ENV,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    try:
        procs.append(
            subprocess.Popen(
                [
                    *dask_cli,
                    "worker",
                    address,
                    "--nthreads",
                    "1",
                    "--nworkers",
                    "2",
                    "--host",
                    "127.0.0.1",
                    "--no-dashboard",
                ],
                env=ENV,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=120)
        cfg = small(tmp_path, "cluster=address", f"cluster.address={address}")
        result = orchestrate.run_sweep(cfg, stream=io.StringIO())
        assert result.failed == {} and len(result.complete) == 4
        assert_runs_match_references(cfg)
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()


# -- bad input --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def finished_output(tmp_path_factory):
    """An output_dir holding one complete run (run in-process, no cluster); tests must not change it."""
    tmp_path = tmp_path_factory.mktemp("finished")
    cfg = small(tmp_path, "sweep.n_terminals=[16]", "sweep.seeds=[0]")
    (j,) = sweep.expand(cfg)
    job.run_job(j)
    return tmp_path, cfg


def _bad(cfg: config.RunConfig, **changes) -> config.RunConfig:
    """A copy of ``cfg`` with fields set past validation (as a hand-written script could)."""
    cfg = thawed(cfg)
    for dotted, value in changes.items():
        section, _, name = dotted.rpartition("__")
        target = getattr(cfg, section) if section else cfg
        setattr(target, name, value)
    return cfg


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"n_terminals": 1, "sweep": None}, r"n_terminals must be an integer in \[2, 1e\+08\], got 1"),
        ({"sweep__n_terminals": [1]}, r"sweep\.n_terminals\[0\] must be an integer in \[2, 1e\+08\]"),
        ({"sweep__m_b": [0.0]}, r"sweep\.m_b\[0\] must be a finite number > 0"),
        ({"physics__m_b": -641.3, "sweep": None}, r"physics\.m_b must be a finite number > 0"),
        ({"anneal__steps": 0}, r"anneal\.steps must be an integer in \[1, 1e\+15\]"),
        ({"sweep__steps": [-5]}, r"sweep\.steps\[0\] must be an integer in \[1, 1e\+15\]"),
        ({"anneal__T_start": 1.0, "anneal__T_end": 1e12}, r"anneal\.T_end must be < anneal\.T_start"),
        ({"tissue__name": "liver"}, r"tissue\.name: unknown tissue 'liver'; accepted: box, heart, mask"),
        (
            {
                "tissue__name": "mask",
                "tissue__path": "/nonexistent/mask.npy",
                "tissue__voxel_size": 1e-3,
                "tissue__inlets": [[0.0, 0.0, 0.0]],
            },
            r"tissue\.path: mask file '/nonexistent/mask\.npy' does not exist",
        ),
        ({"anneal__T_end": 1e-8}, r"never mixed: anneal\.T_end: None \(stored\) vs 1e-08 \(requested\)"),
        ({"sweep__seeds": [0, 1], "physics__viscosity": 4e-3}, r"physics\.viscosity: 0\.0036 \(stored\) vs 0\.004"),
    ],
)
def test_bad_input_exits_non_zero_naming_the_field_and_touches_no_result(finished_output, changes, message):
    out, cfg = finished_output
    before = results_snapshot(out)
    log = io.StringIO()
    code = orchestrate.main(_bad(cfg, **changes), stream=log)
    assert code == 2
    assert log.getvalue().startswith("vasc_pipeline: error: ")
    assert re.search(message, log.getvalue()), log.getvalue()
    assert results_snapshot(out) == before


def test_bad_input_on_the_command_line(finished_output, tmp_path_factory):
    out, _ = finished_output
    before = results_snapshot(out)
    blocker = tmp_path_factory.mktemp("x") / "a_file"
    blocker.write_text("")
    cases = [  # (overrides, text the message must contain)
        ([*SMALL, f"output_dir={out}", "anneal.steps=0"], "anneal.steps must be an integer in [1, 1e+15]"),
        ([*SMALL, f"output_dir={out}", "tissue=liver"], "tissue/liver"),  # Hydra lists the tissues
        ([*SMALL, f"output_dir={out}", "anneal.T_end=1e-8"], "never mixed: anneal.T_end"),
        ([*SMALL, f"output_dir={blocker}/sub"], "output_dir: cannot create or write"),
        (["+sweep=nonexistent", f"output_dir={out}"], "sweep/nonexistent"),
    ]
    procs = [(cli(*args), text) for args, text in cases]  # concurrently: each start costs seconds
    for proc, text in procs:
        code, output = finish(proc)
        assert code != 0 and text in output, output
    assert results_snapshot(out) == before


def test_a_resumed_run_whose_stored_config_changed_is_refused_before_any_job(tmp_path):
    cfg = small(tmp_path, "sweep.n_terminals=[16]", "sweep.seeds=[0]", "checkpoint.every_seconds=1e-6")
    (j,) = sweep.expand(cfg)

    def crash(msg):
        if msg["step"] >= 100000:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        job.run_job(j, report=crash)
    before = results_snapshot(tmp_path)
    changed = replace(cfg, physics=replace(cfg.physics, gamma=3.0))
    log = io.StringIO()
    assert orchestrate.main(changed, stream=log) == 2
    assert f"physics.gamma: {cfg.physics.gamma!r} (stored) vs 3.0 (requested)" in log.getvalue()
    assert results_snapshot(tmp_path) == before


# -- locking ---------------------------------------------------------------------------------


def test_output_dir_lock_is_exclusive_and_names_the_holder(tmp_path):
    with orchestrate.output_dir_lock(tmp_path):
        with pytest.raises(orchestrate.OutputDirLocked, match=rf"in use by another sweep \(pid {os.getpid()}"):
            with orchestrate.output_dir_lock(tmp_path):
                pass
    with orchestrate.output_dir_lock(tmp_path):  # released on exit
        pass


def test_a_second_concurrent_sweep_refuses_and_the_first_completes_intact(tmp_path):
    args = [*SMALL, f"output_dir={tmp_path}", "cluster.n_workers=2"]
    first = cli(*args)
    lock = tmp_path / orchestrate.LOCK_NAME
    wait_for(lambda: lock.is_file() and f'"pid": {first.pid}' in lock.read_text(), "the first sweep's lock", proc=first)
    log = io.StringIO()
    assert orchestrate.main(small(tmp_path), stream=log) == 2
    assert f"is in use by another sweep (pid {first.pid}" in log.getvalue()
    code, output = finish(first)
    assert code == 0, output
    assert "4 completed now" in output
    assert_runs_match_references(small(tmp_path))


# -- the command line ------------------------------------------------------------------------


def test_single_run_default_goes_through_the_same_path(tmp_path):
    code, output = finish(
        cli(
            "tissue=plane2d",
            "n_terminals=8",
            "anneal.steps=20000",
            f"output_dir={tmp_path}",
            "cluster.n_workers=1",
            "cluster.dashboard_address=null",
        )
    )
    assert code == 0, output
    (path,) = (tmp_path / "runs").glob("*.zarr")
    assert path.name == "plane2d-N8-mb641.3-s0.zarr"
    attrs = store_attrs(path)
    assert attrs["status"] == "complete" and attrs["steps_done"] == 20000
    assert "1 completed now" in output


@pytest.mark.slow
def test_the_smoke_sweep_as_shipped(tmp_path):
    """`python -m vasc_pipeline +sweep=smoke output_dir=... cluster.n_workers=2` (about a minute)."""
    code, output = finish(cli("+sweep=smoke", f"output_dir={tmp_path}", "cluster.n_workers=2"))
    assert code == 0, output
    cfg = config.compose(["+sweep=smoke", f"output_dir={tmp_path}"])
    for j in sweep.expand(cfg):
        a = store_attrs(Path(j.store))
        assert a["status"] == "complete" and a["steps_done"] == config.scheduled_steps(j.run_config())
