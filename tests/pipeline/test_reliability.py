"""Reliability, first pass, one test per case: never mix configurations, never hang, name the broken store.

Runs are tiny (sphere, 16 terminals, a few thousand proposals); where the failure needs a real
process (Hydra, exit status, a cluster that never starts) ``python -m vasc_pipeline`` runs as a
subprocess, otherwise the plain functions run in this process.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import io
import re
import socket
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import zarr
from helpers import ENV, FAST_ONE_EXPONENTIAL, TIMEOUT, TINY_RUN, cli, finish, free_port

from vasc_pipeline import config, engine, job, store, sweep
from vasc_pipeline.config import ConfigError
from vasc_pipeline.model.tissue import TissueError
from vasc_pipeline.pipeline import orchestrate
from vasc_pipeline.pipeline.cluster import walltime_seconds, worker_lifetime

pytestmark = pytest.mark.integration  # the pipeline end to end (tests/conftest.py)

THREE_SEEDS = ["+sweep=smoke", "sweep.n_terminals=[16]", "sweep.m_b=[641.3]", "sweep.seeds=[0,1,2]"]


def tiny(out: Path, *extra: str) -> config.RunConfig:
    return config.compose([*TINY_RUN, f"output_dir={out}", *extra])


def run_in_process(out: Path, *extra: str) -> list[sweep.Job]:
    """Every job of the config, run here without Dask (the same stores a sweep writes)."""
    jobs = sweep.expand(tiny(out, *extra))
    for j in jobs:
        job.run_job(j)
    return jobs


def snapshot(out: Path) -> dict[str, str]:
    return {
        str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted((out / "runs").rglob("*"))
        if p.is_file() and ".locks" not in p.parts
    }


def chunk_files(array_dir: Path) -> list[Path]:
    return [p for p in array_dir.rglob("*") if p.is_file() and p.name != "zarr.json"]


# -- 1. one configuration per output_dir -----------------------------------------------------


def test_1_runs_of_another_configuration_are_refused_naming_the_keys(tmp_path):
    run_in_process(tmp_path, "anneal.steps=4000")
    before = snapshot(tmp_path)
    for extra, text in [
        (["anneal.steps=2000", "physics.gamma=3.0", "seed=1"], "physics.gamma: 2.3333333333333335 (stored) vs 3.0"),
        (["anneal.steps=2000", "seed=1"], "proposed moves of cell sphere-N16-mb641.3: 4000 (stored) vs 2000"),
        (["anneal.steps=4000", "anneal.p_swap=0.7", "n_terminals=24"], "anneal.p_swap: 0.3 (stored)"),
    ]:
        log = io.StringIO()
        assert orchestrate.main(tiny(tmp_path, *extra), stream=log) == 2, log.getvalue()
        assert "holds runs of another configuration" in log.getvalue() and text in log.getvalue(), log.getvalue()
    assert snapshot(tmp_path) == before
    # The sweep axes may differ: another seed, N or m_b (same steps per cell) joins the output_dir.
    p = orchestrate.plan(
        tiny(
            tmp_path,
            "anneal.steps=4000",
            "+sweep=smoke",
            "sweep.seeds=[0,1]",
            "sweep.n_terminals=[16,24]",
            "sweep.m_b=[641.3,6413]",
        )
    )
    orchestrate.inspect_stores(p)
    assert p.complete == {"sphere-N16-mb641.3-s0"} and not p.damaged


def test_1_a_directory_already_mixed_is_never_reduced(tmp_path):
    run_in_process(tmp_path)
    (other,) = sweep.expand(tiny(tmp_path / "elsewhere", "seed=1", "physics.gamma=3.0"))
    job.run_job(other)  # mixed by hand: moved in from another output_dir
    Path(other.store).rename(store.run_path(tmp_path, other.run_id))
    log = io.StringIO()
    assert orchestrate.reduce_stage(tiny(tmp_path, "+stage=reduce"), stream=log) == 2
    assert "holds runs of different configurations, which are never reduced together" in log.getvalue()
    assert (
        "sphere-N16-mb641.3-s1 differs from sphere-N16-mb641.3-s0 in physics.gamma: 3.0 (stored) vs 2.3333333333333335"
        in log.getvalue()
    ), log.getvalue()
    assert not (tmp_path / "summary.zarr").exists()


# -- 2. seeds validated alike ----------------------------------------------------------------


@pytest.mark.parametrize("value", [-1, 2**63])
def test_2_seed_and_sweep_seeds_are_validated_alike(value):
    messages = []
    for override in (f"seed={value}", f"+sweep=smoke sweep.seeds=[{value}]"):
        with pytest.raises(ConfigError) as info:
            config.compose(override.split())
        messages.append(str(info.value))
    assert messages == [
        f"seed must be an integer in [0, 2^63), got {value}",
        f"sweep.seeds[0] must be an integer in [0, 2^63), got {value}",
    ]
    config.compose(["seed=0"]), config.compose([f"seed={2**63 - 1}"])


# -- 3. an empty output_dir; nothing outside output_dir ---------------------------------------


def test_3_empty_output_dir_is_refused_and_reduce_never_creates_its_directory(tmp_path):
    work = tmp_path / "cwd"
    work.mkdir()
    missing = tmp_path / "missing"
    procs = [
        cli(*TINY_RUN, "output_dir=", cwd=work),
        cli(*TINY_RUN, "output_dir=' '", cwd=work),
        cli("+stage=reduce", f"output_dir={missing}", cwd=work),
    ]
    results = [finish(p) for p in procs]
    for code, output in results[:2]:
        assert code == 2 and "output_dir is empty" in output, output
    code, output = results[2]
    assert code == 2 and "nothing to reduce" in output, output
    assert list(work.iterdir()) == [] and not missing.exists()
    with pytest.raises(ConfigError, match="output_dir must name a directory"):
        config.compose(["output_dir="])


# -- 4. never hang: bounds, a cluster with no worker, jobs the scheduler never starts -----------


@pytest.mark.parametrize(
    "override, message",
    [
        ("anneal.steps=99999999999999999999999", r"anneal\.steps must be an integer in \[1, 1e\+15\]"),
        ("+sweep=smoke sweep.steps=[10000000000000000]", r"sweep\.steps\[0\] must be an integer in \[1, 1e\+15\]"),
        ("anneal.trace_every=10000000000000000", r"anneal\.trace_every must be an integer in \[1, 1e\+15\]"),
        ("checkpoint.every_seconds=1e9", r"checkpoint\.every_seconds must lie in \(0, 604800\] \(s; at most a week\)"),
        ("anneal.steps_at_1000=1e30", r"anneal\.steps_at_1000=1e\+30 schedules"),
        ("cluster.startup_timeout=0", r"cluster\.startup_timeout must be a finite number of seconds > 0"),
        ("anneal.calibration_samples=1000000000", r"anneal\.calibration_samples must be an integer in \[1, 1e\+07\]"),
        ("physics.pressure_terminal=20000", r"physics\.pressure_inlet must exceed physics\.pressure_terminal"),
        ("physics.pressure_inlet=-5", r"physics\.pressure_inlet must exceed"),
        ("tissue=mask tissue.inlets=[[0,0]]", r"tissue\.inlets\[0\] must be an \[x, y, z\] position"),
        ("tissue=mask tissue.inlets=[]", r"tissue\.inlets must hold at least one"),
        ("cluster=slurm cluster.dry_run=true cluster.slurm.memory=lots", r"cluster\.slurm\.memory must be an amount"),
        ("cluster=slurm cluster.dry_run=true cluster.slurm.interface=nonexistent0", r"cluster\.slurm\.interface"),
    ],
)
def test_4_upper_bounds_are_validated(override, message, tmp_path):
    with pytest.raises(ConfigError, match=message):
        cfg = config.compose(override.split() + [f"output_dir={tmp_path}"])
        orchestrate.check_cluster(cfg.cluster)
        sweep.expand(cfg)  # the grid's axes (what orchestrate.plan checks before any store or job)


def test_4_a_given_T_start_below_the_calibrated_T_end_is_refused_before_any_job():
    """T_end from anneal.T_end_rel needs the problem's physics: the check runs where problems
    are built, before any store or job."""
    cfg = config.compose(["tissue=sphere", "n_terminals=16", "anneal.T_start=1e-15"])
    with pytest.raises(ConfigError, match=r"anneal\.T_start=1e-15 W must exceed the end temperature"):
        engine.build_problem(cfg)


def test_4_a_scheduler_without_workers_stops_after_the_startup_timeout(tmp_path):
    port = free_port()
    scheduler = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "distributed.cli.dask_scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--no-dashboard",
        ],
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + TIMEOUT
        while True:
            with socket.socket() as probe:
                if probe.connect_ex(("127.0.0.1", port)) == 0:
                    break
            assert time.monotonic() < deadline and scheduler.poll() is None, "scheduler did not start"
            time.sleep(0.1)
        started = time.monotonic()
        code, output = finish(
            cli(
                *TINY_RUN,
                f"output_dir={tmp_path}",
                f"cluster.address=tcp://127.0.0.1:{port}",
                "cluster.startup_timeout=3",
            )
        )
        assert code == 1, output
        assert "no Dask worker started within cluster.startup_timeout=3 s" in output, output
        assert f"dask worker tcp://127.0.0.1:{port}" in output
        assert time.monotonic() - started < TIMEOUT
    finally:
        scheduler.kill()
        scheduler.wait()


_GATE = threading.Event()


def _occupy(i: int) -> int:
    """A task holding a worker's only thread until the test opens the gate."""
    _GATE.wait(60)
    return i


