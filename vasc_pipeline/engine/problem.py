"""The problem of one run and the kernel state it anneals: build, initialise, convert.

:func:`build_problem` turns a config into a :class:`Problem` (tissue, physics, cost terms
and the kernel's read-only ``Model``); :func:`initial_state` draws and calibrates the initial
``State``; :func:`state_arrays` / :func:`restore_state` are the checkpoint round trip;
:func:`running_costs` and :func:`tree_of` read a state. The loop that anneals a state is
:mod:`vasc_pipeline.engine.run`'s.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .. import kernel
from ..config.checks import share_set_by_model, validate
from ..config.schedule import Schedule
from ..config.schema import ConfigError, RunConfig, to_run_config
from ..model.costs import COST_TERMS, ActiveTerms, active_terms, cavity_share, total_cost
from ..model.physics import Physics, cost_tables, supply_radius
from ..model.rng import seed_state
from ..model.tissue import Tissue, build_tissue
from ..model.tissue.grid import check_voxel_scale
from ..model.tree import (
    Tree,
    TreeError,
    check_duplicate_sites,
    inlet_count_bounds,
    load_terminal_sites,
    random_tree,
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
]

# State fields saved in a checkpoint (everything but scratch space).
CHECKPOINT_FIELDS = tuple(f for f in kernel.State._fields if not f.startswith("scratch_"))
# Their dtypes (the one list; :func:`restore_state` casts to them): float64 but these, and
# the supply map (:func:`supply_dtype`).
_STATE_INT64 = dict.fromkeys(
    ("parent", "children", "n_downstream", "counters", "cell_of", "cell_head", "cell_next", "cell_prev"), np.int64
)
_STATE_INT64["rng"] = np.uint64


@dataclass
class Problem:
    """Everything fixed for a run: config, physics, tissue, active terms and the kernel's Model."""

    config: RunConfig
    physics: Physics
    tissue: Tissue
    terms: ActiveTerms
    model: kernel.Model
    schedule: Schedule  # the run's phases in steps (the kernel's Model holds a flat copy)
    sites: np.ndarray | None = None
    coarse_model: kernel.Model | None = None  # ``model`` on the coarse exclusion map, before schedule.coarse

    @property
    def total_steps(self) -> int:
        """Proposed moves of the run."""
        return self.schedule.total

    @property
    def coarse_steps(self) -> int:
        """The proposals before this one run on ``coarse_model`` (0: none)."""
        return self.schedule.coarse


def node_radii(tree: Tree, physics: Physics) -> np.ndarray:
    radius = physics.radius(tree.n_downstream)
    radius[: tree.n_inlets] = 0.0
    return radius


def build_problem(config: Any) -> Problem:
    """Build a config's tissue, physics and kernel model.

    A validated (frozen) config is taken as it is; a RunConfig, dict or OmegaConf node is
    validated first (:func:`vasc_pipeline.config.validate`).
    """
    cfg = validate(to_run_config(config))
    tissue, sites = _tissue_and_sites(cfg)
    physics = _physics(cfg, tissue)
    terms = active_terms(physics, cfg.terminals.fixed)
    schedule = Schedule.of(cfg, exclusion=terms.exclusion)
    cells = _neighbour_cells(cfg.anneal, physics, tissue)
    _check_start_temperature(cfg.anneal, physics, cfg.n_terminals)
    check_voxel_scale(tissue, physics.supply_radius, cfg.n_terminals)
    model = _kernel_model(cfg, tissue, physics, terms, schedule, cells)
    coarse_model = None
    if schedule.coarse > 0:
        coarse_model = model._replace(
            **kernel.exclusion_fields(tissue.exclusion_grid.coarsened(cfg.anneal.coarse_exclusion_factor))
        )
    return Problem(cfg, physics, tissue, terms, model, schedule, sites, coarse_model)


