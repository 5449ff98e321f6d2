"""Where the first run's compile time goes: numba's compile events, per jitted function.

    python benchmarks/compile_profile.py                   # the default job's warm-up
    python benchmarks/compile_profile.py tissue=sphere     # any overrides of the run's config
    python benchmarks/compile_profile.py --quick           # one small kernel (seconds)

Runs the orchestrator's warm-up (the job's own schedule, a few moves of each phase) with an
empty numba cache in a temporary directory, so everything is compiled, and records numba's
``numba:compile`` events. One JSON line per function, largest own time first, after a first
line for the warm-up in all: how often it was compiled, its inclusive seconds (with the
functions it compiled on the way), its own seconds (without them) and, for a function
compiled more than once, the argument types of each specialisation. Use it before and after
a change to the kernels' compilation; the figures depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable


def profile(action: Callable[[], object]) -> list[dict]:
    """Run ``action`` recording numba's compile events; one row per jitted function compiled."""
    from numba.core import event

    with event.install_recorder("numba:compile") as recorder:
        started = time.perf_counter()
        action()
        total = time.perf_counter() - started
    inclusive: dict[str, float] = defaultdict(float)
    own: dict[str, float] = defaultdict(float)
    signatures: dict[str, list[str]] = defaultdict(list)
    stack: list[list] = []  # [name, start, seconds of the compilations nested in it]
    for stamp, ev in recorder.buffer:
        name = _name(ev.data)
        if ev.is_start:
            stack.append([name, stamp, 0.0])
            signatures[name].append(", ".join(map(str, ev.data.get("args", ()))))
            continue
        _, start, nested = stack.pop()
        seconds = stamp - start
        if all(entry[0] != name for entry in stack):  # a recursive compilation counts once
            inclusive[name] += seconds
        own[name] += seconds - nested
        if stack:
            stack[-1][2] += seconds
    rows = [
        {
            "function": name,
            "compilations": len(signatures[name]),
            "inclusive_s": round(inclusive[name], 2),
            "own_s": round(own[name], 2),
            **({"signatures": signatures[name]} if len(signatures[name]) > 1 else {}),
        }
        for name in own
    ]
    rows.sort(key=lambda r: -r["own_s"])
    compilations = sum(r["compilations"] for r in rows)
    return [{"function": "(all)", "compilations": compilations, "inclusive_s": round(total, 2)}, *rows]


def _name(data: dict) -> str:
    dispatcher = data.get("dispatcher")
    py_func = getattr(dispatcher, "py_func", None)
    if py_func is None:
        return str(dispatcher)
    return f"{py_func.__module__.removeprefix('vasc_pipeline.')}.{py_func.__qualname__}"


def warm_up(overrides: list[str]) -> Callable[[], None]:
    """The orchestrator's warm-up for the jobs of ``overrides``."""
    from vasc_pipeline import config, sweep
    from vasc_pipeline.pipeline.warmup import compile_kernels

    jobs = sweep.expand(config.compose(overrides))
    return lambda: compile_kernels(jobs)


def small_kernel() -> None:
    """The generator's uniform fill: three nested jitted functions, a second or two."""
    import numpy as np

    from vasc_pipeline.model import rng

    rng.fill_uniform(rng.seed_state(0), np.empty(4))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("overrides", nargs="*", help="config overrides of the profiled job (Hydra syntax)")
    parser.add_argument("--top", type=int, default=25, help="functions to print (default 25)")
    parser.add_argument("--quick", action="store_true", help="one small kernel: checks the script runs")
    args = parser.parse_args(argv)
    if "NUMBA_CACHE_DIR" not in os.environ:
        # numba reads the variable when it is imported: start again in a child with an empty cache.
        with tempfile.TemporaryDirectory() as cache:
            env = dict(os.environ, NUMBA_CACHE_DIR=cache)
            command = [sys.executable, __file__, *(sys.argv[1:] if argv is None else argv)]
            return subprocess.call(command, env=env)
    rows = profile(small_kernel if args.quick else warm_up(args.overrides))
    for row in rows[: args.top + 1]:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
