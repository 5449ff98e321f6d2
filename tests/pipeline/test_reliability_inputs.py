"""Reliability, second pass: a run's input files are part of its identity (by content), and the
inputs a user types are accepted or refused by name. Tiny problems, mostly in this process."""

from __future__ import annotations

import io
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
        problem = engine.build_problem(config.compose([*TINY_RUN, "model=paper", f"physics.gamma={gamma}"]))
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
    from vasc_pipeline.model.tree import TreeError

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
    from vasc_pipeline.model.tree import TreeError

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
        reduce.reduce(out, exports=False)


def test_reduce_with_an_override_unlike_the_runs_is_refused(tmp_path):
    from vasc_pipeline import job

    out = tmp_path / "out"
    (j,) = sweep.expand(config.compose([*TINY_RUN, f"output_dir={out}"]))
    assert job.run_job(j)["status"] == "complete"
    code, output = finish(cli("+stage=reduce", f"output_dir={out}", "physics.gamma=3"))
    assert code == 2, output
    assert "physics.gamma=3.0 (the runs: 2.3333333333333335)" in output and "Nothing was reduced" in output, output
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


# -- 7. label maps and inlets: a batch of bad inputs, each refused by name with exit 2 ----------

LABELS = np.zeros((9, 11, 13), dtype=np.uint8)  # (z, y, x): 1 a shell of tissue, 2 a cavity inside it
_z, _y, _x = np.indices(LABELS.shape)
_r = np.sqrt((_x - 6.0) ** 2 + (_y - 5.0) ** 2 + ((_z - 4.0) * 1.3) ** 2)
LABELS[_r <= 5.0] = 1
LABELS[_r <= 2.5] = 2
IN_CAVITY = "[[0.006,0.005,0.004]]"  # voxel (6, 5, 4): the cavity's centre (origin 0, 1 mm voxels)
ABOVE = "[[0.006,0.005,0.008]]"  # voxel (6, 5, 8): outside the shell, above it