def _tissue_and_sites(cfg: RunConfig) -> tuple[Tissue, np.ndarray | None]:
    """The config's tissue and given terminal sites (or None), checked against N and the inlets."""
    params = {k: v for k, v in asdict(cfg.tissue).items() if k != "name"}
    n = cfg.n_terminals
    tissue = build_tissue(cfg.tissue.name, n, total_flow=cfg.physics.total_flow, **params)
    sites = None
    if cfg.terminals.path:
        sites = load_terminal_sites(cfg.terminals.path, tissue)
        if len(sites) != n:
            raise TreeError(
                f"terminals.path holds {len(sites)} sites but n_terminals = {n}; set n_terminals={len(sites)}"
            )
        check_duplicate_sites(sites, cfg.terminals.path, cfg.terminals.fixed)
    k = len(tissue.inlets)
    if n < k:
        raise TreeError(f"n_terminals must be >= the number of inlets ({k}) of tissue {tissue.name!r}, got {n}")
    share = cfg.tissue.inlet_share
    if share is not None and len(share) != k:
        names = ", ".join(tissue.inlet_names)
        raise TreeError(
            f"tissue.inlet_share lists {len(share)} fractions; tissue {tissue.name!r} has {k} inlets ({names})"
            + share_set_by_model(cfg)
        )
    return tissue, sites


def _physics(cfg: RunConfig, tissue: Tissue) -> Physics:
    """Field by field: the config's physics as given, plus what the problem fixes (N, K, R_supply)."""
    p, n = cfg.physics, cfg.n_terminals
    return Physics(
        n_terminals=n,
        n_inlets=len(tissue.inlets),
        gamma=p.gamma,
        inlet_radius=p.inlet_radius,
        total_flow=p.total_flow,
        m_b=p.m_b,
        viscosity=p.viscosity,
        # with a demand map the spheres fill the demand-weighted volume, sum of t_v voxel volumes
        supply_radius=supply_radius(n, tissue.supply_measure, tissue.ndim, cfg.tissue.q_required, p.total_flow),
        r_cutoff=p.r_cutoff,
        r_cutoff_ramp=p.r_cutoff_ramp,
        A_wv=p.A_wv,
        A_o=p.A_o,
        A_p=p.A_p,
        A_s=p.A_s,
        pressure_inlet=p.pressure_inlet,
        pressure_terminal=p.pressure_terminal,
        viscosity_law=p.viscosity_law,
    )


def _bifurcation_region(t, tissue: Tissue) -> np.ndarray:
    """uint8 grid of where bifurcations may lie (``tissue.bifurcation_reach``, less the cavities
    with ``tissue.bifurcations_in_cavities=false``); shape (0, 0, 0): anywhere in the box."""
    if t.bifurcation_reach is None and t.bifurcations_in_cavities:
        return np.zeros((0, 0, 0), dtype=np.uint8)
    if t.bifurcation_reach is None:
        region = np.ones(tissue.mask.shape, dtype=np.uint8)
    else:
        region = tissue.bifurcation_region(t.bifurcation_reach)
    if not t.bifurcations_in_cavities:
        region[tissue.cavity] = 0
    return region


def _neighbour_cells(a, physics: Physics, tissue: Tissue) -> tuple[float, np.ndarray]:
    """(cell size [m], cell shape) of the local swap partners' neighbour cells (at most 2e7 cells)."""
    lo, hi = tissue.bounds
    cell_size = a.neighbour_cell * physics.supply_radius
    cell_shape = np.maximum(np.ceil((hi - lo) / cell_size), 1).astype(np.int64)
    if tissue.ndim == 2:
        cell_shape[2] = 1
    if np.prod(cell_shape) > 20_000_000:
        raise ConfigError(
            f"anneal.neighbour_cell={a.neighbour_cell} gives {int(np.prod(cell_shape))} neighbour "
            "cells (at most 2e7); use a larger value (in R_supply; fast: 2, paper and fast_v1: 1)"
        )
    return cell_size, cell_shape


def _check_start_temperature(a, physics: Physics, n: int) -> None:
    """A given anneal.T_start must exceed the end temperature: the schedule never warms up."""
    t_end = scheduled_T_end(a, physics)
    if a.T_start is not None and not a.T_start > t_end:
        where = "anneal.T_end" if a.T_end is not None else f"anneal.T_end_rel={a.T_end_rel:g} times w(1) R_supply"
        raise ConfigError(
            f"anneal.T_start={a.T_start:g} W must exceed the end temperature, {t_end:.4g} W "
            f"({where}, at n_terminals={n}); the schedule would warm up"
        )