def _run_tasks_held(dask_worker) -> list[str]:
    """The sweep's run tasks a worker still holds (run on its event loop by Client.run)."""
    return [str(key) for key in dask_worker.state.tasks if str(key).startswith("vasc-run-")]


def test_4_jobs_no_worker_ever_starts_end_the_sweep(tmp_path):
    """Workers that never take the sweep's job (here: busy with other work) stop it after the timeout."""
    from distributed import Client, LocalCluster

    _GATE.clear()
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl,
        Client(cl) as client,
    ):
        busy = client.map(_occupy, range(4), pure=False)  # more than the worker's share: the rest is queued
        try:
            started = time.monotonic()
            with pytest.raises(
                orchestrate.SweepStartError,
                match=r"none of the 1 run started within "
                r"cluster\.startup_timeout=3 s",
            ):
                orchestrate.run_sweep(
                    tiny(tmp_path, "cluster.startup_timeout=3"), client=client, stream=io.StringIO(), reduce=False
                )
            assert time.monotonic() - started < TIMEOUT
            # The cancel reaches the worker asynchronously: open the gate only once the worker has
            # dropped the run's task, or the freed thread may take it first (the store is then complete).
            while any(client.run(_run_tasks_held).values()) and time.monotonic() - started < TIMEOUT:
                time.sleep(0.05)
        finally:
            _GATE.set()
            client.gather(busy)
    assert store.RunStore.open(store.run_path(tmp_path, "sphere-N16-mb641.3-s0"), mode="r").status == "running"


