"""Shared test helpers: seeded problem builders (configs composed as users compose them).

Imported as ``from helpers import ...`` by the tests of every folder under tests/ (``pythonpath``
in pyproject.toml). Paths in the repository are taken from :data:`REPO`, never from a test
file's own ``__file__``, whose depth depends on its folder.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from vasc_pipeline import config, costs, engine, job, kernel, sweep
from vasc_pipeline.model.tree import check_tree


def make_problem(*overrides: str):
    """A validated Problem from Hydra-style overrides, on the paper's model unless one of them
    names a model: the engine's tests hold values recorded on it (the default model's own tests
    say ``model=physiological``)."""
    if not any(o.startswith("model=") for o in overrides):
        overrides = ("model=paper", *overrides)
    return engine.build_problem(config.compose(list(overrides)))


def random_topology(n, rng):
    """Parent array of a random rooted binary tree (inlet 0, terminals 1..n, bifurcations n+1..2n-1),
    built by joining random pairs of subtrees with ``rng`` (a NumPy Generator), independently of
    the package's own tree builders."""
    parent = np.full(2 * n, -1, dtype=np.int64)
    roots = list(range(1, n + 1))
    nxt = n + 1
    while len(roots) > 1:
        a = roots.pop(rng.integers(len(roots)))
        b = roots.pop(rng.integers(len(roots)))
        parent[a] = parent[b] = nxt
        roots.append(nxt)
        nxt += 1
    parent[roots[0]] = 0
    return parent


# -- tree topology: a plain swap to compare the kernel's with ------------------------------


def ancestors(parent, node):
    """The nodes above ``node``, nearest first."""
    out = []
    node = parent[node]
    while node >= 0:
        out.append(node)
        node = parent[node]
    return out


def reference_swap(parent, a, b):
    """Plain-Python swap on a parent array; None where the swap is illegal."""
    if a == b or parent[a] == parent[b] or b in ancestors(parent, a) or a in ancestors(parent, b):
        return None
    out = parent.copy()
    out[a], out[b] = parent[b], parent[a]
    return out


# -- kernel states: running sums and move counters ------------------------------------------


def assert_running_equals_full(problem, state):
    tree = engine.tree_of(problem, state)
    check_tree(tree, problem.tissue)
    running = engine.running_costs(problem, state)
    full = costs.full_costs(tree, problem.tissue, problem.physics, problem.terms)
    if state.counters[kernel.COUNTER_STEP] < problem.coarse_steps:
        # Until the switch the exclusion term is summed on the coarse map (anneal.coarse_exclusion_*,
        # `fast`'s): its reference is every segment summed afresh on that map.
        fresh = engine.restore_state(problem, engine.state_arrays(state))
        kernel.recompute_exclusion(problem.coarse_model, fresh)
        full["exclusion"] = engine.running_costs(problem, fresh)["exclusion"]
        full["total"] = costs.total_cost(full, problem.physics)
    assert running["supply"] == full["supply"]  # integer-valued: exact
    for term in ("volume", "power", "exclusion", "pressure", "total"):
        assert running[term] == pytest.approx(full[term], rel=1e-9, abs=1e-300), term
    return running


def assert_block_splits_bit_identical(problem, seed: int, blocks) -> None:
    """Run ``problem`` from the initial tree of ``seed`` in one block of ``sum(blocks)``
    proposals and again block by block, the state round-tripped through its checkpoint
    arrays after each block (as a resume would): every checkpoint field must be the same."""
    one = engine.initial_state(problem, seed)
    engine.run_block(problem, one, sum(blocks))
    split = engine.initial_state(problem, seed)
    for n in blocks:
        engine.run_block(problem, split, n)
        split = engine.restore_state(problem, engine.state_arrays(split))
    for name in engine.CHECKPOINT_FIELDS:
        np.testing.assert_array_equal(getattr(one, name), getattr(split, name), err_msg=name)


def assert_moves_of_every_kind_accepted_and_rejected(state, terminals_move=True):
    c = state.counters
    pairs = [
        (kernel.COUNTER_BIFURCATION_PROPOSED, kernel.COUNTER_BIFURCATION_ACCEPTED),
        (kernel.COUNTER_SWAP_PROPOSED, kernel.COUNTER_SWAP_ACCEPTED),
    ]
    if terminals_move:
        pairs.append((kernel.COUNTER_TERMINAL_PROPOSED, kernel.COUNTER_TERMINAL_ACCEPTED))
    for proposed, accepted in pairs:
        assert 0 < c[accepted] < c[proposed]


