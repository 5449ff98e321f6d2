"""Validation of a run's config: every range the model needs, checked before any job starts.

:func:`validate` raises :class:`~vasc_pipeline.config.errors.ConfigError` naming the field, the value
given and what is accepted, and returns the config frozen (:mod:`vasc_pipeline.config.frozen`).
"""

from __future__ import annotations

import inspect
import json
import math
from dataclasses import asdict, is_dataclass
from typing import Any

from .errors import ConfigError
from .frozen import _freeze, is_frozen, thawed
from .rules import MAX_STEPS, MAX_TERMINALS, SEED_ACCEPTED, SWEPT_KEYS, seed_ok, sweep_axis
from .schedule import packing_steps, scheduled_steps
from .schema import (
    ANNEAL_INITS,
    EXTEND_RUNS,
    EXTEND_ZERODS,
    GAMMA_RANGE,
    INLET_ASSIGNMENTS,
    MAX_CALIBRATION_SAMPLES,
    MAX_CHECKPOINT_SECONDS,
    MAX_COARSE_EXCLUSION_FACTOR,
    METHODS,
    MODELS,
    ORGANS,
    STAGES,
    TISSUE_KEYS_OF_EVERY_TISSUE,
    ExtendConfig,
    LabelsConfig,
    RunConfig,
    TissueConfig,
)

__all__ = ["share_set_by_model", "validate"]


def _positive(name: str, value: float) -> None:
    if value is None or not (value > 0 and math.isfinite(value)):
        raise ConfigError(f"{name} must be a finite number > 0, got {value}")


def _check_finite(node: Any, name: str) -> None:
    """Every float anywhere in the config must be finite (NaN and inf pass every range check)."""
    if hasattr(node, "__dataclass_fields__"):
        for key in node.__dataclass_fields__:
            _check_finite(getattr(node, key), f"{name}.{key}" if name else key)
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            _check_finite(value, f"{name}[{i}]")
    elif isinstance(node, float) and not math.isfinite(node):
        raise ConfigError(f"{name} must be a finite number, got {node}")


def share_set_by_model(cfg) -> str:
    """The words that say where a split the user did not set came from (``model=physiological``
    sets the heart's for the anneal), and how to free it; empty otherwise."""
    if cfg.model.name != "physiological" or cfg.tissue.name != "heart":
        return ""
    return (
        " (model=physiological sets the heart's split for the anneal; "
        "tissue.inlet_share=null tissue.inlet_share_tolerance=null frees it)"
    )


