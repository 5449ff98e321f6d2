"""Stage 3, growing one tree: build the problem, anneal in blocks, finish (polish); CCO.

:mod:`~vasc_pipeline.engine.problem` builds the problem and its kernel state,
:mod:`~vasc_pipeline.engine.run` runs the anneal loop, :mod:`~vasc_pipeline.engine.polish`
the final polish and swap descent, :mod:`~vasc_pipeline.engine.cco` the constructive
baseline (with :mod:`~vasc_pipeline.engine.fermat`, its local problem). Usable without
Hydra or Dask::

    from vasc_pipeline import config, engine
    result = engine.run(config.compose(["tissue=plane2d"]), seed=0)
"""

from . import problem as _problem
from . import run as _run
from .problem import *  # noqa: F403
from .problem import scheduled_T_end, seed_state
from .run import *  # noqa: F403
from .run import accepted_moves

__all__ = [*_problem.__all__, *_run.__all__, "scheduled_T_end", "seed_state", "accepted_moves"]
