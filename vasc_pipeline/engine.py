"""Grow one optimised tree: build the problem, initialise, anneal in blocks, report.

Usable without Hydra or Dask::

    from vasc_pipeline import config, engine
    result = engine.run(config.compose(["tissue=plane2d", "anneal.steps=200000"]), seed=1)
    result.costs["total"], result.costs_recomputed["total"]

The anneal loop is Python (schedule blocks, trace, progress); each block is one call of the
jitted kernel (:func:`vasc_pipeline.kernel.anneal_block`), so a caller can checkpoint
between blocks with :func:`state_arrays` / :func:`restore_state`.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable

import numpy as np

from . import kernel
from .config import RunConfig, scheduled_steps, to_run_config, validate
from .costs import COST_TERMS, ActiveTerms, active_terms, full_costs
from .physics import Physics, cost_tables, supply_radius
from .rng import seed_state
from .tissue import Tissue, build_tissue
from .tree import Tree, TreeError, load_terminal_sites, random_tree

__all__ = ["Problem", "RunResult", "build_problem", "initial_state", "run_block", "running_costs", "tree_of",
           "state_arrays", "restore_state", "run", "CHECKPOINT_FIELDS"]

# State fields saved in a checkpoint (everything but scratch space).
CHECKPOINT_FIELDS = tuple(f for f in kernel.State._fields if not f.startswith("scratch_"))


@dataclass
class Problem:
    """Everything fixed for a run: config, physics, tissue, active terms and the kernel's Model."""

    config: RunConfig
    physics: Physics
    tissue: Tissue
    terms: ActiveTerms
    model: kernel.Model
    total_steps: int
    sites: np.ndarray | None = None


@dataclass
class RunResult:
    """The outcome of :func:`run`: the final tree and its costs (SI, W for costs)."""

    tree: Tree
    problem: Problem
    seed: int
    costs: dict[str, float]
    costs_recomputed: dict[str, float]
    steps: int
    wall_seconds: float
    trace: dict[str, np.ndarray] = field(repr=False)
    counters: np.ndarray = field(repr=False)

    @property
    def radius(self) -> np.ndarray:
        """Radius [m] of the segment ending at every node (0 at inlets)."""
        return node_radii(self.tree, self.problem.physics)


def node_radii(tree: Tree, physics: Physics) -> np.ndarray:
    radius = physics.radius(tree.n_downstream)
    radius[: tree.n_inlets] = 0.0
    return radius


def build_problem(config: Any) -> Problem:
    """Validate a config and build its tissue, physics and kernel model."""
    cfg = validate(to_run_config(config))
    params = {k: v for k, v in asdict(cfg.tissue).items() if k not in ("name", "q_required")}
    n = cfg.n_terminals
    tissue = build_tissue(cfg.tissue.name, n, **params)
    sites = None
    if cfg.terminals.path:
        sites = load_terminal_sites(cfg.terminals.path, tissue)
        if len(sites) != n:
            raise TreeError(f"terminals.path holds {len(sites)} sites but n_terminals = {n}; set n_terminals={len(sites)}")
    k = len(tissue.inlets)
    if n < k:
        raise TreeError(f"n_terminals must be >= the number of inlets ({k}) of tissue {tissue.name!r}, got {n}")
    p = cfg.physics
    physics = Physics(
        n_terminals=n, n_inlets=k, gamma=p.gamma, inlet_radius=p.inlet_radius, total_flow=p.total_flow, m_b=p.m_b,
        viscosity=p.viscosity,
        supply_radius=supply_radius(n, tissue.measure, tissue.ndim, cfg.tissue.q_required, p.total_flow),
        r_cutoff=p.r_cutoff, A_wv=p.A_wv, A_o=p.A_o, A_p=p.A_p, A_s=p.A_s, pressure_inlet=p.pressure_inlet,
        pressure_terminal=p.pressure_terminal)
    terms = active_terms(physics, cfg.terminals.fixed)
    w_o, w_p, w_s = physics.weights
    lo, hi = tissue.bounds
    total_steps = scheduled_steps(cfg)
    model = kernel.Model(
        n_inlets=k, n_terminals=n, tables=cost_tables(physics).array,
        mask=tissue.mask, distance=tissue.distance, origin=tissue.origin,
        voxel_size=float(tissue.voxel_size), box_lo=lo, box_hi=hi,
        supply_rho=physics.supply_radius / tissue.voxel_size,
        w_exclusion=w_o, w_pressure=w_p, w_supply=w_s,
        supply_on=terms.supply, exclusion_on=terms.exclusion, pressure_on=terms.pressure,
        move_terminals=not cfg.terminals.fixed, planar=tissue.ndim == 2,
        pressure_inlet=p.pressure_inlet, pressure_terminal=p.pressure_terminal,
        T_start=float(cfg.anneal.T_start), T_end=float(cfg.anneal.T_end), total_steps=float(total_steps),
        p_swap=float(cfg.anneal.p_swap))
    return Problem(cfg, physics, tissue, terms, model, total_steps, sites)


