"""Every script in benchmarks/ runs to the end in its --quick mode, so none can rot unnoticed.

Correctness of the scripts' plumbing only (tiny sizes, seconds each): no timing is asserted.
"""

import importlib
import json
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import REPO

pytestmark = pytest.mark.integration  # the pipeline end to end (tests/conftest.py)

BENCHMARKS = sorted((REPO / "benchmarks").glob("*.py"))


def run_benchmark(name: str, *args: str, cwd) -> subprocess.CompletedProcess:
    """``python benchmarks/NAME ARGS`` in ``cwd``; its exit status must be 0."""
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS[0].parent / name), *args], cwd=cwd, capture_output=True, text=True, timeout=900
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done


def test_benchmarks_are_found():
    assert {"kernel_profile.py", "kernel_throughput.py"} <= {p.name for p in BENCHMARKS}


# The whole tree's two instruments grow and reduce a tree even in quick mode (20-25 s each):
# run with -m slow, as the extension's own tests cover the code they call.
SLOW_QUICK_MODES = ("extend_reduce", "extend_scaling")


@pytest.mark.parametrize(
    "script",
    [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW_QUICK_MODES else p for p in BENCHMARKS],
    ids=[p.stem for p in BENCHMARKS],
)
def test_benchmark_runs_in_quick_mode(script, tmp_path):
    lines = run_benchmark(script.name, "--quick", cwd=tmp_path).stdout.splitlines()
    assert lines, "a benchmark prints its figures"
    records = [json.loads(line) for line in lines if line.startswith("{")]
    if script.stem in ("kernel_profile", "kernel_throughput"):
        assert records and all(r["n_terminals"] == 20 for r in records)
    if script.stem == "kernel_profile":
        assert {r["phase"] for r in records} == {"start", "middle", "end"}
        assert all(r["ns_per_move"]["all"] > 0 and r["ns_per_move"]["swap_without_exclusion"] > 0 for r in records)
        for r in records:
            quantiles = list(r["exclusion_cost_over_temperature"].values())
            assert len(quantiles) == 4 and 0 <= quantiles[0] and quantiles == sorted(quantiles)
    if script.stem == "kernel_throughput":
        assert all(r["moves_per_second"] > 0 and r["coarse_exclusion_ratio"] is None for r in records)
    if script.stem == "paired_kernels":
        (row,) = records
        assert row["n_terminals"] == 20 and row["variant"] == ["supply_shell_width=0"]
        assert row["speedup"] > 0 and len(row["speedup_by_third"]) == 3
    if script.stem == "compile_profile":  # fill_uniform -> next_double -> next_u64 -> _rotl, all compiled
        total, *functions = records
        names = {r["function"] for r in functions}
        assert {"model.rng.fill_uniform", "model.rng.next_u64", "model.rng._rotl"} <= names
        assert total["compilations"] == sum(r["compilations"] for r in functions) >= 4
        outer = next(r for r in functions if r["function"] == "model.rng.fill_uniform")
        assert 0 < outer["own_s"] < outer["inclusive_s"] <= total["inclusive_s"]
    if script.stem == "budget_law":  # synthetic rows with C_s/N a function of moves / N^1.5
        absolute = [r for r in records if r.get("fit") == "supply_per_terminal"]
        assert absolute and all(r["alpha"] == pytest.approx(1.5, abs=0.05) for r in absolute)
    if script.stem == "extend_scaling":  # the N = 500 heart, 2 and 4 fine terminals per territory
        rows = [r for r in records if "n_terminals" in r]
        assert [(r["n_terminals"], r["per_territory"]) for r in rows] == [(1000, 2), (2000, 4)]
        assert all(r["cavity_segments"] == 0 and r["peak_rss_mb"] > 0 for r in rows)
    if script.stem == "fidelity":
        (row,) = records
        assert row["n_terminals"] == 40 and row["n_orders"] == len(row["orders"]) >= 2
        assert 0 <= row["exclusion_share_terminal_segments"] <= 1 and row["cost_exclusion_weighted"] > 0
        assert sum(row[f"terminal_share_{name}"] for name in ("LCA", "RCA")) == pytest.approx(1)


