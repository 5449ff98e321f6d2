"""Every script under studies/ runs in its quick or dry mode, so no study can rot unnoticed.

A study's Python script answers ``--quick`` (tiny sizes or the committed rows, seconds) or
``--dry-run`` (what it would do, printed); a shell script answers ``--dry-run`` (the commands it
would run, printed, one a line; ``#`` lines say what it would do besides). Scripts named ``_*``
are sourced by the others, not run. Every printed command is checked further: the script or
module it calls exists, takes the options given, and the config overrides it passes compose, so a
renamed option or config key fails here rather than an hour into a study. No timing is asserted.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from functools import cache
from importlib.util import find_spec
from pathlib import Path

import pytest
from helpers import REPO

pytestmark = pytest.mark.integration  # the pipeline end to end (tests/conftest.py)

STUDIES = REPO / "studies"
SCRIPTS = sorted(p for p in STUDIES.rglob("*") if p.suffix in (".py", ".sh", ".sbatch") and not p.name.startswith("_"))


def mode(script: Path) -> str:
    """The script's quick or dry mode: ``--quick`` where a Python script has one, else ``--dry-run``."""
    text = script.read_text()
    for flag in ("--quick", "--dry-run") if script.suffix == ".py" else ("--dry-run",):
        if flag in text:
            return flag
    raise AssertionError(f"{script.relative_to(REPO)} has neither --quick nor --dry-run")


def run(script: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    command = [sys.executable if script.suffix == ".py" else "bash", str(script), *args]
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    return done


@cache
def options_of(script: Path) -> frozenset[str]:
    """The ``--options`` a Python script's argument parser declares."""
    return frozenset(re.findall(r"add_argument\(\s*\"(--[\w-]+)\"", script.read_text()))


@cache
def composes(overrides: tuple[str, ...]) -> bool:
    from vasc_pipeline import config

    config.compose(list(overrides))
    return True


def option_values(argv: list[str], name: str) -> list[str]:
    """The values given to ``name`` in ``argv`` (``--name a b``, repeated or not)."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] == name:
            i += 1
            while i < len(argv) and not argv[i].startswith("--"):
                out.append(argv[i])
                i += 1
        else:
            i += 1
    return out


def check_command(line: str) -> None:
    """One printed command: what it calls exists and takes its options, its overrides compose."""
    argv = shlex.split(line)
    assert argv[0] == "python", line
    if argv[1] == "-m":  # the package's command line: every further argument is a Hydra override
        assert find_spec(argv[2]) is not None, line
        if argv[2] == "vasc_pipeline":
            assert composes(tuple(argv[3:])), line
        return
    script = REPO / argv[1]
    assert script.is_file() and script.parent.name == "benchmarks", line  # an instrument
    flags = {a for a in argv[2:] if a.startswith("--")}
    assert flags <= options_of(script), f"{line}: {sorted(flags - options_of(script))} unknown"
    presets = option_values(argv, "--anneal")
    if presets:  # time_to_quality.py: the runs' config, as it composes it
        (preset,) = presets
        overrides = [f"anneal={preset}", *option_values(argv, "--override")]
        sizes = option_values(argv, "--sizes")
        overrides += [f"n_terminals={sizes[0]}"] if sizes else []
        overrides += [f"anneal.parts={k}" for k in option_values(argv, "--parts") if k != "1"]
        assert composes(tuple(overrides)), line


def test_studies_are_found():
    names = {p.relative_to(STUDIES).as_posix() for p in SCRIPTS}
    assert {"paper/size_scan.sh", "2026-12-06_model_levers/run.sh", "2026-12-02_svv/score_svv.py"} <= names


@pytest.mark.parametrize("script", SCRIPTS, ids=[p.relative_to(STUDIES).as_posix() for p in SCRIPTS])
def test_study_script_runs_in_its_quick_or_dry_mode(script, tmp_path):
    flag = mode(script)
    # shell scripts run from the repository root, as documented (a SLURM job script from its submit dir)
    done = run(script, flag, cwd=tmp_path if script.suffix == ".py" else REPO)
    assert done.stdout.strip(), "a study script prints what it did or would do"
    if script.suffix != ".py":
        commands = [line for line in done.stdout.splitlines() if line.strip() and not line.startswith("#")]
        assert commands, "a dry run prints the commands"
        for line in commands:
            check_command(line)


@pytest.mark.parametrize("script", SCRIPTS, ids=[p.relative_to(STUDIES).as_posix() for p in SCRIPTS])
def test_study_script_imports_the_installed_package(script):
    text = script.read_text()
    assert "sys.path" not in text and "PYTHONPATH" not in text
    if script.suffix == ".py":  # siblings are not imported either: a study script stands alone
        siblings = {p.stem for p in script.parent.glob("*.py")} - {script.stem}
        imported = set(re.findall(r"^\s*(?:from|import) (\w+)", text, flags=re.M))
        assert not imported & siblings


def test_every_study_has_a_readme_and_a_line_in_the_index():
    index = (STUDIES / "README.md").read_text()
    homes = [p for p in STUDIES.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))]
    assert len(homes) >= 8
    for home in homes:
        assert (home / "README.md").is_file(), home.name
        assert f"({home.name}/" in index, f"{home.name} is not in studies/README.md"


def test_a_dry_run_passes_the_cluster_and_overrides_through(tmp_path):
    """The paper's scripts: cluster and overrides reach the command; the SLURM job script runs the study."""
    done = run(STUDIES / "paper" / "mb_scan.sh", "--dry-run", "slurm", "sweep.seeds=[0,1]", cwd=tmp_path)
    (command, collect) = done.stdout.splitlines()
    assert "cluster=slurm" in command and "sweep.seeds=\\[0\\,1\\]" in command
    assert collect == "# collect results/studies/mb_scan into results/paper/mb_scan"
    sbatch = subprocess.run(
        ["bash", str(STUDIES / "paper" / "slurm" / "study.sbatch"), "--dry-run"],
        cwd=REPO,
        env={"PATH": "/usr/bin:/bin", "STUDY": "consistency", "PARTITION": "long"},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert sbatch.returncode == 0, sbatch.stderr
    assert "sweep.name=consistency" in sbatch.stdout and "cluster.slurm.queue=long" in sbatch.stdout
