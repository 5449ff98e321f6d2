"""Stage 1, the configuration: the schema and its validation, composition from ``conf/``, a run's identity.

:mod:`~vasc_pipeline.config.schema`: the run's dataclasses (defaults, types);
:mod:`~vasc_pipeline.config.checks`: :func:`validate`, every range checked before a job starts;
:mod:`~vasc_pipeline.config.keys`: the key table (unit, accepted range, meaning of every key), which drives
:func:`validate`, ``--help`` and the page's key tables (:mod:`~vasc_pipeline.config.keypage`);
:mod:`~vasc_pipeline.config.compose`: :func:`compose` from ``conf/`` as the command line does;
:mod:`~vasc_pipeline.config.pipeline`: the sweep and cluster groups;
:mod:`~vasc_pipeline.config.frozen`: a validated config is frozen (checked once, then only read);
:mod:`~vasc_pipeline.config.rules`: one rule per key a sweep can scan (the key table's for those keys);
:mod:`~vasc_pipeline.config.identity`: which part of a config determines a result;
:mod:`~vasc_pipeline.config.schedule`: a run's phases in steps (:class:`Schedule`).
"""

from .checks import validate
from .compose import (
    SINGLE_SWEEP,
    compose,
    hydra_error_message,
    integral_counts,
    register_schema,
    with_sweep_group,
)
from .rules import MAX_STEPS, MAX_TERMINALS, SEED_ACCEPTED, seed_ok
from .schedule import Schedule, packing_steps, scheduled_steps
from .schema import (  # the former config module's other names, outside its __all__
    ANNEAL_INITS,
    CONFIG_DIR,
    EXTEND_RUNS,
    EXTEND_ZERODS,
    GAMMA_RANGE,
    HEART_EXCLUSION_VOXEL_SIZE,
    INLET_ASSIGNMENTS,
    KEYS_ADDED_LATER,
    MAX_CALIBRATION_SAMPLES,
    MAX_CHECKPOINT_SECONDS,
    MAX_COARSE_EXCLUSION_FACTOR,
    METHODS,
    MODELS,
    ORGANS,
    PAPER_STEPS_AT_1000,
    STAGES,
    SWEPT_KEYS,
    TISSUE_KEYS_OF_EVERY_TISSUE,
    AnnealConfig,
    CheckpointConfig,
    ClusterConfig,
    ConfigError,
    ExtendConfig,
    LabelsConfig,
    MethodConfig,
    ModelConfig,
    PhysicsConfig,
    Rule,
    RunConfig,
    SlurmConfig,
    SweepConfig,
    TerminalsConfig,
    TissueConfig,
    TLSConfig,
    from_stored,
    organ_of,
    sweep_axis,
    to_run_config,
)

__all__ = [
    "EXTEND_RUNS",
    "EXTEND_ZERODS",
    "ConfigError",
    "KEYS_ADDED_LATER",
    "TissueConfig",
    "LabelsConfig",
    "PhysicsConfig",
    "AnnealConfig",
    "TerminalsConfig",
    "CheckpointConfig",
    "MethodConfig",
    "ExtendConfig",
    "METHODS",
    "ModelConfig",
    "MODELS",
    "RunConfig",
    "SweepConfig",
    "ClusterConfig",
    "TLSConfig",
    "SlurmConfig",
    "to_run_config",
    "from_stored",
    "validate",
    "Rule",
    "SWEPT_KEYS",
    "sweep_axis",
    "HEART_EXCLUSION_VOXEL_SIZE",
    "ORGANS",
    "organ_of",
    "scheduled_steps",
    "packing_steps",
    "Schedule",
    "CONFIG_DIR",
    "compose",
    "integral_counts",
    "register_schema",
    "with_sweep_group",
    "hydra_error_message",
    "SINGLE_SWEEP",
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