def test_4_slurm_without_sbatch_or_dask_jobqueue_is_refused_before_any_store(tmp_path):
    empty_path = tmp_path / "bin"
    empty_path.mkdir()
    code, output = finish(
        cli(*TINY_RUN, f"output_dir={tmp_path / 'out'}", "cluster=slurm", env={**ENV, "PATH": str(empty_path)})
    )
    assert code == 2, output
    assert "sbatch, which is not on PATH" in output or "needs dask-jobqueue" in output, output
    assert not (tmp_path / "out" / "runs").exists()


# -- 5. finite floats; a deterministic failure says so ------------------------------------------


@pytest.mark.parametrize(
    "override, field",
    [
        ("tissue.origin=[nan,0,0]", "tissue.origin[0]"),
        ("tissue.inlets=[[nan,0.0,0.0]]", "tissue.inlets[0][0]"),
        ("physics.m_b=nan", "physics.m_b"),
        ("physics.A_s=inf", "physics.A_s"),
        ("anneal.T_start=nan", "anneal.T_start"),
        ("+sweep=smoke sweep.m_b=[641.3,inf]", "sweep.m_b[1]"),
    ],
)
def test_5_every_float_must_be_finite(override, field):
    with pytest.raises(ConfigError, match=re.escape(f"{field} must be a finite number")):
        config.compose(override.split())


