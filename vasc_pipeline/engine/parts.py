"""One tree annealed in parts: a phase of the anneal run as independent anneals of subtrees.

A phase cuts the tree into ``k`` parts, each a set of whole subtrees of about N/k terminals
(:func:`cut`), and gives every tissue voxel to the part of its nearest terminal
(:func:`part_regions`). Each part is then annealed on its own (:func:`anneal_parts`), with
exactly the moves of the whole tree's kernel, on a copy of the tree restricted to its
subtrees, while everything else is frozen:

- the subtrees' roots hang from *pseudo-inlets*, their parents in the whole tree, whose
  positions are fixed: each root keeps its terminal count (a swap between two of a part's
  subtrees must keep their counts), so no segment above the roots changes cost;
- a terminal may move only while its supply sphere stays inside its part's region: its
  part's model marks as tissue only the voxels where that holds, and a terminal outside them
  is frozen (a *border* terminal). Regions are disjoint, so no voxel's supply count changes
  in two parts.

Every cost term but C_p is then a sum over segments or over voxels that the parts change
in disjoint pieces: the parts' changes add up to the whole tree's, exactly (C_p, the
terminal pressures, couples every segment: it must be off, ``physics.A_p = 0``). Within a
part the moves are the kernel's own, so detailed balance holds in the part's phase; the
cut changes from phase to phase, so every terminal and segment is free in some phase.

Each part draws from its own generator, seeded from (phase seed, part index), so the result
is a function of the tree, the phase seed and ``k``, not of how many workers ran the parts or
in which order they finished (``map`` is any order-preserving map: the builtin, a thread
pool's, as the kernel releases the GIL, or a cluster's).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .. import kernel
from ..model.rng import next_double, seed_state
from .problem import Problem, restore_state

__all__ = [
    "Part",
    "cut",
    "part_regions",
    "make_parts",
    "part_model",
    "part_state",
    "anneal_parts",
    "anneal_part",
    "merge_parts",
    "phase_ends",
    "run_phase",
]


@dataclass
class Part:
    """One part of a phase: its nodes in the part state's order and where its terminals may be.

    ``nodes``: global node ids, pseudo-inlets first (the parents of the subtree roots
    ``roots``, one for each), then the terminals, then the bifurcations of the subtrees;
    ``n_inlets`` and ``n_terminals`` count the first two groups. ``mask``: uint8 on the
    supply grid, 1 where a terminal's supply sphere lies in the part's region (and the
    voxel is tissue).
    """

    nodes: np.ndarray
    roots: np.ndarray
    n_inlets: int
    n_terminals: int
    mask: np.ndarray


def _subtree_terminals(children: np.ndarray, root: int) -> list[int]:
    out, stack = [], [root]
    while stack:
        node = stack.pop()
        c0, c1 = children[node]
        if c0 < 0:
            out.append(node)
        else:
            stack.extend((c1, c0))
    return out


def cut(
    parent, children, n_downstream, position, n_inlets: int, k: int, shift: np.ndarray, leaves: bool = False
) -> list[np.ndarray]:
    """The roots of whole subtrees grouped into ``k`` parts of about N/k terminals each.

    The largest subtree is split into its two children until none holds more than N/(4k)
    terminals; the subtrees are then ordered along a Morton curve of their terminals' centroid
    (the cloud placed at ``shift`` in [0, 1)^3 within a grid twice its size, so that the cut
    moves from phase to phase) and the curve is cut into ``k`` runs of about N/k terminals.
    Returns one int64 array of roots per part, in curve order.
    """
    n_terminals = int(sum(n_downstream[children[i, 0]] for i in range(n_inlets)))
    limit = 1 if leaves else max(1, n_terminals // (4 * k))
    roots = [int(children[i, 0]) for i in range(n_inlets)]
    final = []
    while roots:
        r = roots.pop()
        if n_downstream[r] > limit and children[r, 0] >= 0:
            roots.extend((int(children[r, 0]), int(children[r, 1])))
        else:
            final.append(r)
    centroids = np.array([position[_subtree_terminals(children, r)].mean(axis=0) for r in final])
    lo, hi = centroids.min(axis=0), centroids.max(axis=0)
    cells = 1024
    # the cloud fills half of each axis of the curve's grid, placed at ``shift`` along it
    grid = np.floor(((centroids - lo) / np.maximum(hi - lo, 1e-300) + shift) * (cells / 2 - 1)).astype(np.int64)
    keys = np.zeros(len(final), dtype=np.int64)
    for bit in range(10):
        for axis in range(3):
            keys |= ((grid[:, axis] >> bit) & 1) << (3 * bit + axis)
    order = np.lexsort((np.array(final), keys))
    counts = np.cumsum([n_downstream[final[i]] for i in order])
    part_of = np.minimum((counts - 1) * k // n_terminals, k - 1)
    return [np.array([final[i] for i in order[part_of == p]], dtype=np.int64) for p in range(k)]


def part_regions(problem: Problem, terminal_position: np.ndarray, terminal_part: np.ndarray, k: int) -> np.ndarray:
    """uint8 (k, nz, ny, nx): per part, the supply-grid voxels where a terminal's supply sphere
    lies wholly in the part's region (the tissue voxels whose nearest terminal is the part's,
    and the voxels outside the tissue, whose counts no sphere changes) and which are tissue.

    A terminal at x covers the voxel centres within ρ (the supply radius, voxels) of x, and x
    lies within √3/2 of its voxel's centre; so a voxel more than ρ + 1 from every voxel of
    other regions is safe.
    """
    t = problem.tissue
    tissue = t.mask != 0
    centres = np.argwhere(tissue)  # (z, y, x) indices
    _, nearest = cKDTree(terminal_position).query(t.origin + t.voxel_size * centres[:, ::-1])
    region = np.full(t.shape, -1, dtype=np.int64)  # -1: not tissue, no count to share
    region[tissue] = terminal_part[nearest]
    reach = problem.model.supply_rho + 1.0
    out = np.zeros((k, *t.shape), dtype=np.uint8)
    for p in range(k):
        out[p] = (ndimage.distance_transform_edt((region == p) | ~tissue) > reach) & tissue
    return out


def make_parts(problem: Problem, state: kernel.State, k: int, shift: np.ndarray, leaves: bool = False) -> list[Part]:
    """The phase's ``k`` parts of the tree in ``state`` (:func:`cut`, :func:`part_regions`);
    ``leaves``: parts of terminals alone, grouped by position, each hanging from its parent."""
    model = problem.model
    roots = cut(state.parent, state.children, state.n_downstream, state.position, model.n_inlets, k, shift, leaves)
    first_terminal = model.n_inlets
    first_bifurcation = model.n_inlets + model.n_terminals
    terminal_part = np.full(model.n_terminals, -1, dtype=np.int64)
    members = []
    for p, part_roots in enumerate(roots):
        nodes, stack = [], list(part_roots)
        while stack:
            node = stack.pop()
            nodes.append(node)
            if state.children[node, 0] >= 0:
                stack.extend(state.children[node])
        nodes = np.sort(np.array(nodes, dtype=np.int64))
        terminals = nodes[nodes < first_bifurcation]
        terminal_part[terminals - first_terminal] = p
        # one pseudo-inlet per root, even where two roots share a parent (an inlet has one child)
        members.append((part_roots, terminals, nodes[nodes >= first_bifurcation]))
    masks = part_regions(problem, state.position[first_terminal:first_bifurcation], terminal_part, k)
    return [
        Part(np.concatenate([state.parent[r], t, b]), r, len(r), len(t), masks[p])
        for p, (r, t, b) in enumerate(members)
    ]


def part_model(model: kernel.Model, part: Part) -> kernel.Model:
    """The kernel model of a part: its node counts, its terminals' tissue, counts kept between
    its subtrees; the whole tree's tables, grids, weights and schedule."""
    return model._replace(n_inlets=part.n_inlets, n_terminals=part.n_terminals, mask=part.mask, fixed_inlet_counts=True)


