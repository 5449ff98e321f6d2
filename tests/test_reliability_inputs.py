"""Reliability, second pass: a run's input files are part of its identity (by content), and the
inputs a user types are accepted or refused by name. Tiny problems, mostly in this process."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from helpers import TINY_RUN, cli, finish

from vasc_pipeline import config, engine, store, sweep
from vasc_pipeline.config import ConfigError
from vasc_pipeline.config.identity import INPUTS
from vasc_pipeline.pipeline import orchestrate, planning

H = 1e-3  # m


def ball(n: int, r: float) -> np.ndarray:
    z, y, x = np.indices((n, n, n)) - (n - 1) / 2
    return (x**2 + y**2 + z**2 <= r**2).astype(np.uint8)


def mask_overrides(path: Path, out: Path, *extra: str) -> list[str]:
    data = np.load(path)
    z, y, x = np.argwhere(data)[np.argmax(np.argwhere(data)[:, 0])]
    inlet = [float(H * x), float(H * y), float(H * z)]
    return [
        "tissue=mask",
        f"tissue.path={path}",
        f"tissue.voxel_size={H!r}",
        "tissue.origin=[0.0,0.0,0.0]",
        f"tissue.inlets=[[{inlet[0]!r},{inlet[1]!r},{inlet[2]!r}]]",
        "n_terminals=8",
        "anneal.steps=2000",
        "anneal.trace_every=500",
        f"output_dir={out}",
        *extra,
    ]


def plan_and_create(overrides: list[str]) -> planning.Plan:
    """What a sweep does before dispatch: plan, check the stores on disk, create the new ones."""
    p = planning.plan(config.compose(overrides))
    with orchestrate.output_dir_lock(p.output_dir):
        planning.inspect_stores(p)
        planning.create_stores(p)
    return p


# -- 1. an input file edited in place is another input ---------------------------------------


def test_mask_overwritten_in_place_is_refused_by_name(tmp_path):
    mask = tmp_path / "tissue.npy"
    np.save(mask, ball(16, 7.0))
    out = tmp_path / "out"
    (j,) = plan_and_create(mask_overrides(mask, out, "seed=0")).jobs
    stored = store.RunStore.open(j.store, mode="r").attrs["config"]
    assert stored[INPUTS]["tissue.path"].startswith("sha256:")
    np.save(mask, ball(16, 5.0))  # same path, another tissue
    # a new seed beside the stored one: the one-configuration rule compares the content
    with pytest.raises(ConfigError, match=r"tissue\.path: the content of .*tissue\.npy.* changed in place"):
        plan_and_create(mask_overrides(mask, out, "+sweep=single", "sweep.seeds=[0,1]"))
    assert not (out / "runs" / f"{j.run_id[:-1]}1.zarr").exists()  # nothing was created
    # the stored run itself, resumed: refused too
    with pytest.raises(ConfigError, match=r"tissue\.path: the content of"):
        plan_and_create(mask_overrides(mask, out, "seed=0"))
    np.save(mask, ball(16, 7.0))  # the original content again: accepted
    plan_and_create(mask_overrides(mask, out, "+sweep=single", "sweep.seeds=[0,1]"))


def test_exclusion_mask_and_terminals_csv_are_part_of_the_identity(tmp_path):
    mask, excl = tmp_path / "tissue.npy", tmp_path / "excl.npy"
    data = ball(16, 7.0)
    np.save(mask, data)
    np.save(excl, np.zeros_like(data))
    base = mask_overrides(mask, tmp_path / "a", f"tissue.exclusion_path={excl}")
    problem = engine.build_problem(config.compose(base))
    sites = engine.initial_state(problem, seed=3).position[1:9]
    csv = tmp_path / "sites.csv"
    np.savetxt(csv, sites, delimiter=",", header="x,y,z", comments="")
    overrides = [*base, f"terminals.path={csv}"]
    (j,) = plan_and_create(overrides).jobs
    assert set(store.RunStore.open(j.store, mode="r").attrs["config"][INPUTS]) == {
        "tissue.path",
        "tissue.exclusion_path",
        "terminals.path",
    }
    np.savetxt(csv, sites[::-1], delimiter=",", header="x,y,z", comments="")
    with pytest.raises(ConfigError, match=r"terminals\.path: the content of .*sites\.csv"):
        plan_and_create([*overrides, "+sweep=single", "sweep.seeds=[0,1]"])
    np.savetxt(csv, sites, delimiter=",", header="x,y,z", comments="")
    exclusion = np.zeros_like(data)
    exclusion[0, 0, 0] = 1
    np.save(excl, exclusion)
    with pytest.raises(ConfigError, match=r"tissue\.exclusion_path: the content of .*excl\.npy"):
        plan_and_create(overrides)


def test_an_inlets_file_is_part_of_the_identity(tmp_path):
    mask = tmp_path / "tissue.npy"
    np.save(mask, ball(16, 7.0))
    base = [o for o in mask_overrides(mask, tmp_path / "out") if not o.startswith("tissue.inlets=")]
    inlets = tmp_path / "ostia.json"
    inlets.write_text('{"ostium": [0.0075, 0.0075, 0.0145]}')
    overrides = [*base, f"tissue.inlets_path={inlets}"]
    (j,) = plan_and_create(overrides).jobs
    assert set(store.RunStore.open(j.store, mode="r").attrs["config"][INPUTS]) == {"tissue.path", "tissue.inlets_path"}
    inlets.write_text('{"ostium": [0.0075, 0.0075, 0.0005]}')  # the other pole: another tree
    with pytest.raises(ConfigError, match=r"tissue\.inlets_path: the content of .*ostia\.json.* changed in place"):
        plan_and_create([*overrides, "+sweep=single", "sweep.seeds=[0,1]"])


def test_a_store_written_before_the_input_digests_keeps_resuming(tmp_path):
    mask = tmp_path / "tissue.npy"
    np.save(mask, ball(16, 7.0))
    out = tmp_path / "out"
    (j,) = plan_and_create(mask_overrides(mask, out)).jobs
    s = store.RunStore.open(j.store)
    legacy = {k: v for k, v in s.attrs["config"].items() if k != INPUTS}  # as older versions wrote it
    s._set_attrs(config=legacy, config_hash=store.config_hash(legacy))
    p = plan_and_create(mask_overrides(mask, out, "+sweep=single", "sweep.seeds=[0,1]"))
    assert p.started == {j.run_id: 0}


def test_runs_without_input_files_keep_their_identity():
    (j,) = sweep.expand(config.compose(TINY_RUN))
    assert INPUTS not in j.config  # the hash of every earlier store of the built-in tissues stands
    assert re.fullmatch(r"[0-9a-f]{64}", store.config_hash(j.config))


# -- 4. counts written as floats --------------------------------------------------------------


def test_a_count_written_as_a_float_is_the_integer_it_is():
    cfg = config.compose([*TINY_RUN, "anneal.steps=1e5", "anneal.trace_every=5e4", "sweep.steps=[1e4,2.5e4]"])
    assert cfg.anneal.steps == 100_000 and isinstance(cfg.anneal.steps, int)
    assert cfg.anneal.trace_every == 50_000 and cfg.sweep.steps == [10_000, 25_000]
    assert [j.coords["steps"] for j in sweep.expand(cfg)] == [10_000, 25_000]
    assert config.compose([*TINY_RUN, "anneal.T_start=1e5"]).anneal.T_start == 1e5  # floats stay floats


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("anneal.steps=150000.5", r"anneal\.steps must be an integer \(a count\), got 150000\.5"),
        ("sweep.steps=[1e4,1.5e4,2.5e-1]", r"sweep\.steps\[2\] must be an integer \(a count\), got 2\.5e-1"),
    ],
)
def test_a_count_with_a_fraction_is_refused_naming_the_key(override, message):
    with pytest.raises(ConfigError, match=message):
        config.compose([*TINY_RUN, override])


def test_the_command_line_takes_1e5_steps_and_refuses_a_fraction(tmp_path):
    code, output = finish(cli(*TINY_RUN, f"output_dir={tmp_path}", "anneal.steps=2e3", "cluster.dry_run=true"))
    assert code == 0 and "(2000 proposed moves; new)" in output, output
    code, output = finish(cli(*TINY_RUN, f"output_dir={tmp_path}", "anneal.steps=150000.5"))
    assert code == 2 and "anneal.steps must be an integer (a count), got 150000.5" in output, output
    assert "Traceback" not in output and not (tmp_path / "runs").exists()


# -- 5. physical parameters inside the range where the model is defined ----------------------


@pytest.mark.parametrize("gamma", ["0.01", "0.5", "4.5", "100"])
def test_gamma_outside_the_model_is_refused_naming_it(gamma):
    with pytest.raises(ConfigError, match=rf"physics\.gamma must lie in \[1, 4\].*got {gamma}"):
        config.compose([*TINY_RUN, f"physics.gamma={gamma}"])


@pytest.mark.parametrize(
    "override", ["physics.inlet_radius=1e-80", "physics.viscosity=1e300", "physics.total_flow=1e200"]
)
def test_physics_giving_a_segment_an_undefined_cost_is_refused(override):
    with pytest.raises(ConfigError, match=r"outside the floating-point range .* the model is not defined"):
        config.compose([*TINY_RUN, override])


def test_gamma_across_its_range_runs():
    for gamma in ("1", "2.1", "4"):
        problem = engine.build_problem(config.compose([*TINY_RUN, f"physics.gamma={gamma}"]))
        assert np.isfinite(problem.model.tables).all() and (problem.model.tables[:, 1:] > 0).all()


# -- 6. +stage=reduce while a sweep runs ------------------------------------------------------


def test_reduce_while_a_sweep_holds_the_directory_names_the_runs_and_the_sweep(tmp_path):
    import io
    import os

    out = tmp_path / "out"
    overrides = [*TINY_RUN, f"output_dir={out}", "+sweep=single", "sweep.seeds=[0,1]"]
    p = plan_and_create(overrides)  # two stores, status "running", as a sweep leaves them while it runs
    log = io.StringIO()
    with orchestrate.output_dir_lock(out):  # the sweep's lock (another open file: flock tells them apart)
        assert orchestrate.reduce_stage(config.compose(overrides), log) == 2
    text = log.getvalue()
    for j in p.jobs:
        assert f"{j.run_id}.zarr: status 'running' (not complete: 0 of 2000 proposed moves)" in text, text
    assert f"a sweep is running in this output_dir (pid {os.getpid()} on " in text, text
    assert "run the sweep first" not in text
    log = io.StringIO()  # no sweep holding it: the advice is to run one
    assert orchestrate.reduce_stage(config.compose(overrides), log) == 2
    assert "run the sweep first" in log.getvalue() and "a sweep is running" not in log.getvalue()


# -- smaller cases ----------------------------------------------------------------------------


def test_a_nan_in_the_terminals_csv_is_named_as_such(tmp_path, recwarn):
    from vasc_pipeline.tree import TreeError

    problem = engine.build_problem(config.compose(TINY_RUN))
    sites = engine.initial_state(problem, seed=0).position[1:17]
    csv = tmp_path / "sites.csv"
    np.savetxt(csv, sites, delimiter=",", header="x,y,z", comments="")
    lines = csv.read_text().splitlines()
    lines[4] = lines[4].split(",")[0] + ",,0.0"  # site 3: a missing y
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(TreeError, match=r"terminals\.path: site 3 of .* three finite coordinates"):
        engine.build_problem(config.compose([*TINY_RUN, f"terminals.path={csv}"]))
    assert not [w for w in recwarn if "invalid value" in str(w.message)]


def test_an_output_dir_that_is_a_file_is_refused_as_such(tmp_path):
    target = tmp_path / "results.txt"
    target.write_text("not a directory")
    code, output = finish(cli(*TINY_RUN, f"output_dir={target}"))
    assert code == 2 and f"output_dir: {str(target)!r} is a file, not a directory" in output, output
    assert target.read_text() == "not a directory"


def test_duplicate_terminal_sites_warn_and_are_refused_when_fixed(tmp_path):
    from vasc_pipeline.tree import TreeError

    problem = engine.build_problem(config.compose(TINY_RUN))
    sites = engine.initial_state(problem, seed=0).position[1:17]
    sites[9] = sites[2]
    csv = tmp_path / "sites.csv"
    np.savetxt(csv, sites, delimiter=",", header="x,y,z", comments="")
    with pytest.warns(UserWarning, match=r"terminals\.path: sites 2 and 9 of .* are the same point"):
        engine.build_problem(config.compose([*TINY_RUN, f"terminals.path={csv}"]))
    with pytest.raises(TreeError, match=r"sites 2 and 9 .* terminals\.fixed=true they would stay at one point"):
        engine.build_problem(config.compose([*TINY_RUN, f"terminals.path={csv}", "terminals.fixed=true"]))


def test_a_garbled_cost_attribute_is_a_damaged_store_for_the_sweep_and_the_reduction(tmp_path):
    from vasc_pipeline import job, reduce

    out = tmp_path / "out"
    overrides = [*TINY_RUN, f"output_dir={out}"]
    (j,) = sweep.expand(config.compose(overrides))
    assert job.run_job(j)["status"] == "complete"
    store.RunStore.open(j.store)._set_attrs(cost="garbled")
    p = planning.plan(config.compose(overrides))
    planning.inspect_stores(p)
    assert j.run_id in p.damaged and "holds no total cost" in p.damaged[j.run_id]
    assert not p.complete
    with pytest.raises(reduce.ReductionError, match=r"is damaged: its final cost attribute holds no total cost"):
        reduce.reduce(out, figures=False, exports=False)


def test_reduce_with_an_override_unlike_the_runs_is_refused(tmp_path):
    from vasc_pipeline import job

    out = tmp_path / "out"
    (j,) = sweep.expand(config.compose([*TINY_RUN, f"output_dir={out}"]))
    assert job.run_job(j)["status"] == "complete"
    code, output = finish(cli("+stage=reduce", f"output_dir={out}", "physics.gamma=3"))
    assert code == 2, output
    assert "physics.gamma=3.0 (the runs: 2.1)" in output and "Nothing was reduced" in output, output
    assert not (out / "summary.zarr").exists()


def test_a_refused_input_leaves_no_hydra_logs_behind(tmp_path):
    """Bad input found after Hydra made its run directory (the config's validation): exit 2, and
    neither the run's log directory nor an output_dir this run created is left."""
    fresh = tmp_path / "fresh"
    code, output = finish(cli(*TINY_RUN, f"output_dir={fresh}", "physics.gamma=0.01"))
    assert code == 2 and "physics.gamma" in output, output
    assert not fresh.exists(), sorted(p.name for p in fresh.rglob("*"))
    kept = tmp_path / "kept"
    (kept / "notes.txt").parent.mkdir()
    (kept / "notes.txt").write_text("mine")
    code, output = finish(cli(*TINY_RUN, f"output_dir={kept}", "physics.gamma=0.01"))
    assert code == 2, output
    assert sorted(p.name for p in kept.iterdir()) == ["notes.txt"]