def test_5_a_deterministic_failure_is_not_retried_and_says_a_rerun_fails_the_same_way(tmp_path):
    # A trajectory whose polish meets an exactly singular factor: `fast` as it was before its
    # cold part and its fewer swaps; the failure, not the schedule, is what this test is about.
    old_fast = (*FAST_ONE_EXPONENTIAL, "anneal.p_swap=0.5")
    code, output = finish(cli(*TINY_RUN, "model=paper", *old_fast, f"output_dir={tmp_path}", "physics.m_b=1e300"))
    assert code == 1, output
    assert "FAILED: RuntimeError: Factor is exactly singular (deterministic: a rerun fails the same way)" in output
    assert "failed deterministically" in output and "Rerun the same command" not in output, output
    (path,) = (tmp_path / "runs").glob("*.zarr")
    assert len(store.RunStore.open(path, mode="r").attrs["resumes"]) == 1  # one session: never retried


# -- 6. grids: memory, coarseness, mask contents -------------------------------------------------


@pytest.mark.slow  # 34 s: six grids built to be refused
def test_6_grids_too_large_or_too_coarse_and_bad_masks_are_refused(tmp_path):
    with pytest.raises(
        TissueError,
        match=r"needs about .* GiB to build, more than the .* GiB of memory here; set a "
        r"larger tissue\.voxel_size",
    ):
        engine.build_problem(config.compose(["tissue=sphere", "tissue.voxel_size=1e-6"]))
    with pytest.raises(TissueError, match=r"GiB.*lower n_terminals"):
        engine.build_problem(config.compose(["tissue=sphere", "n_terminals=100000000", "anneal.steps=2000"]))
    with pytest.raises(
        TissueError,
        match=r"tissue\.voxel_size=1 m is coarser than the supply sphere .* the largest "
        r"accepted voxel_size is R_supply",
    ):
        engine.build_problem(config.compose(["tissue=sphere", "n_terminals=16", "tissue.voxel_size=1.0"]))
    mask = np.ones((4, 6, 6))
    mask[1, 2, 3] = np.nan
    np.save(tmp_path / "nan.npy", mask)
    (tmp_path / "text.npy").write_text("0,1,1\n1,1,0\n")
    base = ["tissue=mask", "tissue.voxel_size=0.001", "tissue.inlets=[[0.0,0.0,0.0]]", "n_terminals=2"]
    with pytest.raises(TissueError, match=r"holds 1 NaN or infinite voxels"):
        engine.build_problem(config.compose([*base, f"tissue.path={tmp_path / 'nan.npy'}"]))
    with pytest.raises(TissueError, match=r"is a text file, not a NumPy \.npy array"):
        engine.build_problem(config.compose([*base, f"tissue.path={tmp_path / 'text.npy'}"]))


# -- 7. Hydra-level errors exit 2 and list what is accepted --------------------------------------


def test_7_hydra_errors_exit_2_listing_the_accepted_options(tmp_path):
    cases = [
        ("tissue=liver", "accepted options for 'tissue': box, heart, mask, plane2d, sphere"),
        ("anneal.stepz=5", "unknown config key 'anneal.stepz'; accepted keys at anneal: name, T_start"),
        ("n_terminals=abc", "n_terminals: Value 'abc' of type 'str' could not be converted to Integer"),
        ("+sweep=nope", "accepted options for 'sweep': convergence, mb_scan, single, size_scan, smoke"),
    ]
    procs = [(cli(override, f"output_dir={tmp_path}"), text) for override, text in cases]
    for proc, text in procs:
        code, output = finish(proc)
        assert code == 2 and text in output and "Traceback" not in output, output
    assert not (tmp_path / "runs").exists()


# -- 8. damaged stores are named, left out, and the others proceed -------------------------------


def test_8_complete_stores_carry_checksums_of_tree_and_trace(tmp_path):
    (j,) = run_in_process(tmp_path)
    attrs = store.RunStore.open(j.store, mode="r").attrs
    assert set(attrs["checksums"]) == {f"tree/{n}" for n in ("parent", "position", "radius", "kind")} | {
        f"trace/{f[0]}" for f in store.TRACE_FIELDS
    }
    store.verify_store(j.store)
    # Rewrite a tree array with other (validly encoded) values: only the checksum can tell.
    position = zarr.open_group(j.store, mode="r+")["tree/position"]
    position[0, 0] = position[0, 0] + 1e-3
    with pytest.raises(store.StoreDamaged, match=r"array 'tree/position' fails its CRC-32 check\. Move it aside"):
        store.verify_store(j.store)