def benchmark_module(name: str):
    """A script of benchmarks/ imported as a module, to call its functions."""
    sys.path.insert(0, str(BENCHMARKS[0].parent))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.pop(0)


def test_time_to_quality_takes_a_label_with_override_syntax(tmp_path):
    """A variant's label names its directory; '=' and spaces in it must not reach Hydra's grammar."""
    time_to_quality = benchmark_module("time_to_quality")
    label = "mix p_swap=0.7"
    (job,) = time_to_quality.jobs_for(tmp_path, "fast", 0.3, 40, [0], 2000, ["anneal.p_swap=0.7"], label)
    assert Path(job.store).parent.parent == tmp_path / label / "x0.3"
    assert job.config["anneal"]["p_swap"] == 0.7  # not the default (0.3)


def test_time_to_quality_runs_one_tree_in_parts(tmp_path):
    done = run_benchmark(
        "time_to_quality.py",
        "--quick",
        "--anneal",
        "fast",
        "--parts",
        "2",
        "--workers",
        "2",
        "--out",
        str(tmp_path),
        cwd=tmp_path,
    )
    (row,) = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert row["anneal"] == "fast-parts2-w2" and row["steps"] == 20_000
    assert (row["parts"], row["workers"]) == (2, 2)
    assert (tmp_path / "fast-parts2-w2" / "x1" / "runs").is_dir()


def test_the_parts_cost_model_times_every_stage_of_a_phase(tmp_path):
    """One instrumented run in parts: its stages add up to its wall time, its rounds are the
    phases' two (K parts each), the model's one-worker wall time is the run's own, and a
    projection at another part_share divides the same per-move costs anew."""
    run_benchmark("parts_cost_model.py", "--quick", "--out", str(tmp_path), cwd=tmp_path)
    (row,) = [json.loads(line) for line in (tmp_path / "rows.jsonl").read_text().splitlines()]
    assert row["phases"] >= 4 and len(row["part_seconds"]) == 2 * row["phases"]  # 4, and the coarse map's end
    assert all(len(r) == 2 for r in row["part_seconds"])
    stages = row["fixed"] + row["cut"] + row["states"] + row["merge"] + row["whole"] + row["parts_serial"]
    assert stages == pytest.approx(row["wall_seconds"])
    assert row["fixed"] > 0 and row["parts_serial"] > 0 and row["whole"] > 0 and row["bytes_per_part"] > 0
    assert row["predicted_wall"]["1"] == pytest.approx(row["wall_seconds"])
    assert row["predicted_wall"]["2"] < row["predicted_wall"]["1"]
    # projected at another anneal.part_share: the same seconds per move, divided anew
    parts_cost_model = benchmark_module("parts_cost_model")
    (own,) = parts_cost_model.project([row], 1000, [16], 1e9)
    (other,) = parts_cost_model.project([row], 1000, [16], 1e9, share=0.99)
    assert (own["part_share"], other["part_share"]) == (row["part_share"], 0.99)
    assert other["whole_hours"] == pytest.approx(own["whole_hours"] * 0.01 / (1 - row["part_share"]))
    assert other["parts_hours"] == pytest.approx(own["parts_hours"] * 0.99 / row["part_share"])


def test_kernel_throughput_measures_a_coarse_exclusion_map(tmp_path):
    coarse = ["--override", "anneal.coarse_exclusion_factor=2", "--override", "anneal.coarse_exclusion_phase=0.5"]
    done = run_benchmark("kernel_throughput.py", "--quick", "--anneal", "fast", *coarse, cwd=tmp_path)
    (record,) = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert record["overrides"] == coarse[1::2]
    assert 0.3 < record["coarse_exclusion_ratio"] < 3.0


def test_paired_kernels_fails_when_the_variant_changes_a_decision(tmp_path):
    """The paired measurement is only for exact shortcuts: a variant whose states differ stops it."""
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS[0].parent / "paired_kernels.py"), "--quick", "--variant", "p_swap=0.9"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode != 0 and "differs after moves" in done.stderr
