"""Stage 1, the configuration: the schema and its validation, composition from ``conf/``, a run's identity.

:mod:`~vasc_pipeline.config.schema`: the run's dataclasses (defaults, types) and :func:`validate`;
:mod:`~vasc_pipeline.config.compose`: :func:`compose` from ``conf/`` as the command line does;
:mod:`~vasc_pipeline.config.pipeline`: the sweep and cluster groups;
:mod:`~vasc_pipeline.config.frozen`: a validated config is frozen (checked once, then only read);
:mod:`~vasc_pipeline.config.rules`: one rule per key a sweep can scan;
:mod:`~vasc_pipeline.config.identity`: which part of a config determines a result.
"""

from . import compose as _compose
from . import schema as _schema
from .compose import *  # noqa: F403
from .rules import MAX_STEPS, MAX_TERMINALS, SEED_ACCEPTED, seed_ok
from .schema import *  # noqa: F403
from .schema import (  # the former config module's other names, outside its __all__
    ANNEAL_INITS,
    GAMMA_RANGE,
    INLET_ASSIGNMENTS,
    MAX_CALIBRATION_SAMPLES,
    MAX_CHECKPOINT_SECONDS,
    MAX_COARSE_EXCLUSION_FACTOR,
    PAPER_STEPS_AT_1000,
    STAGES,
    TISSUE_KEYS_OF_EVERY_TISSUE,
)

__all__ = [
    *_schema.__all__,
    *_compose.__all__,
    "ANNEAL_INITS",
    "GAMMA_RANGE",
    "INLET_ASSIGNMENTS",
    "MAX_CALIBRATION_SAMPLES",
    "MAX_CHECKPOINT_SECONDS",
    "MAX_COARSE_EXCLUSION_FACTOR",
    "PAPER_STEPS_AT_1000",
    "TISSUE_KEYS_OF_EVERY_TISSUE",
    "MAX_STEPS",
    "MAX_TERMINALS",
    "SEED_ACCEPTED",
    "STAGES",
    "seed_ok",
]