def test_8_a_sweep_leaves_damaged_stores_out_naming_them_and_runs_the_others(tmp_path):
    jobs = sweep.expand(tiny(tmp_path, *THREE_SEEDS, "checkpoint.every_seconds=1e-6"))
    unfinished, gone, fresh = jobs

    def crash(msg):
        if msg["step"] >= 1500:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        job.run_job(unfinished, report=crash)
    chunk = chunk_files(Path(unfinished.store) / "trace" / "total")[0]
    chunk.write_bytes(chunk.read_bytes()[:5])  # a truncated trace chunk
    job.run_job(gone)
    (Path(gone.store) / "zarr.json").unlink()  # a finished store without its root metadata
    before = snapshot(tmp_path)
    code, output = finish(cli(*TINY_RUN, f"output_dir={tmp_path}", *THREE_SEEDS, "checkpoint.every_seconds=1e-6"))
    assert code == 1, output
    assert "1 completed now" in output and "2 left out (damaged store)" in output, output
    for j, what in [(unfinished, "trace cannot be read"), (gone, "no zarr.json")]:
        assert re.search(
            rf"left out: {j.run_id}: run store '{re.escape(j.store)}' is damaged: [^\n]*{what}[^\n]*"
            rf"Move it aside",
            output,
        ), output
    assert store.RunStore.open(fresh.store, mode="r").status == "complete"
    after = snapshot(tmp_path)
    assert {k: v for k, v in after.items() if fresh.run_id not in k} == before  # the damaged ones left as they were


def test_8_the_reduce_stage_validates_its_config_before_reading_anything(tmp_path):
    (tmp_path / store.RUNS_DIR).mkdir()
    bad = config.compose([*TINY_RUN, f"output_dir={tmp_path}", "+stage=reduce", "physics.m_b=-1"], check=False)
    log = io.StringIO()
    assert orchestrate.reduce_stage(bad, stream=log) == 2
    assert "physics.m_b must be a finite number > 0, got -1.0" in log.getvalue(), log.getvalue()
    assert "Nothing was reduced" in log.getvalue()
    assert sorted(p.name for p in tmp_path.iterdir()) == [store.RUNS_DIR]


def test_8_the_reduction_names_damaged_stores_and_exits_1(tmp_path):
    jobs = run_in_process(tmp_path, *THREE_SEEDS)
    costs = {j.run_id: store.RunStore.open(j.store, mode="r").attrs["cost"]["total"] for j in jobs}
    best = min(jobs, key=lambda j: costs[j.run_id])
    other = next(j for j in jobs if j is not best)
    for j in (best, other):  # a corrupt best run and a corrupt other run
        chunk = chunk_files(Path(j.store) / "tree" / "position")[0]
        chunk.write_bytes(chunk.read_bytes()[:7])
    bare = store.run_path(tmp_path, "sphere-N16-mb641.3-s9")
    (bare / "tree").mkdir(parents=True)  # a store without zarr.json
    log = io.StringIO()
    code = orchestrate.reduce_stage(tiny(tmp_path, "+stage=reduce"), stream=log)
    text = log.getvalue()
    assert code == 1, text
    assert "reduced 1 complete runs in 1 cells (3 stores left out)" in text, text
    for path, what in [
        (best.store, "final tree or trace cannot be read"),
        (other.store, "cannot be read"),
        (str(bare), "no zarr.json"),
    ]:
        assert f"left out: run store '{path}' is damaged: " in text and what in text, text
    assert "Traceback" not in text


# -- 9. slurm: TLS by default, the dashboard off when asked, no dead link ------------------------