def validate(cfg: RunConfig) -> RunConfig:
    """Check every range the model needs; raise :class:`ConfigError` naming the field.

    Returns a validated copy, frozen (:mod:`vasc_pipeline.config.frozen`): the engine and the
    planner take it as it is. A frozen config was validated already and is returned unchanged.
    """
    from ..model.tissue import TISSUES

    if is_frozen(cfg):
        return cfg
    cfg = thawed(cfg)
    _check_finite(cfg, "")
    if not str(cfg.output_dir).strip():
        raise ConfigError("output_dir must name a directory, got an empty string; give one with output_dir=...")
    # as their kind: a script's n_terminals=5.0 is run as 5
    cfg.seed = SWEPT_KEYS["seeds"].check("seed", cfg.seed)
    cfg.n_terminals = SWEPT_KEYS["n_terminals"].check("n_terminals", cfg.n_terminals)
    if cfg.anneal.steps is not None:
        cfg.anneal.steps = SWEPT_KEYS["steps"].check("anneal.steps", cfg.anneal.steps)
    cfg.physics.m_b = SWEPT_KEYS["m_b"].check("physics.m_b", cfg.physics.m_b)
    if cfg.sweep is not None:
        for axis in SWEPT_KEYS:
            sweep_axis(axis, getattr(cfg.sweep, axis), None)
    if cfg.tissue.inlets is not None:
        if not cfg.tissue.inlets:
            raise ConfigError("tissue.inlets must hold at least one [x, y, z] position in metres (or be null), got []")
        for k, p in enumerate(cfg.tissue.inlets):
            if not (
                isinstance(p, (list, tuple))
                and len(p) == 3
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p)
            ):
                raise ConfigError(f"tissue.inlets[{k}] must be an [x, y, z] position in metres, got {p!r}")
        cfg.tissue.inlets = [[float(v) for v in p] for p in cfg.tissue.inlets]
    phys = cfg.physics
    if not phys.pressure_inlet > phys.pressure_terminal >= 0.0:
        raise ConfigError(
            "physics.pressure_inlet must exceed physics.pressure_terminal, which must be >= 0 (Pa; blood "
            f"flows from the inlets to the terminals), got {phys.pressure_inlet:g} and {phys.pressure_terminal:g}"
        )
    if cfg.model.name not in MODELS:
        raise ConfigError(f"model.name: unknown model {cfg.model.name!r}; accepted: {', '.join(MODELS)} (model=...)")
    if cfg.tissue.name not in TISSUES:
        raise ConfigError(f"tissue.name: unknown tissue {cfg.tissue.name!r}; accepted: {', '.join(sorted(TISSUES))}")
    if cfg.tissue.organ is not None and cfg.tissue.organ not in ORGANS:
        raise ConfigError(
            f"tissue.organ must be one of {', '.join(ORGANS)}, or null (decided by the tissue), "
            f"got {cfg.tissue.organ!r}"
        )
    if cfg.tissue.inlet_assignment not in INLET_ASSIGNMENTS:
        raise ConfigError(
            f"tissue.inlet_assignment must be one of {', '.join(INLET_ASSIGNMENTS)}, "
            f"got {cfg.tissue.inlet_assignment!r}"
        )
    share = cfg.tissue.inlet_share
    if share is not None:
        if not share or any(not (s > 0) for s in share) or abs(sum(share) - 1.0) > 1e-6:
            raise ConfigError(
                f"tissue.inlet_share must list one fraction > 0 per inlet, summing to 1 (heart: [LCA, RCA], "
                f"e.g. [0.62, 0.38]), got {list(share)}"
            )
        if cfg.method.name == "cco" or cfg.anneal.init == "cco":
            raise ConfigError(
                "tissue.inlet_share fixes the terminals of every inlet, which the CCO growth (method=cco, "
                "anneal.init=cco) assigns by connection: leave it unset (null) there" + share_set_by_model(cfg)
            )
    tolerance = cfg.tissue.inlet_share_tolerance
    if tolerance is not None:
        if share is None:
            raise ConfigError(
                "tissue.inlet_share_tolerance is a band around tissue.inlet_share: set the share too (heart: "
                f"tissue.inlet_share=[0.62,0.38]), or leave the tolerance null; got {tolerance}"
            )
        if not 0.0 < tolerance < 1.0:
            raise ConfigError(f"tissue.inlet_share_tolerance must lie in (0, 1) (a share's +-), got {tolerance}")
    reach = cfg.tissue.bifurcation_reach
    if reach is not None:
        if not (reach >= 0 and math.isfinite(reach)):
            raise ConfigError(f"tissue.bifurcation_reach must be a length >= 0 in metres, or null, got {reach}")
        if cfg.method.name == "cco":
            raise ConfigError(
                "tissue.bifurcation_reach confines the anneal's bifurcations; the CCO growth (method=cco) "
                "places them at their optimum: leave it unset (null) there"
            )
    _check_tissue_keys(cfg.tissue)
    if cfg.tissue.ostium_height is not None and (cfg.tissue.inlets is not None or cfg.tissue.inlets_path):
        given = "tissue.inlets" if cfg.tissue.inlets is not None else "tissue.inlets_path"
        raise ConfigError(
            f"tissue.ostium_height places the heart's own ostia, which {given} replaces: set one of them "
            f"(got ostium_height={cfg.tissue.ostium_height:g} m)"
        )
    if cfg.tissue.inlets is not None and cfg.tissue.inlets_path:
        raise ConfigError("tissue.inlets and tissue.inlets_path both give the inlets: set one of them")
    _check_labels(cfg.tissue.labels)
    _check_surface_keys(cfg.tissue)
    p = cfg.physics
    for name in ("gamma", "inlet_radius", "total_flow", "viscosity", "A_wv"):
        _positive(f"physics.{name}", getattr(p, name))
    for name in ("r_cutoff", "A_o", "A_p", "A_s"):
        value = getattr(p, name)
        if not (value >= 0 and math.isfinite(value)):
            raise ConfigError(f"physics.{name} must be a finite number >= 0, got {value}")
    if not GAMMA_RANGE[0] <= p.gamma <= GAMMA_RANGE[1]:
        raise ConfigError(
            f"physics.gamma must lie in [{GAMMA_RANGE[0]:g}, {GAMMA_RANGE[1]:g}] (the bifurcation exponent of "
            f"r_parent^gamma = sum r_child^gamma: Murray's 3, the paper's 2.1), got {p.gamma:g}"
        )
    _check_segment_costs(cfg)
    a = cfg.anneal
    if a.T_start is not None:
        _positive("anneal.T_start", a.T_start)
    if a.T_end is not None:
        _positive("anneal.T_end", a.T_end)
    if a.T_start is not None and a.T_end is not None and a.T_end >= a.T_start:
        raise ConfigError(f"anneal.T_end must be < anneal.T_start, got T_end={a.T_end} >= T_start={a.T_start}")
    for name in ("accept_start", "acceptance_target"):
        if not 0.0 < getattr(a, name) < 1.0:
            raise ConfigError(f"anneal.{name} must lie in (0, 1), got {getattr(a, name)}")
    _positive("anneal.T_end_rel", a.T_end_rel)
    if a.supply_T_start is not None:
        _positive("anneal.supply_T_start", a.supply_T_start)
        _positive("anneal.supply_T_end", a.supply_T_end)
        if a.supply_T_end >= a.supply_T_start:
            raise ConfigError(
                f"anneal.supply_T_end must be < anneal.supply_T_start, got {a.supply_T_end} >= {a.supply_T_start}"
            )
    if not 0.0 < a.supply_phase <= 1.0:
        raise ConfigError(f"anneal.supply_phase must lie in (0, 1], got {a.supply_phase}")
    if not 0.0 < a.full_width_phase <= 1.0:
        raise ConfigError(f"anneal.full_width_phase must lie in (0, 1], got {a.full_width_phase}")
    if (a.cold_from is None) != (a.cold_share is None):
        raise ConfigError(
            f"anneal.cold_from and anneal.cold_share are set together (both null: one exponential), "
            f"got cold_from={a.cold_from}, cold_share={a.cold_share}"
        )
    if a.cold_from is not None:
        for name in ("cold_from", "cold_share"):
            if not 0.0 < getattr(a, name) < 1.0:
                raise ConfigError(f"anneal.{name} must lie in (0, 1), got {getattr(a, name)}")
    _check_parts(cfg)
    if (a.coarse_exclusion_factor is None) != (a.coarse_exclusion_phase is None):
        raise ConfigError(
            "anneal.coarse_exclusion_factor and anneal.coarse_exclusion_phase are set together (both null: the "
            f"true depth map throughout), got factor={a.coarse_exclusion_factor}, phase={a.coarse_exclusion_phase}"
        )
    if a.coarse_exclusion_factor is not None:
        f = a.coarse_exclusion_factor
        if isinstance(f, bool) or not isinstance(f, int) or not 2 <= f <= MAX_COARSE_EXCLUSION_FACTOR:
            raise ConfigError(
                f"anneal.coarse_exclusion_factor must be an integer in [2, {MAX_COARSE_EXCLUSION_FACTOR}] "
                f"(voxels per coarse voxel edge), got {f!r}"
            )
        if not 0.0 < a.coarse_exclusion_phase < 1.0:
            raise ConfigError(f"anneal.coarse_exclusion_phase must lie in (0, 1), got {a.coarse_exclusion_phase}")
    _positive("anneal.neighbour_cell", a.neighbour_cell)
    if not isinstance(a.polish_swaps_max_terminals, int) or a.polish_swaps_max_terminals < 0:
        raise ConfigError(
            f"anneal.polish_swaps_max_terminals must be an integer >= 0, got {a.polish_swaps_max_terminals}"
        )
    for name in ("calibration_samples", "adapt_window"):
        if not isinstance(getattr(a, name), int) or not 1 <= getattr(a, name) <= MAX_CALIBRATION_SAMPLES:
            raise ConfigError(
                f"anneal.{name} must be an integer in [1, {MAX_CALIBRATION_SAMPLES:.0e}], got {getattr(a, name)}"
            )
    if not 0.0 <= a.p_local <= 1.0:
        raise ConfigError(f"anneal.p_local must lie in [0, 1], got {a.p_local}")
    _positive("anneal.steps_at_1000", a.steps_at_1000)
    if a.steps is None and scheduled_steps(cfg) > MAX_STEPS:
        raise ConfigError(
            f"anneal.steps_at_1000={a.steps_at_1000:g} schedules {scheduled_steps(cfg):.3g} proposed "
            f"moves at n_terminals={cfg.n_terminals}, more than {MAX_STEPS:.0e}; lower it or set "
            "anneal.steps"
        )
    if not (0.0 <= a.steps_exponent <= 4.0):
        raise ConfigError(f"anneal.steps_exponent must lie in [0, 4], got {a.steps_exponent}")
    if not (0.0 <= a.packing_steps_per_terminal < math.inf):
        raise ConfigError(
            f"anneal.packing_steps_per_terminal must be a finite number >= 0, got {a.packing_steps_per_terminal}"
        )
    if a.packing_steps_per_terminal > 0:
        _positive("anneal.packing_T_start", a.packing_T_start)
        _positive("anneal.packing_T_end", a.packing_T_end)
        if cfg.terminals.fixed:
            raise ConfigError(
                "anneal.packing_steps_per_terminal must be 0 with terminals.fixed=true (the packing "
                "phase moves terminals)"
            )
        if packing_steps(cfg) >= scheduled_steps(cfg):
            raise ConfigError(
                f"anneal.packing_steps_per_terminal={a.packing_steps_per_terminal:g} gives "
                f"{packing_steps(cfg)} packing proposals, but the run has only {scheduled_steps(cfg)} "
                "(anneal.steps): leave room for the tree anneal"
            )
    if not 0.0 <= a.p_swap <= 1.0:
        raise ConfigError(f"anneal.p_swap must lie in [0, 1], got {a.p_swap}")
    _positive("anneal.step_terminal", a.step_terminal)
    _positive("anneal.step_bifurcation", a.step_bifurcation)
    if not isinstance(a.trace_every, int) or not 1 <= a.trace_every <= MAX_STEPS:
        raise ConfigError(f"anneal.trace_every must be an integer in [1, {MAX_STEPS:.0e}], got {a.trace_every}")
    for name in ("voxel_size", "exclusion_voxel_size"):
        if getattr(cfg.tissue, name) is not None:
            _positive(f"tissue.{name}", getattr(cfg.tissue, name))
    if cfg.tissue.q_required is not None:
        _positive("tissue.q_required", cfg.tissue.q_required)
    _positive("checkpoint.every_seconds", cfg.checkpoint.every_seconds)
    if cfg.checkpoint.every_seconds > MAX_CHECKPOINT_SECONDS:
        raise ConfigError(
            f"checkpoint.every_seconds must be <= {MAX_CHECKPOINT_SECONDS:g} (a week), got "
            f"{cfg.checkpoint.every_seconds}"
        )
    if cfg.stage not in STAGES:
        raise ConfigError(f"stage must be one of {', '.join(STAGES)}, got {cfg.stage!r}")
    _validate_extend(cfg.extend)
    _validate_method(cfg)
    if cfg.terminals.fixed and not cfg.terminals.path:
        raise ConfigError("terminals.fixed=true needs terminals.path (a CSV of x, y, z in metres)")
    return _freeze(cfg)