def _kernel_model(cfg: RunConfig, tissue: Tissue, physics: Physics, terms, schedule: Schedule, cells) -> kernel.Model:
    """The kernel's :class:`~vasc_pipeline.kernel.Model`: every array and scalar the anneal reads."""
    a, p, n = cfg.anneal, cfg.physics, cfg.n_terminals
    w_o, w_p, w_s = physics.weights
    lo, hi = tissue.bounds
    cell_size, cell_shape = cells
    rho = physics.supply_radius / tissue.voxel_size
    sphere_voxels = math.pi * rho**2 if tissue.ndim == 2 else 4.0 / 3.0 * math.pi * rho**3  # C_s scale of one move
    return kernel.Model(
        n_inlets=physics.n_inlets,
        n_terminals=n,
        tables=cost_tables(physics).array,
        mask=tissue.mask,
        **kernel.exclusion_fields(tissue.exclusion_grid),
        origin=tissue.origin,
        voxel_size=float(tissue.voxel_size),
        box_lo=lo,
        box_hi=hi,
        supply_rho=physics.supply_radius / tissue.voxel_size,
        w_exclusion=w_o,
        w_pressure=w_p,
        w_supply=w_s,
        supply_on=terms.supply,
        exclusion_on=terms.exclusion,
        pressure_on=terms.pressure,
        move_terminals=not cfg.terminals.fixed,
        planar=tissue.ndim == 2,
        pressure_inlet=np.full(physics.n_inlets, float(p.pressure_inlet)),
        pressure_terminal=p.pressure_terminal,
        total_steps=float(schedule.total),
        pack_steps=float(schedule.pack),
        cold_steps=float(schedule.cold),
        cold_path=float(a.cold_from) if a.cold_from is not None else 1.0,
        pack_T_start=float(a.packing_T_start) * sphere_voxels,
        pack_T_end=float(a.packing_T_end),
        p_swap=float(a.p_swap),
        p_local=float(a.p_local),
        cell_lo=lo.astype(np.float64),
        cell_size=float(cell_size),
        cell_shape=cell_shape,
        supply_T_start=float(a.supply_T_start or 1.0) * sphere_voxels,
        supply_T_end=float(a.supply_T_end),
        supply_steps=float(schedule.supply),
        adapt_steps=bool(a.adapt_steps),
        full_width_steps=float(schedule.full_width),
        acceptance_target=float(a.acceptance_target),
        adapt_window=int(a.adapt_window),
        step_max=np.array([a.step_terminal, a.step_bifurcation]) * physics.supply_radius,
        early_reject=True,
        supply_shell_width=kernel.SHELL_WIDTH,
        prefetch_lead=kernel.PREFETCH_LEAD,
        prefetch_supply=True,
        fixed_inlet_counts=cfg.tissue.inlet_share is not None and cfg.tissue.inlet_share_tolerance is None,
        inlet_count_bounds=inlet_count_bounds(cfg.tissue.inlet_share, cfg.tissue.inlet_share_tolerance, n),
        bifurcation_region=_bifurcation_region(cfg.tissue, tissue),
        supply_target=(
            np.zeros((0, 0, 0), dtype=np.uint8)
            if tissue.supply_target is None
            else np.ascontiguousarray(tissue.supply_target, dtype=np.uint8)
        ),
    )


def supply_dtype(n_terminals: int) -> type:
    """Dtype of the supply count map: int16 while no count can overflow it (a count is at
    most N), which halves the map's cache footprint against int32; int32 beyond."""
    return np.int16 if n_terminals <= np.iinfo(np.int16).max else np.int32