def initial_state(problem: Problem, seed: int) -> kernel.State:
    """The random initial tree of (config, seed) with its caches and running sums filled."""
    rng = seed_state(seed)
    tree = random_tree(problem.tissue, problem.physics.n_terminals, rng, problem.sites)
    r_supply = problem.physics.supply_radius
    anneal = problem.config.anneal
    m = tree.n_nodes
    state = kernel.State(
        parent=tree.parent, children=tree.children, position=tree.position, n_downstream=tree.n_downstream,
        seg_length=np.zeros(m), seg_exclusion=np.zeros(m), supply=np.zeros(problem.tissue.shape, dtype=np.int32),
        costs=np.zeros(len(COST_TERMS)), compensation=np.zeros(len(COST_TERMS)), rng=rng,
        counters=np.zeros(kernel.N_COUNTERS, dtype=np.int64),
        step_size=np.array([anneal.step_terminal * r_supply, anneal.step_bifurcation * r_supply]),
        scratch_mark=np.zeros(m, dtype=np.int64), scratch_stack=np.zeros(m, dtype=np.int64),
        scratch_pressure=np.zeros(m))
    kernel.initialise(problem.model, state)
    return state


def run_block(problem: Problem, state: kernel.State, n_steps: int) -> None:
    """Propose ``n_steps`` moves (in place). The GIL is released for the whole block."""
    kernel.anneal_block(problem.model, state, int(n_steps))


def running_costs(problem: Problem, state: kernel.State) -> dict[str, float]:
    """The kernel's running sums (compensated), unscaled, plus the annealed total."""
    values = state.costs + state.compensation
    out = {name: float(values[i]) for i, name in enumerate(COST_TERMS)}
    w_o, w_p, w_s = problem.physics.weights
    out["total"] = (out["volume"] + out["power"]) + w_o * out["exclusion"] + w_p * out["pressure"] \
        + w_s * out["supply"]
    return out


def tree_of(problem: Problem, state: kernel.State) -> Tree:
    """A copy of the state's tree."""
    return Tree(state.parent.copy(), state.children.copy(), state.position.copy(), state.n_downstream.copy(),
                problem.physics.n_inlets)


def state_arrays(state: kernel.State) -> dict[str, np.ndarray]:
    """Copies of the state arrays a checkpoint must hold (no scratch space)."""
    return {name: getattr(state, name).copy() for name in CHECKPOINT_FIELDS}


def restore_state(problem: Problem, arrays: dict[str, np.ndarray]) -> kernel.State:
    """A kernel state from checkpointed arrays; bit-identical continuation is guaranteed."""
    m = 2 * problem.physics.n_terminals
    dtypes = {"parent": np.int64, "children": np.int64, "n_downstream": np.int64, "supply": np.int32,
              "rng": np.uint64, "counters": np.int64}
    fields = {name: np.ascontiguousarray(arrays[name], dtype=dtypes.get(name, np.float64)).copy()
              for name in CHECKPOINT_FIELDS}
    return kernel.State(**fields, scratch_mark=np.zeros(m, dtype=np.int64), scratch_stack=np.zeros(m, dtype=np.int64),
                        scratch_pressure=np.zeros(m))


class Trace:
    """Cost trace records, one per block: step, temperature, cost terms, acceptance."""

    names = ("step", "temperature", *COST_TERMS, "total", "acceptance")

    def __init__(self) -> None:
        self.rows: list[tuple] = []

    def record(self, problem: Problem, state: kernel.State, proposed: int, accepted: int) -> None:
        step = int(state.counters[kernel.COUNTER_STEP])
        costs = running_costs(problem, state)
        temp = kernel.temperature(problem.model, max(step - 1, 0))
        self.rows.append((step, temp, *(costs[c] for c in COST_TERMS), costs["total"],
                          accepted / proposed if proposed else 0.0))

    def arrays(self) -> dict[str, np.ndarray]:
        data = np.array(self.rows, dtype=np.float64).reshape(-1, len(self.names))
        out = {name: data[:, i] for i, name in enumerate(self.names)}
        out["step"] = out["step"].astype(np.int64)
        return out


def accepted_moves(state: kernel.State) -> int:
    c = state.counters
    return int(c[kernel.COUNTER_TERMINAL_ACCEPTED] + c[kernel.COUNTER_BIFURCATION_ACCEPTED]
               + c[kernel.COUNTER_SWAP_ACCEPTED])


def run(config: Any, seed: int | None = None, *, block_steps: int | None = None,
        progress: Callable[[int, int, dict], None] | None = None) -> RunResult:
    """Grow one tree from (config, seed) and return it with running and recomputed costs.

    ``seed`` defaults to ``config.seed``. ``block_steps`` (default ``anneal.trace_every``)
    sets the trace resolution; it does not change the result. ``progress(step, total,
    costs)`` is called after every block.
    """
    start = time.perf_counter()
    problem = build_problem(config)
    seed = problem.config.seed if seed is None else int(seed)
    state = initial_state(problem, seed)
    block = int(block_steps or problem.config.anneal.trace_every)
    trace = Trace()
    trace.record(problem, state, 0, 0)
    total = problem.total_steps
    while state.counters[kernel.COUNTER_STEP] < total:
        n = min(block, total - int(state.counters[kernel.COUNTER_STEP]))
        before = accepted_moves(state)
        run_block(problem, state, n)
        trace.record(problem, state, n, accepted_moves(state) - before)
        if progress is not None:
            progress(int(state.counters[kernel.COUNTER_STEP]), total, running_costs(problem, state))
    tree = tree_of(problem, state)
    return RunResult(
        tree=tree, problem=problem, seed=seed, costs=running_costs(problem, state),
        costs_recomputed=full_costs(tree, problem.tissue, problem.physics, problem.terms),
        steps=int(state.counters[kernel.COUNTER_STEP]), wall_seconds=time.perf_counter() - start,
        trace=trace.arrays(), counters=state.counters.copy())