@pytest.fixture(scope="module")
def bad_inputs(tmp_path_factory):
    """The files the cases below name: label maps (NIfTI, NRRD), .npy masks, inlet files."""
    d = tmp_path_factory.mktemp("inputs")
    np.save(d / "labels.npy", LABELS)
    np.save(d / "empty.npy", np.zeros((4, 4, 4), dtype=np.uint8))
    np.save(d / "line.npy", np.ones(7, dtype=np.uint8))
    nan = np.ones((4, 4, 4))
    nan[1, 2, 3] = np.nan
    np.save(d / "nan.npy", nan)
    np.save(d / "long.npy", np.ones((3, 3, 600), dtype=np.uint8))
    np.save(d / "other_grid.npy", np.ones((5, 5, 5), dtype=np.uint8))
    (d / "text.npy").write_text("0,1,1\n1,1,0\n")
    (d / "make.py").write_text("print('a script, not a mask')\n")
    (d / "scans").mkdir()
    (d / "ostia.json").write_text('{"LCA": [0.006, 0.005, 0.008]}')
    (d / "far.json").write_text('{"LCA": [-0.03, 0.005, 0.008]}')
    (d / "cavity.json").write_text('{"LCA": [0.006, 0.005, 0.004]}')
    (d / "broken.json").write_text('{"LCA": [0.006, 0.005')
    (d / "two.json").write_text('{"LCA": [0.006, 0.005]}')
    (d / "columns.csv").write_text("a,b,c\n1,2,3\n")
    try:
        import nibabel
        import nrrd

        from vasc_pipeline.model.tissue import images
    except ImportError:  # the label-map cases skip themselves
        return d
    images.write_label_map(d / "heart.nii.gz", LABELS, 1e-3, [0.0, 0.0, 0.0])
    images.write_label_map(d / "metres.nii.gz", LABELS, 1.0, [0.0, 0.0, 0.0])  # a header in the wrong unit
    images.write_label_map(d / "tiny.nii.gz", LABELS, 1e-8, [0.0, 0.0, 0.0])
    (d / "cut.nii.gz").write_bytes((d / "heart.nii.gz").read_bytes()[:90])
    xyz = LABELS.transpose(2, 1, 0)
    nibabel.save(nibabel.Nifti1Image(xyz, np.diag([1.0, 1.0, 1.5, 1.0])), d / "aniso.nii")
    c, s = np.cos(0.3), np.sin(0.3)
    oblique = np.eye(4)
    oblique[:2, :2] = [[c, -s], [s, c]]
    nibabel.save(nibabel.Nifti1Image(xyz, oblique), d / "oblique.nii")
    nrrd.write(str(d / "heart.nrrd"), xyz, {"space directions": np.eye(3), "space": "right-anterior-superior"})
    raw = (d / "heart.nrrd").read_bytes()
    (d / "cut.nrrd").write_bytes(raw[: len(raw) // 2])
    (d / "garbled.nrrd").write_bytes(b"NRRD0004\nhello\n")
    nrrd.write(str(d / "flat.nrrd"), xyz[:, :, 0])  # 2-D, no spatial frame
    return d


NPY = ("tissue=mask", "tissue.path={d}/labels.npy", "tissue.voxel_size=0.001", "tissue.origin=[0.0,0.0,0.0]")
NII = ("tissue=mask", "tissue.path={d}/heart.nii.gz")
ROLES = ("tissue.labels.supply=[1]", "tissue.labels.exclusion=[2]")
# (overrides, the words the refusal must hold, needs nibabel/pynrrd); every case one mistake
BAD_INPUTS = [
    # label maps: scale and geometry
    ((*NII[:1], "tissue.path={d}/metres.nii.gz", f"tissue.inlets={ABOVE}"), "the header of tissue.path", True),
    ((*NII[:1], "tissue.path={d}/tiny.nii.gz", f"tissue.inlets={ABOVE}"), "gives voxels of 1e-05 mm", True),
    ((*NII, "tissue.voxel_size=0.002", f"tissue.inlets={ABOVE}"), "tissue.voxel_size=0.002 contradicts", True),
    ((*NII, "tissue.origin=[0.0,0.0,0.001]", f"tissue.inlets={ABOVE}"), "tissue.origin=[0.0, 0.0, 0.001] contra", True),
    ((*NII[:1], "tissue.path={d}/aniso.nii", f"tissue.inlets={ABOVE}"), "anisotropic voxels", True),
    ((*NII[:1], "tissue.path={d}/oblique.nii", f"tissue.inlets={ABOVE}"), "has an oblique grid", True),
    ((*NII[:1], "tissue.path={d}/cut.nii.gz", f"tissue.inlets={ABOVE}"), "is not a readable NIfTI label map", True),
    ((*NII[:1], "tissue.path={d}/cut.nrrd", f"tissue.inlets={ABOVE}"), "is not a readable NRRD label map", True),
    ((*NII[:1], "tissue.path={d}/garbled.nrrd", f"tissue.inlets={ABOVE}"), "is not a readable NRRD label map", True),
    ((*NII[:1], "tissue.path={d}/flat.nrrd", f"tissue.inlets={ABOVE}"), "has no 3-D 'space directions'", True),
    # label maps: labels by role
    ((*NII, f"tissue.inlets={ABOVE}", "tissue.labels.exclusion=[7]"), "tissue.labels.exclusion: no voxel", True),
    ((*NII, f"tissue.inlets={ABOVE}", *ROLES, "tissue.labels.open=[9]"), "tissue.labels.open: no voxel", True),
    ((*NII, f"tissue.inlets={ABOVE}", "tissue.labels.supply=[5]"), "tissue.labels.supply: no voxel", True),
    (
        (*NII, f"tissue.inlets={ABOVE}", "tissue.labels.supply=[1,5]"),
        "holds the labels [5] (its labels: [0, 1, 2])",
        True,
    ),
    (
        (*NII, f"tissue.inlets={ABOVE}", "tissue.labels.supply=[1,2]", "tissue.labels.exclusion=[2]"),
        "label 2 is both supply and exclusion",
        True,
    ),
    ((*NII, f"tissue.inlets={ABOVE}", "tissue.labels.open=[]"), "tissue.labels.open must be a non-empty list", True),
    ((*NII, f"tissue.inlets={ABOVE}", "tissue.labels.exclusion=[-1]"), "integer label values >= 0", True),
    (
        (*NII, f"tissue.inlets={ABOVE}", *ROLES, "tissue.exclusion_path={d}/labels.npy"),
        "tissue.labels.exclusion and tissue.exclusion_path both",
        True,
    ),
    ((*NPY, "tissue.inlets_path={d}/heart.nii.gz"), "tissue.inlets_path: cannot read inlets from", True),
    # masks that are no masks, or at no organ's scale
    (("tissue=mask", "tissue.path={d}/make.py", f"tissue.inlets={ABOVE}"), "is not a mask this reads; accepted", False),
    (("tissue=mask", "tissue.path={d}/scans", f"tissue.inlets={ABOVE}"), "is a directory but not a Zarr store", False),
    (("tissue=mask", "tissue.path={d}/nowhere.npy", f"tissue.inlets={ABOVE}"), "does not exist", False),
    (
        ("tissue=mask", "tissue.path={d}/empty.npy", "tissue.voxel_size=0.001", f"tissue.inlets={ABOVE}"),
        "is empty",
        False,
    ),
    (
        ("tissue=mask", "tissue.path={d}/line.npy", "tissue.voxel_size=0.001", f"tissue.inlets={ABOVE}"),
        "2-D (y, x)",
        False,
    ),
    (("tissue=mask", "tissue.path={d}/nan.npy", "tissue.voxel_size=0.001", "tissue.inlets=[[0,0,0]]"), "NaN", False),
    (
        ("tissue=mask", "tissue.path={d}/text.npy", "tissue.voxel_size=0.001", f"tissue.inlets={ABOVE}"),
        "a text file",
        False,
    ),
    ((*NPY[:2], "tissue.voxel_size=1.0", f"tissue.inlets={ABOVE}"), "tissue.voxel_size is in metres", False),
    (
        (*NPY[:2], "tissue.voxel_size=-0.001", f"tissue.inlets={ABOVE}"),
        "tissue.voxel_size must be a finite number > 0",
        False,
    ),
    (
        ("tissue=mask", "tissue.path={d}/long.npy", "tissue.voxel_size=0.005", "tissue.inlets=[[0,0,0]]"),
        "an extent of 3000 mm",
        False,
    ),
    ((*NPY, f"tissue.inlets={ABOVE}", "tissue.exclusion_path={d}/other_grid.npy"), "they must be the same grid", False),
    # inlets
    (
        (*NPY, "tissue.inlets=[[0.5,0.005,0.008]]"),
        "tissue.inlets: inlet 0 (inlet0) at [500, 5, 8] mm lies outside",
        False,
    ),
    (
        (*NPY, *ROLES, f"tissue.inlets={IN_CAVITY}"),
        "tissue.inlets: inlet 0 (inlet0) at [6, 5, 4] mm lies inside a cavity",
        False,
    ),
    ((*NPY, "tissue.inlets=[]"), "tissue.inlets must hold at least one", False),
    ((*NPY, "tissue.inlets=[[0.006,0.005]]"), "tissue.inlets[0] must be an [x, y, z] position", False),
    ((*NPY, "tissue.inlets=[[0.006,0.005,1e999]]"), "must be a finite number", False),
    ((*NPY[:4],), "tissue.inlets (a list of [x, y, z] positions in metres) or tissue.inlets_path is required", False),
    ((*NPY, "tissue.inlets_path={d}/nowhere.json"), "tissue.inlets_path: ", False),
    ((*NPY, "tissue.inlets_path={d}/broken.json"), "tissue.inlets_path: cannot read inlets from", False),
    ((*NPY, "tissue.inlets_path={d}/two.json"), "must hold one or more finite [x, y, z] positions", False),
    ((*NPY, "tissue.inlets_path={d}/columns.csv"), "tissue.inlets_path: cannot read inlets from", False),
    (
        (*NPY, "tissue.inlets_path={d}/far.json"),
        "tissue.inlets_path ('{d}/far.json'): inlet 0 (LCA) at [-30, 5, 8] mm",
        False,
    ),
    (
        (*NPY, *ROLES, "tissue.inlets_path={d}/cavity.json"),
        "): inlet 0 (LCA) at [6, 5, 4] mm lies inside a cavity",
        False,
    ),
    ((*NPY, f"tissue.inlets={ABOVE}", "tissue.inlets_path={d}/ostia.json"), "both give the inlets: set one", False),
    ((*NPY, f"tissue.inlets={ABOVE}", "tissue.inlet_share=[0.5,0.5]"), "tissue.inlet_share lists 2 fractions", False),
    # own inlets on the shaped tissues
    (
        ("tissue.inlets=[[0.0,0.0,-0.03]]",),
        "tissue.inlets: inlet 0 (inlet0) at [0, 0, -30] mm lies inside a cavity",
        False,
    ),
    (("tissue.inlets=[[0.0,0.0,0.5]]",), "tissue.inlets: inlet 0 (inlet0) at [0, 0, 500] mm lies outside", False),
    (
        ("tissue.inlets_path={d}/far.json", "tissue.ostium_height=0.01"),
        "tissue.ostium_height places the heart's",
        False,
    ),
    (("tissue=sphere", "tissue.inlets=[[0.0,0.0,0.05]]"), "lies outside the voxel grid's box", False),
    (("tissue=plane2d", "tissue.inlets=[[0.05,0.05,0.01]]"), "(the plane of a 2-D tissue)", False),
    (("tissue=box", "tissue.organ=kidney"), "tissue.organ must be one of heart, other, or null", False),
]


def refused(overrides, out: Path) -> tuple[int, str]:
    """What ``python -m vasc_pipeline OVERRIDES`` does with them, in this process: the config as Hydra
    composes it, then the command's own function (exit status, what it printed)."""
    log = io.StringIO()
    cfg = config.compose([*overrides, "n_terminals=8", "anneal.steps=2000", f"output_dir={out}"], check=False)
    return orchestrate.main(cfg, stream=log), log.getvalue()


@pytest.mark.parametrize("overrides, words, images", BAD_INPUTS, ids=[f"case{k}" for k in range(len(BAD_INPUTS))])
def test_a_bad_label_map_or_inlet_exits_2_naming_it(bad_inputs, tmp_path, overrides, words, images):
    if images:
        pytest.importorskip("nibabel")
        pytest.importorskip("nrrd")
    out = tmp_path / "results"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    code, text = refused([o.format(d=bad_inputs) for o in overrides], out)
    assert code == 2, text
    assert words.format(d=bad_inputs) in text, text
    assert "Traceback" not in text and "Existing results were left as they were" in text, text
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


def test_the_batch_is_a_batch():
    assert len(BAD_INPUTS) >= 30


@pytest.mark.parametrize(
    "overrides, words",
    [
        ((*NII, f"tissue.inlets={ABOVE}", "tissue.labels.exclusion=[7]"), "tissue.labels.exclusion: no voxel of"),
        ((*NPY, *ROLES, f"tissue.inlets={IN_CAVITY}"), "lies inside a cavity"),
    ],
)
def test_the_command_exits_2_and_leaves_the_output_dir_as_it_was(bad_inputs, tmp_path, overrides, words):
    pytest.importorskip("nibabel")
    out = tmp_path / "results"
    (j,) = plan_and_create(mask_overrides_of_labels(bad_inputs, out)).jobs  # a run store already there
    before = {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    code, output = finish(cli(*[o.format(d=bad_inputs) for o in overrides], "n_terminals=8", f"output_dir={out}"))
    assert code == 2 and words in output and "Traceback" not in output, output
    after = {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    assert after == before and Path(j.store).is_dir()


def mask_overrides_of_labels(d: Path, out: Path) -> list[str]:
    return [o.format(d=d) for o in NPY] + [f"tissue.inlets={ABOVE}", "n_terminals=8", f"output_dir={out}"]