def initial_state(problem: Problem, seed: int) -> kernel.State:
    """The initial tree of (config, seed) with its caches, running sums and schedule filled.

    The tree is random (:func:`vasc_pipeline.model.tree.random_tree`), or with ``anneal.init=cco`` the CCO tree of
    :func:`vasc_pipeline.engine.cco.grow_tree` drawn from the run's generator.

    Temperatures left unset in the config (``anneal.T_start`` / ``anneal.T_end`` = None)
    are calibrated here (:func:`calibrate_schedule`) and kept in ``state.schedule``, so a
    resumed run uses the same ones.
    """
    rng = seed_state(seed)
    if problem.config.anneal.init == "cco":  # a constructive tree as the warm start (same generator)
        from .cco import grow_tree

        tree = grow_tree(problem, rng)[0]
    else:
        t = problem.config.tissue
        tree = random_tree(
            problem.tissue, problem.physics.n_terminals, rng, problem.sites, t.inlet_share, t.inlet_assignment
        )
    region = problem.model.bifurcation_region
    if region.size:  # tissue.bifurcation_reach: the initial bifurcations (children's means) moved into it
        bifurcations = slice(problem.model.n_inlets + problem.model.n_terminals, None)
        tree.position[bifurcations] = problem.tissue.move_into(region, tree.position[bifurcations])
    return state_from_tree(problem, tree, rng)


def state_from_tree(problem: Problem, tree: Tree, rng: np.ndarray) -> kernel.State:
    """A kernel state on ``tree`` (legal for ``problem``) drawing from the generator state
    ``rng``, with its caches and running sums filled and its schedule set or calibrated on it."""
    anneal = problem.config.anneal
    m = tree.n_nodes
    state = restore_state(
        problem,
        {
            "parent": tree.parent,
            "children": tree.children,
            "position": tree.position,
            "n_downstream": tree.n_downstream,
            "seg_length": np.zeros(m),
            "seg_exclusion": np.zeros(m),
            "supply": np.zeros(problem.tissue.shape),
            "costs": np.zeros(len(COST_TERMS)),
            "compensation": np.zeros(len(COST_TERMS)),
            "rng": rng,
            "counters": np.zeros(kernel.N_COUNTERS),
            "step_size": problem.model.step_max,
            "schedule": np.array([np.nan, np.nan]),
            "cell_of": np.zeros(m),
            "cell_head": np.zeros(int(np.prod(problem.model.cell_shape))),
            "cell_next": np.zeros(m),
            "cell_prev": np.zeros(m),
        },
    )
    kernel.initialise(problem.model, state)
    state.schedule[:] = (
        calibrate_schedule(problem, state) if None in (anneal.T_start, anneal.T_end) else (anneal.T_start, anneal.T_end)
    )
    if problem.coarse_steps > 0:  # calibrated on the true cost, run on the coarse exclusion map first
        kernel.recompute_exclusion(problem.coarse_model, state)
    return state


def scheduled_T_end(anneal: Any, physics: Physics) -> float:
    """The schedule's end temperature [W]: ``anneal.T_end``, or ``anneal.T_end_rel`` times the cost
    of one terminal segment of length R_supply (see :func:`calibrate_schedule`)."""
    if anneal.T_end is not None:
        return float(anneal.T_end)
    tables = cost_tables(physics)
    return anneal.T_end_rel * float(tables.volume[1] + tables.power[1]) * physics.supply_radius


def calibrate_schedule(problem: Problem, state: kernel.State) -> tuple[float, float]:
    """(T_start, T_end) [W] from the cost scale of the problem; configured values are kept.

    T_start: the temperature at which the uphill moves of an infinite-temperature random
    walk from ``state`` (swaps and bifurcation translations, measured on a copy with a
    copy of its generator: the run's random stream is untouched) are accepted with mean
    probability ``anneal.accept_start``, the usual criterion (Johnson et al. 1989).
    T_end: ``anneal.T_end_rel`` times the cost of one terminal segment of length R_supply,
    w(1) R_supply: well below it no uphill rearrangement of the finest branches survives,
    so colder steps would be wasted. T_start is raised to 10 T_end if it came out lower, and
    to ``anneal.T_start_min`` when set: the calibration reads the typical move, whose cost
    falls with N, while the barrier of a trunk through a cavity does not.
    """
    a = problem.config.anneal
    t_end = scheduled_T_end(a, problem.physics)
    if a.T_start is not None:
        return float(a.T_start), float(t_end)
    walker = restore_state(problem, state_arrays(state))
    uphill = np.empty(a.calibration_samples)
    uphill = uphill[: kernel.sample_uphill(problem.model, walker, a.calibration_samples, uphill)]
    t_start = 10.0 * t_end
    if uphill.size:
        # Mean acceptance exp(-dC/T) rises monotonically with T: bisect on log T.
        lo, hi = np.log(uphill.min()) - 10.0, np.log(uphill.max()) + 10.0
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.mean(np.exp(-uphill / np.exp(mid))) < a.accept_start else (lo, mid)
        t_start = max(t_start, float(np.exp(hi)))
    if a.T_start_min is not None:
        t_start = max(t_start, float(a.T_start_min))
    return t_start, float(t_end)


