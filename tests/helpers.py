"""Shared test helpers: seeded problem builders (configs composed as users compose them)."""

from __future__ import annotations

from vasc_pipeline import config, engine


def make_problem(*overrides: str):
    """A validated Problem from Hydra-style overrides."""
    return engine.build_problem(config.compose(list(overrides)))


# -- real processes: ``python -m vasc_pipeline`` as a user runs it -----------------------------

import os  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
TIMEOUT = 240  # seconds any one subprocess may take before the test fails
# A run of a few seconds: the size the reliability tests use.
TINY_RUN = [
    "tissue=sphere",
    "n_terminals=16",
    "anneal.steps=2000",
    "anneal.trace_every=500",
    "cluster.n_workers=1",
    "cluster.dashboard_address=null",
]


def cli(*args: str, **kw) -> subprocess.Popen:
    """``python -m vasc_pipeline ARGS`` started (stdout and stderr piped, text)."""
    return subprocess.Popen(
        [sys.executable, "-m", "vasc_pipeline", *args],
        env=kw.pop("env", ENV),
        cwd=kw.pop("cwd", REPO),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


def finish(proc: subprocess.Popen) -> tuple[int, str]:
    """Wait for a :func:`cli` process: (exit status, stdout + stderr)."""
    out, err = proc.communicate(timeout=TIMEOUT)
    return proc.returncode, out + err


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now (for a scheduler started by a test)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
