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
from .keys import KEYS
from .keyspec import EVERY
from .rules import MAX_STEPS, SWEPT_KEYS, sweep_axis
from .schedule import packing_steps, scheduled_steps
from .schema import (
    TISSUE_KEYS_OF_EVERY_TISSUE,
    AnnealConfig,
    LabelsConfig,
    RunConfig,
    TissueConfig,
)

__all__ = ["share_set_by_model", "validate"]


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

    The ranges of single keys are the key table's (:data:`~vasc_pipeline.config.keys.KEYS`); the
    checks below it are those that tie keys together. Returns a validated copy, frozen
    (:mod:`vasc_pipeline.config.frozen`): the engine and the planner take it as it is. A frozen
    config was validated already and is returned unchanged.
    """
    if is_frozen(cfg):
        return cfg
    cfg = thawed(cfg)
    _check_finite(cfg, "")
    _check_table(cfg)
    if not str(cfg.output_dir).strip():
        raise ConfigError("output_dir must name a directory, got an empty string; give one with output_dir=...")
    if cfg.sweep is not None:
        for axis in SWEPT_KEYS:
            sweep_axis(axis, getattr(cfg.sweep, axis), None)
    _check_inlets(cfg.tissue)
    _check_inlet_share(cfg)
    _check_tissue_keys(cfg.tissue)
    _check_labels(cfg.tissue.labels)
    _check_surface_keys(cfg.tissue)
    phys = cfg.physics
    if not phys.pressure_inlet > phys.pressure_terminal:
        raise ConfigError(
            "physics.pressure_inlet must exceed physics.pressure_terminal, which must be >= 0 (Pa; blood "
            f"flows from the inlets to the terminals), got {phys.pressure_inlet:g} and {phys.pressure_terminal:g}"
        )
    _check_segment_costs(cfg)
    _check_temperatures(cfg.anneal)
    _check_pairs(cfg.anneal)
    _check_parts(cfg)
    _check_budget(cfg)
    _validate_method(cfg)
    if cfg.terminals.fixed and not cfg.terminals.path:
        raise ConfigError("terminals.fixed=true needs terminals.path (a CSV of x, y, z in metres)")
    return _freeze(cfg)


def _check_table(cfg: RunConfig) -> None:
    """Every key of the key table with a check, in the table's order; a tissue key the chosen
    tissue does not read is left to :func:`_check_tissue_keys` (it must keep its default). A count
    written as a float (a script's ``n_terminals=5.0``) is stored as the integer it is."""
    for key in KEYS:
        if key.check is None or (key.applies is not None and not key.applies(cfg)):
            continue
        if key.tissues not in (None, EVERY) and cfg.tissue.name not in key.tissues:
            continue
        *path, leaf = key.name.split(".")
        node = cfg
        for part in path:
            node = getattr(node, part)
        setattr(node, leaf, key.check.check(key.name, getattr(node, leaf)))


def _check_inlets(tissue: TissueConfig) -> None:
    """tissue.inlets null or a non-empty list of [x, y, z] numbers (stored as floats); the heart's
    own ostia (ostium_height), tissue.inlets and tissue.inlets_path: one of them at most."""
    if tissue.inlets is not None:
        if not tissue.inlets:
            raise ConfigError("tissue.inlets must hold at least one [x, y, z] position in metres (or be null), got []")
        for k, p in enumerate(tissue.inlets):
            if not (
                isinstance(p, (list, tuple))
                and len(p) == 3
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p)
            ):
                raise ConfigError(f"tissue.inlets[{k}] must be an [x, y, z] position in metres, got {p!r}")
        tissue.inlets = [[float(v) for v in p] for p in tissue.inlets]
    if tissue.ostium_height is not None and (tissue.inlets is not None or tissue.inlets_path):
        given = "tissue.inlets" if tissue.inlets is not None else "tissue.inlets_path"
        raise ConfigError(
            f"tissue.ostium_height places the heart's own ostia, which {given} replaces: set one of them "
            f"(got ostium_height={tissue.ostium_height:g} m)"
        )
    if tissue.inlets is not None and tissue.inlets_path:
        raise ConfigError("tissue.inlets and tissue.inlets_path both give the inlets: set one of them")


def _check_inlet_share(cfg: RunConfig) -> None:
    """tissue.inlet_share one fraction > 0 per inlet summing to 1; its tolerance only with it."""
    share = cfg.tissue.inlet_share
    if share is not None and (not share or any(not (s > 0) for s in share) or abs(sum(share) - 1.0) > 1e-6):
        raise ConfigError(
            f"tissue.inlet_share must list one fraction > 0 per inlet, summing to 1 (heart: [LCA, RCA], "
            f"e.g. [0.62, 0.38]), got {list(share)}"
        )
    tolerance = cfg.tissue.inlet_share_tolerance
    if tolerance is not None and share is None:
        raise ConfigError(
            "tissue.inlet_share_tolerance is a band around tissue.inlet_share: set the share too (heart: "
            f"tissue.inlet_share=[0.62,0.38]), or leave the tolerance null; got {tolerance}"
        )