def model_at(problem: Problem, step: int) -> kernel.Model:
    """The kernel model the proposal at ``step`` runs on: before ``problem.coarse_steps`` the
    coarse exclusion map's (anneal.coarse_exclusion_*), else the true one's."""
    return problem.coarse_model if step < problem.coarse_steps else problem.model


def running_costs(problem: Problem, state: kernel.State) -> dict[str, float]:
    """The kernel's running sums (compensated), unscaled, plus the annealed total."""
    values = state.costs + state.compensation
    out = {name: float(values[i]) for i, name in enumerate(COST_TERMS)}
    out["total"] = total_cost(out, problem.physics)
    return out


def tree_of(problem: Problem, state: kernel.State) -> Tree:
    """A copy of the state's tree."""
    return Tree(
        state.parent.copy(),
        state.children.copy(),
        state.position.copy(),
        state.n_downstream.copy(),
        problem.physics.n_inlets,
    )


def tree_statistics(problem: Problem, tree: Tree) -> dict[str, float]:
    """Diagnostics of a final tree stored with the run (attrs ``statistics``).

    ``cavity_share``: the share of the length of the large vessels (r >= r_max/4) inside
    the tissue's cavities (:func:`vasc_pipeline.model.costs.cavity_share`); only for tissues
    whose exclusion domain has cavities (the heart).
    """
    if not problem.tissue.cavity.any():
        return {}
    share = cavity_share(tree.parent, tree.position, node_radii(tree, problem.physics), problem.tissue)
    return {"cavity_share": share}


def state_arrays(state: kernel.State) -> dict[str, np.ndarray]:
    """Copies of the state arrays a checkpoint must hold (no scratch space)."""
    return {name: getattr(state, name).copy() for name in CHECKPOINT_FIELDS}


def restore_state(problem: Problem, arrays: dict[str, np.ndarray], n_terminals: int | None = None) -> kernel.State:
    """A kernel state from checkpointed arrays; bit-identical continuation is guaranteed.

    ``n_terminals``: of a part of the tree (:mod:`vasc_pipeline.engine.parts`); default the tree's.
    """
    n = problem.physics.n_terminals if n_terminals is None else int(n_terminals)
    m = 2 * n
    dtypes = {name: _STATE_INT64.get(name, np.float64) for name in CHECKPOINT_FIELDS}
    dtypes["supply"] = supply_dtype(problem.physics.n_terminals)  # a part's is the whole tree's map
    fields = {name: np.ascontiguousarray(arrays[name], dtype=dtypes[name]).copy() for name in CHECKPOINT_FIELDS}
    state = kernel.State(
        **fields,
        scratch_mark=np.zeros(m, dtype=np.int64),
        scratch_stack=np.zeros(m, dtype=np.int64),
        scratch_pressure=np.zeros(m),
        scratch_drop_moment=np.zeros(m),
        scratch_cell_count=np.bincount(
            fields["cell_of"][fields["cell_of"] >= 0], minlength=int(np.prod(problem.model.cell_shape))
        ).astype(np.int64),
        scratch_shell_voxels=np.zeros(
            (n, kernel.shell_capacity(problem.model.supply_rho, problem.model.supply_shell_width), 3), dtype=np.int16
        ),
        scratch_shell_bands=np.zeros((n, kernel.SHELL_BANDS), dtype=np.int64),
        scratch_shell_frame=np.zeros((n, 4)),
    )
    if problem.model.pressure_on and n_terminals is None:  # a part's are its own model's (engine.parts)
        kernel.pressure_moments(problem.model, state)
    return state