def part_state(problem: Problem, model: kernel.Model, state: kernel.State, part: Part, rng: np.ndarray) -> kernel.State:
    """A kernel state holding the part's subtrees (renumbered in ``part.nodes`` order), the
    whole tree's supply map and C_s, the whole tree's step count and step sizes, and ``rng``."""
    k_in = part.n_inlets
    own = part.nodes[k_in:]
    local = np.full(state.parent.size, -1, dtype=np.int64)
    local[own] = np.arange(k_in, part.nodes.size)
    parent = np.full(part.nodes.size, -1, dtype=np.int64)
    parent[k_in:] = local[state.parent[own]]
    children = np.full((part.nodes.size, 2), -1, dtype=np.int64)
    children[k_in:] = np.where(state.children[own] >= 0, local[np.maximum(state.children[own], 0)], -1)
    for j, root in enumerate(local[part.roots]):  # pseudo-inlet j: root j's parent in the whole tree
        parent[root] = j
        children[j, 0] = root
    m = part.nodes.size
    arrays = {
        "parent": parent,
        "children": children,
        "position": state.position[part.nodes],
        "n_downstream": state.n_downstream[part.nodes],
        "seg_length": np.zeros(m),
        "seg_exclusion": np.zeros(m),
        "supply": state.supply,
        "costs": np.zeros_like(state.costs),
        "compensation": np.zeros_like(state.compensation),
        "rng": rng,
        "counters": state.counters,
        "step_size": state.step_size,
        "schedule": state.schedule,
        "cell_of": np.full(m, -1, dtype=np.int64),
        "cell_head": np.full_like(state.cell_head, -1),
        "cell_next": np.full(m, -1, dtype=np.int64),
        "cell_prev": np.full(m, -1, dtype=np.int64),
    }
    sub = restore_state(problem, arrays, n_terminals=part.n_terminals)
    kernel.initialise_segments(part_model(model, part), sub)
    sub.costs[kernel.SUPPLY] = state.costs[kernel.SUPPLY] + state.compensation[kernel.SUPPLY]
    return sub