# -- real processes: ``python -m vasc_pipeline`` as a user runs it -----------------------------

REPO = Path(__file__).resolve().parents[1]  # this file is tests/helpers.py
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
TIMEOUT = 240  # seconds any one subprocess may take before the test fails
# `anneal=fast` as it was before its cold part (2026-11-26): one exponential over all of its
# moves, the supply schedule over the first half of them, full-width terminal moves over a quarter.
FAST_ONE_EXPONENTIAL = (
    "anneal.cold_from=null",
    "anneal.cold_share=null",
    "anneal.supply_phase=0.5",
    "anneal.full_width_phase=0.25",
)
# `fast` as of 2026-12-01, spelled out on the frozen `fast_v1`: for tests that need "a good schedule
# with every feature on" (coarse map, cold part, adapted steps, neighbour swaps, supply schedule),
# not the preset itself, so that a retune of `fast` leaves them alone. Overrides after it win.
FAST_2026_12 = (
    "anneal=fast_v1",
    "anneal.acceptance_target=0.1",
    "anneal.coarse_exclusion_factor=2",
    "anneal.coarse_exclusion_phase=0.4",
    "anneal.cold_from=0.5",
    "anneal.cold_share=0.2",
    "anneal.full_width_phase=0.4",
    "anneal.neighbour_cell=2.0",
    "anneal.p_swap=0.3",
    "anneal.steps_at_1000=6.25e7",
    "anneal.steps_exponent=1.7",
    "anneal.supply_phase=0.8",
)


# `fast` sums the exclusion term on a coarse map over its first 40 % of moves: tests that call
# the kernel on a state directly with ``problem.model`` need the true map from the start.
TRUE_EXCLUSION_MAP = ("anneal.coarse_exclusion_factor=null", "anneal.coarse_exclusion_phase=null")
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


def assert_killed_job_resumes_bit_identically(overrides: list[str], kill_before: int) -> None:
    """Run the one job of ``overrides`` in a child process, SIGKILL it as soon as its store
    records a checkpoint (which must come before step ``kill_before``), resume it in this
    process, and check the final tree against the same run made in one go."""
    (j,) = sweep.expand(config.compose(overrides))
    script = (
        "import sys, json; from vasc_pipeline import job, sweep, config; "
        "(j,) = sweep.expand(config.compose(json.loads(sys.argv[1]))); job.run_job(j)"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", script, json.dumps(overrides)],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    store_attrs = Path(j.store) / "zarr.json"
    killed_at = 0
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                killed_at = json.loads(store_attrs.read_text())["attributes"].get("steps_done", 0)
            except (OSError, ValueError, KeyError):
                killed_at = 0
            if killed_at > 0:
                break
            time.sleep(0.005)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert 0 < killed_at < kill_before, f"no checkpoint before step {kill_before} ahead of the kill"
    summary = job.run_job(j)
    assert summary["resumed_from"] is not None and 0 < summary["resumed_from"] < kill_before
    reference = engine.run(j.config, seed=0)
    tree = job.read_final_tree(j.store)
    np.testing.assert_array_equal(tree["parent"], reference.tree.parent)
    np.testing.assert_array_equal(tree["position"], reference.tree.position)


def store_attrs(path: Path) -> dict:
    """Root attributes read straight from zarr.json (an atomic file: safe while a job writes)."""
    return json.loads((path / "zarr.json").read_text())["attributes"]


def png_is_a_real_figure(path: Path, min_shape: tuple[int, int] = (400, 600)) -> None:
    """A PNG of at least ``min_shape`` pixels with ink, colours and grey levels: not blank."""
    import matplotlib.image as mpimg

    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", path
    assert path.stat().st_size > 20_000, path
    img = mpimg.imread(path)[..., :3]
    assert img.shape[0] > min_shape[0] and img.shape[1] > min_shape[1], (path, img.shape)
    ink = (img < 0.9).any(axis=-1).mean()  # fraction of pixels that are not (near) white
    assert 0.01 < ink < 0.9, (path, ink)
    sample = (img[::3, ::3] * 255).astype(np.uint8).reshape(-1, 3)
    assert len(np.unique(sample, axis=0)) > 20, path  # colours and grey levels, not one tone