def _check_parts(cfg: RunConfig) -> None:
    a = cfg.anneal
    if not isinstance(a.parts, int) or not 1 <= a.parts <= max(1, cfg.n_terminals // 16):
        raise ConfigError(
            f"anneal.parts must be an integer in [1, n_terminals / 16 = {max(1, cfg.n_terminals // 16)}] (parts of at "
            f"least 16 terminals), got {a.parts}"
        )
    if not isinstance(a.part_phases, int) or not 1 <= a.part_phases <= 100_000:
        raise ConfigError(f"anneal.part_phases must be an integer in [1, 100000], got {a.part_phases}")
    if not 0.0 < a.part_share < 1.0:
        raise ConfigError(f"anneal.part_share must lie in (0, 1), got {a.part_share}")
    if a.parts > 1 and cfg.physics.A_p != 0:
        raise ConfigError(
            f"anneal.parts={a.parts} needs physics.A_p = 0: the terminal-pressure term couples every segment of "
            "the tree, so parts could not be annealed apart"
        )
    if a.parts > 1 and cfg.method.name != "anneal":
        raise ConfigError(f"anneal.parts={a.parts} applies to method=anneal only, got method={cfg.method.name}")


def _check_labels(labels: LabelsConfig) -> None:
    """Each of tissue.labels.* null or a non-empty list of integers >= 0, no label in two roles."""
    seen: dict[int, str] = {}
    for role in ("supply", "exclusion", "open"):
        values = getattr(labels, role)
        if values is None:
            continue
        if not values or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in values):
            raise ConfigError(
                f"tissue.labels.{role} must be a non-empty list of integer label values >= 0, or null, got {values!r}"
            )
        for v in values:
            if v in seen:
                raise ConfigError(f"tissue.labels: label {v} is both {seen[v]} and {role}; give each label one role")
            seen[v] = role