def test_9_slurm_scheduler_uses_temporary_tls_unless_allowed_insecure(tmp_path):
    pytest.importorskip("dask_jobqueue")
    pytest.importorskip("cryptography")
    cluster = config.compose(["cluster=slurm", "cluster.dashboard_address=null"]).cluster
    cl = orchestrate.slurm_cluster(cluster, tmp_path)
    try:
        assert cl.scheduler_address.startswith("tls://")
        script = cl.job_script()
        assert "--tls-ca-file" in script and "--tls-key" in script
        ca = re.search(r"--tls-ca-file (\S+)", script).group(1)
        assert Path(ca).parent == tmp_path  # the workers read the certificates from output_dir
        assert cl.scheduler.http_server is not None
        http = {sock.getsockname()[0] for sock in cl.scheduler.http_server._sockets.values()}
        assert http <= {"127.0.0.1"}, http  # dashboard off: its HTTP server only on loopback
    finally:
        cl.close()
    cluster = replace(cluster, allow_insecure=True)  # a validated config is frozen
    cl = orchestrate.slurm_cluster(cluster, tmp_path)
    try:
        assert cl.scheduler_address.startswith("tcp://")
        # the worker jobs' logs go with the results, not into the directory the sweep started from
        logs = re.findall(r"#SBATCH -[eo] (\S+)", cl.job_script())
        assert logs and all(Path(log).parent == tmp_path / ".slurm_logs" for log in logs), logs
    finally:
        cl.close()


def test_9_the_dashboard_link_is_printed_only_when_bokeh_can_draw_it(tmp_path):
    from distributed import Client, LocalCluster

    cfg = tiny(tmp_path, "cluster.dashboard_address=127.0.0.1:0")
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl,
        Client(cl) as client,
    ):
        log = io.StringIO()
        orchestrate.run_sweep(cfg, client=client, stream=log, reduce=False)
    if importlib.util.find_spec("bokeh") is None:
        assert "Dask dashboard at" not in log.getvalue()
        assert "no Dask dashboard: it needs bokeh" in log.getvalue()
    else:
        assert "Dask dashboard at http" in log.getvalue()


@pytest.mark.parametrize("dashboard", ["127.0.0.1:8787", "null"])
def test_9_a_taken_dashboard_port_without_bokeh_draws_no_word_from_dask(tmp_path, dashboard):
    """Without bokeh there is no dashboard: the local cluster asks for no dashboard port, so a
    port already taken draws no "Hosting the HTTP server on port ... instead" before our note."""
    import warnings

    if importlib.util.find_spec("bokeh") is not None:
        pytest.skip("bokeh is installed: the dashboard asked for is drawn, and Dask may move it")
    with socket.socket() as taken:
        # Without bokeh, Dask's HTTP server fell back to its own default port whatever the config said
        with contextlib.suppress(OSError):  # in use already: taken, as the test needs
            taken.bind(("", 8787))
            taken.listen()
        cluster = tiny(tmp_path, f"cluster.dashboard_address={dashboard}").cluster  # the default, or none
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with orchestrate.open_client(cluster, 1) as client:
                client.wait_for_workers(1, timeout=60)
    moved = [str(w.message) for w in caught if "already in use" in str(w.message)]
    assert not moved, moved


# -- 10. slurm: checked before any store; the job script without submitting ----------------------


def test_10_missing_dask_jobqueue_is_refused_before_any_store(tmp_path, monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "dask_jobqueue" else real(name, *a)
    )
    log = io.StringIO()
    assert orchestrate.main(tiny(tmp_path, "cluster=slurm"), stream=log) == 2
    assert "cluster=slurm needs dask-jobqueue: pip install 'vasc_pipeline[slurm]'" in log.getvalue()
    assert not (tmp_path / "runs").exists()


def test_10_dry_run_prints_the_slurm_job_script_and_runs_nothing(tmp_path):
    pytest.importorskip("dask_jobqueue")
    pytest.importorskip("cryptography")
    code, output = finish(
        cli(
            *TINY_RUN,
            f"output_dir={tmp_path}",
            "cluster=slurm",
            "cluster.dry_run=true",
            "cluster.slurm.walltime=01:00:00",
            "cluster.dashboard_address=null",
        )
    )
    assert code == 0, output
    assert "dry run: 1 run of 1 would run" in output and "sphere-N16-mb641.3-s0 (2000 proposed moves; new)" in output
    assert "#SBATCH -t 01:00:00" in output and "distributed.cli.dask_worker" in output, output
    # workers retire 6 minutes (10 %) before the walltime, give or take 90 s
    assert "--lifetime 3240s --lifetime-stagger 90s" in output, output
    assert f"#SBATCH -o {tmp_path}/.slurm_logs/" in output, output
    assert not (tmp_path / "runs").exists() and not (tmp_path / ".slurm_logs").exists()


