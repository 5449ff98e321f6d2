"""The paper's study scripts (studies/paper/): wiring only, with tiny settings (real sweeps, local cluster)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr
import zarr
from helpers import REPO

pytestmark = pytest.mark.integration  # the pipeline end to end (tests/conftest.py)

PAPER_STUDY = REPO / "studies" / "paper"
TINY = [
    "sweep.seeds=[0]",
    "anneal.steps=3000",
    "anneal.trace_every=1000",
    "cluster.n_workers=1",
    "cluster.dashboard_address=null",
]


def study(script: str, tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    env = {
        **os.environ,
        "RUNS_DIR": str(tmp_path / "runs"),
        "PAPER_DIR": str(tmp_path / "paper"),
        "PYTHON": sys.executable,
    }
    return subprocess.run(
        ["bash", str(PAPER_STUDY / script), *args],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )


def assert_collected(paper: Path, run_ids: list[str]) -> None:
    assert (paper / "comparison.csv").is_file() and (paper / "comparison_summary.csv").is_file()
    assert any((paper / "figures").glob("*.png"))
    summary = xr.open_datatree(paper / "summary.zarr", engine="zarr")
    assert sorted(str(v) for v in summary["costs"]["run_id"].values.ravel() if v) == sorted(run_ids)
    for run_id in summary["morphometry"]["best_run_id"].values.ravel():
        assert (paper / "trees" / f"{run_id}.vtp").is_file() and (paper / "trees" / f"{run_id}.csv").is_file()
    assert not any(paper.glob("runs"))  # the run stores stay in RUNS_DIR


@pytest.mark.slow  # a real sweep, ~25 s; the other study scripts' wiring runs in the default suite
def test_size_scan_runs_the_sweep_then_collects_its_small_outputs(tmp_path):
    done = study("size_scan.sh", tmp_path, "local", "sweep.n_terminals=[12,16]", *TINY)
    assert done.returncode == 0, done.stdout + done.stderr
    assert_collected(tmp_path / "paper" / "size_scan", ["heart-N12-mb641.3-s0", "heart-N16-mb641.3-s0"])
    for path in (tmp_path / "runs" / "size_scan" / "runs").glob("*.zarr"):  # the paper's model, not the default
        assert zarr.open_group(str(path), mode="r").attrs["config"]["physics"]["gamma"] == 2.1
    again = study("size_scan.sh", tmp_path, "local", "sweep.n_terminals=[12,16]", *TINY)  # rerun: resumes
    assert again.returncode == 0 and "2 already complete, 0 failed" in again.stdout + again.stderr, again.stderr


@pytest.mark.parametrize(
    "script, expected",
    [
        pytest.param(  # two sweeps: slow; its commands are checked in dry mode by tests/project/test_studies.py
            "convergence.sh",
            {
                "convergence_paper": ["plane2d-N64-mb641.3-S1000-s0", "plane2d-N64-mb641.3-S3000-s0"],
                "convergence_fast": ["plane2d-N64-mb641.3-S1000-s0", "plane2d-N64-mb641.3-S3000-s0"],
            },
            marks=pytest.mark.slow,
        ),
        ("consistency.sh", {"consistency": ["plane2d-N64-mb641.3-S1000-s0", "plane2d-N64-mb641.3-S3000-s0"]}),
        pytest.param(  # its commands are checked in dry mode by tests/project/test_studies.py
            "mb_scan.sh", {"mb_scan": ["heart-N12-mb641.3-s0", "heart-N12-mb6413-s0"]}, marks=pytest.mark.slow
        ),
    ],
)
def test_each_study_script_wires_its_sweeps(tmp_path, script, expected):
    extra = (
        ["sweep.steps=[1000,3000]"]
        if script != "mb_scan.sh"
        else ["sweep.n_terminals=[12]", "sweep.m_b=[641.3,6413.0]"]
    )
    done = study(script, tmp_path, "local", *TINY, *extra)
    assert done.returncode == 0, done.stdout + done.stderr
    for name, run_ids in expected.items():
        assert_collected(tmp_path / "paper" / name, run_ids)
    if script == "convergence.sh":  # both schedules on one plot
        assert (tmp_path / "paper" / "convergence.png").stat().st_size > 20_000


def test_cluster_argument():
    common = PAPER_STUDY / "_common.sh"
    for arg, expected in [
        ("local", "cluster=local"),
        ("slurm", "cluster=slurm"),
        ("tls://10.0.0.1:8786", "cluster=address cluster.address=tls://10.0.0.1:8786"),
    ]:
        out = subprocess.run(
            ["bash", "-c", f'source "{common}" {arg} x=1; echo "$CLUSTER_ARGS|${{EXTRA[*]}}"'],
            capture_output=True,
            text=True,
        )
        assert out.stdout.strip() == f"{expected}|x=1", out.stderr
    bad = subprocess.run(["bash", "-c", f'source "{common}" lcoal'], capture_output=True, text=True)
    assert bad.returncode == 2 and "unknown cluster 'lcoal' (accepted: local, slurm" in bad.stderr