def _check_segment_costs(cfg: RunConfig) -> None:
    """Every segment's radius, Poiseuille resistance, power and volume cost (n = 1..N terminals
    downstream, r = r_in (n / N)^(1/gamma)) must be a finite number > 0 in float64: where the
    physics parameters together leave that range, the model is not defined (and the flow
    solve fails far from the setting that caused it)."""
    import numpy as np

    p = cfg.physics
    n = np.arange(1, cfg.n_terminals + 1, dtype=np.float64)
    with np.errstate(all="ignore"):
        r = p.inlet_radius * (n / cfg.n_terminals) ** (1.0 / p.gamma)
        resistance = 8.0 * p.viscosity / (math.pi * r**4)
        parts = {
            "radius": r,
            "resistance": resistance,
            "power": (n * p.total_flow / cfg.n_terminals) ** 2 * resistance,
            "volume cost": p.m_b * math.pi * r**2,
        }
    for what, values in parts.items():
        if not (np.all(np.isfinite(values)) and np.all(values > 0)):
            raise ConfigError(
                f"physics.inlet_radius={p.inlet_radius:g}, physics.viscosity={p.viscosity:g}, "
                f"physics.total_flow={p.total_flow:g}, physics.m_b={p.m_b:g} and physics.gamma={p.gamma:g} give "
                f"N={cfg.n_terminals} terminal segments a {what} outside the floating-point range (terminal radius "
                f"{float(r[0]):.3g} m): the model is not defined there"
            )