@pytest.mark.parametrize(
    "walltime, seconds, lifetime",
    [
        ("04:00:00", 14400, ("13500s", "225s")),  # a lead of 15 minutes at most
        ("60", 3600, ("3240s", "90s")),  # minutes
        ("90:30", 5430, ("4887s", "136s")),  # minutes:seconds
        ("1-12", 129600, ("128700s", "225s")),  # days-hours
        ("2-0:30:00", 174600, ("173700s", "225s")),
        ("00:10:00", 600, ("480s", "30s")),  # a lead of 2 minutes at least
        ("UNLIMITED", float("inf"), None),
    ],
)
def test_10_slurm_workers_retire_before_the_walltime(walltime, seconds, lifetime):
    assert walltime_seconds(walltime) == seconds
    assert worker_lifetime(walltime) == lifetime


@pytest.mark.parametrize(
    "walltime, message",
    [("4h", "must be a SLURM time limit such as 04:00:00"), ("1:2:3:4", "time limit"), ("00:05:00", "at least 10")],
)
def test_10_a_bad_walltime_is_refused_naming_the_field(walltime, message):
    cfg = config.compose(["cluster=slurm", f"cluster.slurm.walltime={walltime}", "cluster.dry_run=true"])
    with pytest.raises(ConfigError, match=rf"cluster\.slurm\.walltime .*{message}"):
        orchestrate.check_cluster(cfg.cluster)


def _resumable_work(progress: str, units: int) -> int:
    """One unit a second, its progress kept in a file (as a run keeps its checkpoints)."""
    path = Path(progress)
    done = int(path.read_text()) if path.exists() else 0
    while done < units:
        time.sleep(1.0)
        done += 1
        path.write_text(str(done))
    return done


@pytest.mark.slow  # ~21 s
def test_10_a_task_whose_worker_retires_resumes_on_a_new_worker_without_counting_as_a_failure(tmp_path):
    """What cluster=slurm relies on (cluster.worker_lifetime): a worker retiring at its
    --lifetime is not a failure (allowed-failures 0 here), and adaptive scaling with
    minimum = maximum starts a new worker, where the task resumes from its progress."""
    import dask
    from distributed import Client, LocalCluster

    progress = tmp_path / "progress"
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        with LocalCluster(
            n_workers=1,
            threads_per_worker=1,
            processes=True,
            lifetime="4s",
            lifetime_stagger="0s",
            dashboard_address=None,
            host="127.0.0.1",
        ) as lc:
            lc.adapt(minimum=1, maximum=1, interval="200ms")
            with Client(lc) as client:
                assert client.submit(_resumable_work, str(progress), 9, pure=False).result(timeout=120) == 9


# -- 11. the package's own --help; the progress line ends before the summary ----------------------


def test_11_help_describes_the_package(tmp_path):
    code, output = finish(cli("--help"))
    assert code == 0, output
    for text in (
        "simulated annealing",
        "+sweep=NAME",
        "+stage=reduce",
        "Exit status: 0",
        "2 bad input",
        "<output_dir>/runs/<run_id>.zarr",
        "tissue: box, heart, mask, plane2d, sphere",
        "cluster.startup_timeout",
    ):
        assert text in output, text


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_11_the_last_progress_line_ends_before_the_summary(tmp_path):
    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl,
        Client(cl) as client,
    ):
        log = Terminal()
        orchestrate.run_sweep(tiny(tmp_path), client=client, stream=log, reduce=False)
    text = log.getvalue()
    at = text.index("vasc_pipeline: finished")
    assert text[at - 1] == "\n" and "runs 1/1" in text[:at], repr(text)


# -- 12. a failed stage after the runs sets the exit status ---------------------------------------


def test_12_a_failed_figure_stage_sets_the_exit_status_and_keeps_the_runs(tmp_path, monkeypatch):
    from vasc_pipeline import figures

    def broken(*args, **kwargs):
        raise ValueError("cannot draw two terminals")

    monkeypatch.setattr(figures, "make_figures", broken)
    log = io.StringIO()
    assert orchestrate.main(tiny(tmp_path, "cluster.n_workers=1"), stream=log) == 1, log.getvalue()
    assert "figures FAILED: ValueError: cannot draw two terminals" in log.getvalue()
    (path,) = (tmp_path / "runs").glob("*.zarr")
    assert store.verify_store(path).status == "complete" and (tmp_path / "summary.zarr").is_dir()
