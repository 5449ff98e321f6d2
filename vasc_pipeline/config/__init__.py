"""Stage 1, the configuration: the schema and its validation, composition from ``conf/``, a run's identity.

:mod:`~vasc_pipeline.config.schema`: the run's dataclasses (defaults, types), :func:`validate`
and :func:`compose`; :mod:`~vasc_pipeline.config.pipeline`: the sweep and cluster groups;
:mod:`~vasc_pipeline.config.identity`: which part of a config determines a result.
"""

from . import schema as _schema
from .schema import *  # noqa: F403
from .schema import (  # names callers used from the former config module, outside its __all__
    MAX_STEPS,
    SEED_ACCEPTED,
    SINGLE_SWEEP,
    STAGES,
    hydra_error_message,
    register_schema,
    seed_ok,
    with_sweep_group,
)

__all__ = [
    *_schema.__all__,
    "MAX_STEPS",
    "SEED_ACCEPTED",
    "SINGLE_SWEEP",
    "STAGES",
    "hydra_error_message",
    "register_schema",
    "seed_ok",
    "with_sweep_group",
]
