"""Stage 3, growing one tree: build the problem, anneal in blocks, finish (polish); CCO.

:mod:`~vasc_pipeline.engine.problem` builds the problem and its kernel state,
:mod:`~vasc_pipeline.engine.run` runs the anneal loop, :mod:`~vasc_pipeline.engine.polish`
the final polish and swap descent, :mod:`~vasc_pipeline.engine.cco` the constructive
baseline (its numba kernel in :mod:`~vasc_pipeline.kernel.growth`). Usable without
Hydra or Dask::

    from vasc_pipeline import config, engine
    result = engine.run(config.compose(["tissue=plane2d"]), seed=0)
"""

from .problem import (
    CHECKPOINT_FIELDS,
    Problem,
    build_problem,
    calibrate_schedule,
    initial_state,
    model_at,
    node_radii,
    restore_state,
    running_costs,
    scheduled_T_end,
    seed_state,
    state_arrays,
    state_from_tree,
    supply_dtype,
    tree_of,
    tree_statistics,
)
from .run import (
    BlockHook,
    RunResult,
    Trace,
    TraceRecord,
    accepted_moves,
    anneal_blocks,
    finish,
    run,
    run_block,
    run_phase,
    trace_record,
)

__all__ = [
    "Problem",
    "build_problem",
    "initial_state",
    "state_from_tree",
    "calibrate_schedule",
    "model_at",
    "running_costs",
    "tree_of",
    "tree_statistics",
    "state_arrays",
    "restore_state",
    "node_radii",
    "supply_dtype",
    "CHECKPOINT_FIELDS",
    "RunResult",
    "BlockHook",
    "Trace",
    "TraceRecord",
    "trace_record",
    "run_block",
    "run_phase",
    "anneal_blocks",
    "finish",
    "run",
    "scheduled_T_end",
    "seed_state",
    "accepted_moves",
]
