"""Reliability, second pass: the first run says that it compiles, and compiles once, in the
orchestrator, every kernel its jobs use (workers then load them from numba's disk cache)."""

from __future__ import annotations

import io
import json
import subprocess
import sys
import time

from helpers import ENV, REPO, TINY_RUN

from vasc_pipeline.pipeline import orchestrate, warmup

# In a fresh process: warm up for the jobs of a sweep on `anneal=fast` (the default preset: a
# calibrated T_start, adapted steps, a coarse exclusion map), then run one of those jobs, and list
# every kernel that got a signature only during the run (compiled, or loaded, by the job itself).
_SCRIPT = """
import json, sys
import vasc_pipeline
from numba.core.registry import CPUDispatcher
from vasc_pipeline import config, engine, sweep
from vasc_pipeline.pipeline import orchestrate
import importlib, pkgutil
jobs = sweep.expand(config.compose(json.loads(sys.argv[1])))
orchestrate.compile_kernels(jobs)
mods = [importlib.import_module("vasc_pipeline." + m.name) for m in pkgutil.iter_modules(vasc_pipeline.__path__)
        if m.name != "__main__"]
def signatures():
    return {f"{m.__name__}.{k}": len(v.signatures) for m in mods for k, v in vars(m).items()
            if isinstance(v, CPUDispatcher)}
before = signatures()
result = engine.run(jobs[-1].config, seed=jobs[-1].coords["seed"])
# the polish's single translations, which a short run's polish may not need
from vasc_pipeline import kernel
from vasc_pipeline.model.rng import seed_state
state = engine.state_from_tree(result.problem, result.tree, seed_state(1))
node = int(result.tree.parent.size - 1)
kernel.translate_node(result.problem.model, state, node, state.position[node] + 1e-6, 1e-300)
print(json.dumps(sorted(k for k, n in signatures().items() if n > before.get(k, 0))))
"""


def test_the_warm_up_compiles_every_kernel_the_jobs_use():
    overrides = [*TINY_RUN, "anneal=fast", "anneal.steps=3000", "+sweep=single", "sweep.seeds=[0,1]"]
    # first time on a cold cache this compiles the kernels (minutes on a busy machine): bounded, not timed
    out = subprocess.run(
        [sys.executable, "-c", _SCRIPT, json.dumps(overrides)],
        env=ENV,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.splitlines()[-1]) == [], "kernels left for the workers to compile"


def test_a_slow_compilation_is_announced_while_it_happens(monkeypatch):
    monkeypatch.setattr(warmup, "COMPILE_NOTICE_AFTER", 0.05)
    monkeypatch.setattr(warmup, "_warm_up", lambda jobs: time.sleep(1.0))
    log = io.StringIO()
    warmup.compile_kernels(["a job"], log)
    lines = log.getvalue().splitlines()
    assert lines[0].startswith("vasc_pipeline: compiling the numba kernels (first run only"), lines
    assert lines[1].startswith("vasc_pipeline: kernels compiled in "), lines


def test_loading_the_cached_kernels_says_nothing(monkeypatch):
    monkeypatch.setattr(warmup, "_warm_up", lambda jobs: None)
    log = io.StringIO()
    warmup.compile_kernels(["a job"], log)
    assert log.getvalue() == ""


def test_a_sigterm_while_compiling_ends_the_wait(monkeypatch):
    """numba compiles inside llvmlite's ctypes callbacks, which swallow the KeyboardInterrupt
    a signal handler raises there (seen in CI: the sweep ran on after SIGTERM). Run in the main
    thread, as the warm-up was, the stand-in below swallows it the same way; the signal must
    end compile_kernels before the warm-up ends."""
    import os
    import signal
    import threading

    finished = threading.Event()

    def swallowing_warm_up(jobs):
        for _ in range(40):
            try:
                time.sleep(0.05)
            except KeyboardInterrupt:
                pass
        finished.set()

    monkeypatch.setattr(warmup, "_warm_up", swallowing_warm_up)
    terminated: list[int] = []
    timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGTERM))
    with orchestrate._terminate_as_interrupt(terminated):
        timer.start()
        try:
            warmup.compile_kernels(["a job"], io.StringIO())
        except KeyboardInterrupt:
            interrupted = True
        else:
            interrupted = False
        finally:
            timer.cancel()
    assert terminated == [signal.SIGTERM]
    assert interrupted and not finished.is_set()
    finished.wait(5)  # let the stand-in end before the next test


def test_the_warm_up_leaves_the_regraft_descent_out(monkeypatch):
    """The warm-up compiles; the regraft descent compiles nothing and, on a tree of a few moves,
    would regraft nearly every terminal (it took over ten minutes at N = 6000)."""
    import importlib

    from vasc_pipeline import config, engine, sweep

    run_module = importlib.import_module("vasc_pipeline.engine.run")
    calls = []
    monkeypatch.setattr(run_module, "descend_regrafts", lambda *args, **kwargs: calls.append(1) or 0)
    (job,) = sweep.expand(config.compose([*TINY_RUN, "anneal.polish_regrafts=true", "anneal.steps=3000"]))
    warmup._warm_up_jobs([job])
    assert calls == []
    engine.run(job.run_config(), seed=0)  # the job itself does run it
    assert calls == [1]
