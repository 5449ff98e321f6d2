"""Compile the numba kernels once, in the orchestrator, before any worker needs them.

:func:`compile_kernels` runs a few steps of each distinct kind of job in the sweep (or a
generic tiny problem), so that workers load the kernels from numba's disk cache instead of
racing to compile the same code; it says so when that takes a while.
"""

from __future__ import annotations

import contextlib
import logging
import time
from dataclasses import replace
from typing import Any, TextIO

from .. import config as _config
from .sweep import Job

__all__ = ["compile_kernels", "COMPILE_NOTICE_AFTER"]

COMPILE_NOTICE_AFTER = 2.0  # seconds: loading the cached kernels takes about 1 s, compiling them minutes


def compile_kernels(jobs: list[Job] | None = None, stream: TextIO | None = None) -> None:
    """Compile the kernels once here (or load numba's disk cache), before workers need them.

    With ``jobs``, one job's own config per distinct supply dtype runs for a few steps: the
    kernels its schedule calls (the calibration of T_start, adapted steps, packing, CCO when the
    method or init uses it) and their argument types are those of the sweep, so workers compile
    nothing (a generic tiny problem left ``anneal=fast``'s calibration and moves to the workers,
    which then showed 0 steps/s while compiling). Without ``jobs``: a generic tiny problem.
    When that takes longer than :data:`COMPILE_NOTICE_AFTER`, ``stream`` is told what happens.

    The compilation runs in a helper thread while this one waits: numba compiles inside
    llvmlite's ctypes callbacks, which swallow an exception raised there, so a Ctrl-C or SIGTERM
    delivered into them was lost and the sweep ran on. Waiting here, the signal interrupts at
    once (the helper is a daemon thread: it ends with the process).
    """
    import threading

    failure: list[BaseException] = []

    def compile_all() -> None:
        try:
            if jobs:
                _warm_up(jobs)
            else:
                _warm_up_generic()
        except BaseException as exc:  # re-raised in the caller's thread
            failure.append(exc)

    started = time.monotonic()
    worker = threading.Thread(target=compile_all, name="vasc-compile", daemon=True)
    worker.start()
    worker.join(COMPILE_NOTICE_AFTER)
    slow = worker.is_alive()
    if slow and stream is not None:
        stream.write(
            "vasc_pipeline: compiling the numba kernels (first run only, about 1-2 min; cached for later runs)...\n"
        )
        stream.flush()
    while worker.is_alive():
        worker.join(0.2)
    if failure:
        raise failure[0]
    if slow and stream is not None:
        stream.write(f"vasc_pipeline: kernels compiled in {time.monotonic() - started:.0f} s\n")
        stream.flush()


@contextlib.contextmanager
def _tissue_reports_muted():
    """Drop the tissue builders' INFO reports (the heart's achieved mass) for a while: the
    warm-up builds the sweep's tissues again, which the plan has reported already."""
    from ..model.tissue import heart

    def drop(record: logging.LogRecord) -> bool:
        return record.levelno > logging.INFO

    heart.log.addFilter(drop)
    try:
        yield
    finally:
        heart.log.removeFilter(drop)


def _warm_up(jobs: list[Job]) -> None:
    """A few steps of each distinct kind of job (see :func:`compile_kernels`)."""
    with _tissue_reports_muted():
        _warm_up_jobs(jobs)


def _warm_up_jobs(jobs: list[Job]) -> None:
    from .. import engine

    seen = set()
    for j in jobs:
        cfg = j.run_config()
        kind = (engine.supply_dtype(cfg.n_terminals), cfg.method.name, cfg.anneal.init)
        if kind in seen:
            continue
        seen.add(kind)
        try:
            if cfg.method.name == "cco":
                from ..engine.cco import grow

                grow(engine.build_problem(cfg), 0)
                continue
            steps = _config.packing_steps(cfg) + 256  # every phase of the schedule, a few moves each
            # The regraft descent is plain Python (nothing to compile), and on a tree of a few
            # moves it would regraft nearly every terminal: over ten minutes at N = 6000.
            few_moves = replace(cfg, anneal=replace(cfg.anneal, steps=steps, trace_every=64, polish_regrafts=False))
            result = engine.run(few_moves, seed=int(cfg.seed))
            _warm_up_polish(result)
        except Exception:  # the job itself fails the same way, and its run reports it
            continue


def _warm_up_polish(result: Any) -> None:
    """The polish's single translations (``kernel.translate_node``): a run of a few moves is
    usually polished in one piece and never calls them, a real run often does. And the regraft
    descent's calls (``legal_position``, ``segment_exclusion``), left out of the warm-up's run."""
    from .. import engine, kernel
    from ..kernel.exclusion import segment_exclusion
    from ..kernel.moves import legal_position
    from ..model.rng import seed_state

    problem = result.problem
    state = engine.state_from_tree(problem, result.tree, seed_state(0))
    node = problem.model.n_inlets  # any node that may move; moved onto itself
    kernel.translate_node(problem.model, state, node, state.position[node].copy(), 1e-300)
    segment_exclusion(problem.model, state.position[node], state.position[state.parent[node]])
    legal_position(problem.model, False, state.position[node].copy())


def _warm_up_generic() -> None:
    from .. import engine

    cfg = _config.RunConfig(
        n_terminals=4,
        tissue=_config.TissueConfig(name="sphere", exclusion_voxel_size=None),
        anneal=_config.AnnealConfig(steps=16, trace_every=8),
    )
    engine.run(cfg, seed=0)
    from ..engine.cco import grow  # the CCO growth kernel too (method=cco, anneal.init=cco)

    grow(engine.build_problem(replace(cfg, method=_config.MethodConfig(name="cco"))), 0)