def anneal_parts(
    problem: Problem,
    model: kernel.Model,
    state: kernel.State,
    parts: list[Part],
    n_steps: int,
    phase_seed: int,
    map: Callable = map,
) -> list[kernel.State]:
    """Anneal every part on ``model`` (the whole tree's, or its coarse twin) for its share of
    ``n_steps`` proposals (by node count), from the whole tree's step count on; returns the
    parts' final states in part order. ``state`` is not changed."""
    total_nodes = sum(p.nodes.size for p in parts)
    jobs = []
    for index, part in enumerate(parts):
        rng = seed_state(int(np.random.SeedSequence([phase_seed, index]).generate_state(1, np.uint64)[0]))
        sub = part_state(problem, model, state, part, rng)
        jobs.append((part_model(model, part), sub, int(n_steps) * part.nodes.size // total_nodes))
    return list(map(anneal_part, jobs))


def anneal_part(job: tuple[kernel.Model, kernel.State, int]) -> kernel.State:
    """One part's anneal, ``(model, state, n_steps)`` -> the state: the task a worker runs."""
    model, sub, n_steps = job
    kernel.anneal_block(model, sub, n_steps)
    return sub


# The counters the parts add to the whole tree's (the step count and the adaptation windows
# are the whole tree's own).
_SUMMED_COUNTERS = [
    kernel.COUNTER_TERMINAL_PROPOSED,
    kernel.COUNTER_TERMINAL_ACCEPTED,
    kernel.COUNTER_BIFURCATION_PROPOSED,
    kernel.COUNTER_BIFURCATION_ACCEPTED,
    kernel.COUNTER_SWAP_PROPOSED,
    kernel.COUNTER_SWAP_ACCEPTED,
    kernel.COUNTER_LOCAL_SWAP_PROPOSED,
]


def merge_parts(model: kernel.Model, state: kernel.State, parts: list[Part], results: list[kernel.State]) -> None:
    """Write the parts' subtrees back into ``state``, add their proposals to its counters and
    take the mean of their step sizes (by node count), then recompute its caches and sums on
    ``model`` (the supply map and every running sum from scratch: the merged state is exact)."""
    step0 = int(state.counters[kernel.COUNTER_STEP])
    counters = state.counters.copy()
    step_size = np.zeros(2)
    for part, sub in zip(parts, results):
        own = part.nodes[part.n_inlets :]
        state.position[own] = sub.position[part.n_inlets :]
        state.parent[own] = part.nodes[sub.parent[part.n_inlets :]]
        kids = sub.children[part.n_inlets :]
        state.children[own] = np.where(kids >= 0, part.nodes[np.maximum(kids, 0)], -1)
        state.n_downstream[own] = sub.n_downstream[part.n_inlets :]
        # A swap may have hung another of the part's subtrees from a pseudo-inlet: the parents
        # outside the part take the children their pseudo-inlets ended with, slot by slot.
        now = dict(zip(part.roots.tolist(), part.nodes[sub.children[: part.n_inlets, 0]].tolist()))
        for g in np.unique(part.nodes[: part.n_inlets]):
            state.children[g] = [now.get(c, c) for c in state.children[g]]
        counters[_SUMMED_COUNTERS] += sub.counters[_SUMMED_COUNTERS] - state.counters[_SUMMED_COUNTERS]
        counters[kernel.COUNTER_STEP] += int(sub.counters[kernel.COUNTER_STEP]) - step0
        step_size += part.nodes.size * sub.step_size
    state.counters[:] = counters
    state.step_size[:] = step_size / sum(p.nodes.size for p in parts)
    kernel.initialise(model, state)


def phase_ends(problem: Problem) -> np.ndarray:
    """The global step at which each phase of the parts' anneal ends: ``anneal.part_phases``
    equal shares of the tree anneal (after the packing phase), and the end of the coarse
    exclusion map's phase, so that no phase straddles a change of model."""
    a = problem.config.anneal
    pack, total = int(problem.model.pack_steps), int(problem.total_steps)
    ends = pack + (total - pack) * np.arange(1, a.part_phases + 1, dtype=np.int64) // a.part_phases
    if pack < problem.coarse_steps < total:
        ends = np.union1d(ends, [problem.coarse_steps])
    return np.unique(ends[ends > pack])


def run_phase(problem: Problem, state: kernel.State, n_steps: int, map: Callable = map) -> None:
    """One phase of ``n_steps`` proposals from the state's step on, in place: ``anneal.part_share``
    of them in parts, half in parts of whole subtrees (where a swap or a bifurcation may move;
    their terminals are mostly border terminals, a subtree's territory being rarely compact),
    half in parts of terminals grouped by place, each hanging from its fixed parent (where
    terminals move and trade parents); each cut's shift and its parts' seeds drawn from the
    whole tree's generator, ``map`` running the parts; then the rest on the whole tree
    (:func:`vasc_pipeline.engine.run_block`)."""
    from .run import run_block

    a = problem.config.anneal
    step = int(state.counters[kernel.COUNTER_STEP])
    model = problem.coarse_model if step < problem.coarse_steps else problem.model
    for leaves in (False, True):  # subtrees (their bifurcations and topology), then terminals by place
        shift = np.array([next_double(state.rng) for _ in range(3)])
        phase_seed = int(next_double(state.rng) * 2.0**53)
        parts = make_parts(problem, state, a.parts, shift, leaves)
        results = anneal_parts(problem, model, state, parts, int(n_steps * a.part_share) // 2, phase_seed, map)
        merge_parts(model, state, parts, results)
    rest = step + int(n_steps) - int(state.counters[kernel.COUNTER_STEP])
    if rest > 0:
        run_block(problem, state, rest)