def _check_tissue_keys(tissue: TissueConfig) -> None:
    """A tissue key the chosen tissue does not read (``tissue.mass_g`` with ``tissue=sphere``)
    must keep its default: set, it would change nothing but the run's identity."""
    from ..model.tissue import TISSUES

    read_by = {name: set(inspect.signature(build).parameters) for name, build in TISSUES.items()}
    defaults = TissueConfig()
    for key in TissueConfig.__dataclass_fields__:
        if key in TISSUE_KEYS_OF_EVERY_TISSUE or key in read_by[tissue.name]:
            continue
        default = getattr(defaults, key)
        if getattr(tissue, key) != default:
            readers = " and ".join(f"tissue={name}" for name, keys in read_by.items() if key in keys)
            raise ConfigError(
                f"tissue.{key} is read by {readers} only; tissue={tissue.name} ignores it: leave it at its "
                f"default ({json.dumps(asdict(default) if is_dataclass(default) else default)})"
            )


def _validate_method(cfg: RunConfig) -> None:
    m = cfg.method
    if m.name not in METHODS:
        raise ConfigError(f"method.name: unknown method {m.name!r}; accepted: {', '.join(METHODS)} (method=cco)")
    if cfg.anneal.init not in ANNEAL_INITS:
        raise ConfigError(f"anneal.init must be one of {', '.join(ANNEAL_INITS)}, got {cfg.anneal.init!r}")
    for name in ("candidates", "max_tries"):
        if not isinstance(getattr(m, name), int) or getattr(m, name) < 1:
            raise ConfigError(f"method.{name} must be an integer >= 1, got {getattr(m, name)}")
    if not 0.0 < m.shrink < 1.0:
        raise ConfigError(f"method.shrink must lie in (0, 1), got {m.shrink}")
    if m.order not in ("file", "random"):
        raise ConfigError(f"method.order must be 'file' or 'random', got {m.order!r}")
    if not isinstance(m.avoid_cavities, bool):
        raise ConfigError(f"method.avoid_cavities must be true or false, got {m.avoid_cavities!r}")