def _check_temperatures(a: AnnealConfig) -> None:
    """Each schedule cools: its end temperature below its start."""
    if a.T_start is not None and a.T_end is not None and a.T_end >= a.T_start:
        raise ConfigError(f"anneal.T_end must be < anneal.T_start, got T_end={a.T_end} >= T_start={a.T_start}")
    if a.supply_T_start is not None and a.supply_T_end >= a.supply_T_start:
        raise ConfigError(
            f"anneal.supply_T_end must be < anneal.supply_T_start, got {a.supply_T_end} >= {a.supply_T_start}"
        )


def _check_pairs(a: AnnealConfig) -> None:
    """The keys set together: the cold part's start and share, the coarse map's factor and phase."""
    if (a.cold_from is None) != (a.cold_share is None):
        raise ConfigError(
            f"anneal.cold_from and anneal.cold_share are set together (both null: one exponential), "
            f"got cold_from={a.cold_from}, cold_share={a.cold_share}"
        )
    if (a.coarse_exclusion_factor is None) != (a.coarse_exclusion_phase is None):
        raise ConfigError(
            "anneal.coarse_exclusion_factor and anneal.coarse_exclusion_phase are set together (both null: the "
            f"true depth map throughout), got factor={a.coarse_exclusion_factor}, phase={a.coarse_exclusion_phase}"
        )


def _check_budget(cfg: RunConfig) -> None:
    """The scheduled steps within MAX_STEPS; a packing phase with room for the tree anneal after it."""
    a = cfg.anneal
    if a.steps is None and scheduled_steps(cfg) > MAX_STEPS:
        raise ConfigError(
            f"anneal.steps_at_1000={a.steps_at_1000:g} schedules {scheduled_steps(cfg):.3g} proposed "
            f"moves at n_terminals={cfg.n_terminals}, more than {MAX_STEPS:.0e}; lower it or set "
            "anneal.steps"
        )
    if a.packing_steps_per_terminal > 0:
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


def _check_parts(cfg: RunConfig) -> None:
    a = cfg.anneal
    if not isinstance(a.parts, int) or not 1 <= a.parts <= max(1, cfg.n_terminals // 16):
        raise ConfigError(
            f"anneal.parts must be an integer in [1, n_terminals / 16 = {max(1, cfg.n_terminals // 16)}] (parts of at "
            f"least 16 terminals), got {a.parts}"
        )


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
    downstream, the model's own cost tables) must be a finite number > 0 in float64: where the
    physics parameters together leave that range, the model is not defined (and the flow
    solve fails far from the setting that caused it)."""
    import numpy as np

    from ..model.physics import TABLE_POWER, TABLE_RESISTANCE, TABLE_VOLUME, Physics, segment_factors

    p = cfg.physics
    physics = Physics(
        n_terminals=cfg.n_terminals,
        n_inlets=1,
        gamma=p.gamma,
        inlet_radius=p.inlet_radius,
        total_flow=p.total_flow,
        m_b=p.m_b,
        viscosity=p.viscosity,
        supply_radius=0.0,  # not read by the tables
        viscosity_law=p.viscosity_law,
    )
    n = np.arange(1, cfg.n_terminals + 1)
    with np.errstate(all="ignore"):
        r = physics.radius(n)
        factors = segment_factors(physics, n)
    parts = {
        "radius": r,
        "resistance": factors[TABLE_RESISTANCE],
        "power": factors[TABLE_POWER],
        "volume cost": factors[TABLE_VOLUME],
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
    """What the CCO growth (method=cco, anneal.init=cco) cannot do: a fixed inlet share, a
    bifurcation reach; the anneal's parts apply to method=anneal only."""
    tissue, name = cfg.tissue, cfg.method.name
    if tissue.inlet_share is not None and (name == "cco" or cfg.anneal.init == "cco"):
        raise ConfigError(
            "tissue.inlet_share fixes the terminals of every inlet, which the CCO growth (method=cco, "
            "anneal.init=cco) assigns by connection: leave it unset (null) there" + share_set_by_model(cfg)
        )
    if tissue.bifurcation_reach is not None and name == "cco":
        raise ConfigError(
            "tissue.bifurcation_reach confines the anneal's bifurcations; the CCO growth (method=cco) "
            "places them at their optimum: leave it unset (null) there"
        )
    if not tissue.bifurcations_in_cavities and name == "cco":
        raise ConfigError(
            "tissue.bifurcations_in_cavities=false confines the anneal's bifurcations; the CCO growth "
            "(method=cco) keeps its segments out of cavities with method.avoid_cavities=true instead"
        )
    if cfg.anneal.parts > 1 and name != "anneal":
        raise ConfigError(f"anneal.parts={cfg.anneal.parts} applies to method=anneal only, got method={name}")


def _check_surface_keys(tissue: TissueConfig) -> None:
    """tissue.cavity_paths null or a non-empty list of paths, tissue.demand_path null or a path
    (the files themselves are read, and refused, by the tissue)."""
    cavities = tissue.cavity_paths
    if cavities is not None and (not cavities or not all(isinstance(c, str) and c.strip() for c in cavities)):
        raise ConfigError(
            "tissue.cavity_paths must be a non-empty list of closed surface files (STL, OBJ, PLY, VTP), or null, "
            f"got {cavities!r}"
        )
    if tissue.demand_path is not None and not str(tissue.demand_path).strip():
        raise ConfigError("tissue.demand_path must name a file (.npy, Zarr, NIfTI, NRRD), or be null, got ''")