def _validate_extend(e: ExtendConfig) -> None:
    n = e.n_terminals
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_TERMINALS:
        raise ConfigError(
            f"extend.n_terminals must be an integer in [1, {MAX_TERMINALS:.0e}] (fine terminals in all, at least "
            f"the run's N), got {n!r}"
        )
    if e.runs not in EXTEND_RUNS:
        raise ConfigError(f"extend.runs must be one of {', '.join(EXTEND_RUNS)}, got {e.runs!r}")
    b = e.batch_territories
    if isinstance(b, bool) or not isinstance(b, int) or not 1 <= b <= 10**7:
        raise ConfigError(f"extend.batch_territories must be an integer in [1, 1e7], got {b!r}")
    if e.seed is not None and not seed_ok(e.seed):
        raise ConfigError(f"extend.seed must be {SEED_ACCEPTED} or null (the run's own seed), got {e.seed!r}")
    if e.zerod not in EXTEND_ZERODS:
        raise ConfigError(
            f"extend.zerod must be one of {', '.join(EXTEND_ZERODS)} (the whole tree's 0D network: each territory's "
            f"subtree one lumped resistance, or every vessel), got {e.zerod!r}"
        )


def _check_surface_keys(tissue: TissueConfig) -> None:
    """tissue.cavity_paths null or a non-empty list of paths, tissue.mesh_unit a known unit, and
    tissue.demand_path null or a path (the files themselves are read, and refused, by the tissue)."""
    from ..model.tissue.surfaces import MESH_UNITS

    cavities = tissue.cavity_paths
    if cavities is not None and (not cavities or not all(isinstance(c, str) and c.strip() for c in cavities)):
        raise ConfigError(
            "tissue.cavity_paths must be a non-empty list of closed surface files (STL, OBJ, PLY, VTP), or null, "
            f"got {cavities!r}"
        )
    if tissue.mesh_unit not in MESH_UNITS:
        raise ConfigError(f"tissue.mesh_unit must be one of {', '.join(MESH_UNITS)}, got {tissue.mesh_unit!r}")
    if tissue.demand_path is not None and not str(tissue.demand_path).strip():
        raise ConfigError("tissue.demand_path must name a file (.npy, Zarr, NIfTI, NRRD), or be null, got ''")
