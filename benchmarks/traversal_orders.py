"""What a traversal waits on: the same segments walked in orders that warm the cache, the
branch predictor, both or neither.

A hot tree's segments (its own, and as many with each node re-paired to a random parent
position) are taken from a ``fast`` trajectory (``--run-budget`` times the default budget, run
to ``--at`` of its moves from the seed-0 tree, as ``kernel_profile.py`` reaches its states)
and traversed with ``kernel.exclusion._traverse`` four times each, in four orders:

- ``cold``: the whole shuffled list four times over; neither the segment's voxels nor its
  walk's branch pattern is left from its previous traversal.
- ``warm``: each segment four times in a row; the last three find its voxels in L1/L2 and
  the branch predictor trained on its axis-step pattern.
- ``jittered_warm``: each segment four times in a row, each time translated by up to half a
  voxel along each axis: the same length, nearly the same voxels (cache warm), another
  step pattern (predictor cold).
- ``jittered_cold``: the translated segments in the cold order; beside ``cold``, it shows
  that translation alone changes nothing.

So jittered_cold − jittered_warm (the same segments, in two orders) estimates the time spent
waiting on the depth map, jittered_warm − warm what the predictor's mispredictions of the
axis choice cost; both are given as shares of jittered_cold. One JSON line per N with
the median ns per segment of each order over ``--rounds`` alternating rounds (thread time).

Usage: python benchmarks/traversal_orders.py [--sizes 1000 6000] [--at 0.4] [--run-budget 0.01] [--rounds 9]
       python benchmarks/traversal_orders.py --quick    # N = 40, seconds (run by the tests)
"""

from __future__ import annotations

import argparse
import json
import time

import numba
import numpy as np
from kernel_throughput import trajectory_problem

from vasc_pipeline import engine, kernel

ORDERS = ("cold", "warm", "jittered_warm", "jittered_cold")
REPEATS = 4


@numba.njit(nogil=True)
def traverse_all(depth_index, depth_values, origin, voxel_size, p0, p1, out):
    for k in range(p0.shape[0]):
        out[k] = kernel.exclusion._traverse(
            depth_index,
            depth_values,
            origin[0],
            origin[1],
            origin[2],
            voxel_size,
            p0[k, 0],
            p0[k, 1],
            p0[k, 2],
            p1[k, 0],
            p1[k, 1],
            p1[k, 2],
            np.inf,
            kernel.PREFETCH_LEAD,
        )


def hot_segments(n_terminals: int, at: float, run_budget: float, rng):
    """(model, start points, end points) of a tree ``at`` of the way along a ``fast`` trajectory, shuffled."""
    problem, steps, _ = trajectory_problem(["tissue=heart", f"n_terminals={n_terminals}", "anneal=fast"], run_budget)
    state = engine.initial_state(problem, seed=0)
    engine.run_block(problem, state, round(at * steps))
    pos, parent = state.position, state.parent
    nodes = np.flatnonzero(parent >= 0)
    start = np.concatenate([pos[parent[nodes]], pos[parent[rng.permutation(nodes)]]])
    end = np.concatenate([pos[nodes], pos[nodes]])
    order = rng.permutation(len(start))
    return problem.model, start[order], end[order]


def segment_orders(start, end, voxel_size: float, rng) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The four orders' (start, end) arrays, each segment ``REPEATS`` times."""
    n = len(start) * REPEATS
    # One shift for both ends: the length, hence the expected voxel count, is kept; moving
    # the ends independently lengthens short segments and inflates the jittered times.
    shift = rng.uniform(-0.5, 0.5, (n, 3)) * voxel_size
    over, in_a_row = (lambda a: np.tile(a, (REPEATS, 1))), (lambda a: np.repeat(a, REPEATS, axis=0))
    orders = {
        "cold": (over(start), over(end)),
        "warm": (in_a_row(start), in_a_row(end)),
        "jittered_warm": (in_a_row(start) + shift, in_a_row(end) + shift),
        "jittered_cold": (over(start) + shift, over(end) + shift),
    }
    return {name: (np.ascontiguousarray(a), np.ascontiguousarray(b)) for name, (a, b) in orders.items()}


def measure(n_terminals: int, at: float, run_budget: float, rounds: int) -> dict:
    rng = np.random.default_rng(1)
    model, start, end = hot_segments(n_terminals, at, run_budget, rng)
    origin = np.asarray(model.origin)
    orders = segment_orders(start, end, model.voxel_size, rng)
    out = np.empty(len(start) * REPEATS)
    traverse_all(model.depth_index, model.depth_values, origin, model.voxel_size, start[:2], end[:2], out[:2])
    times = {name: [] for name in ORDERS}
    for r in range(rounds):
        for name in ORDERS if r % 2 == 0 else ORDERS[::-1]:
            p0, p1 = orders[name]
            t = time.thread_time()
            traverse_all(model.depth_index, model.depth_values, origin, model.voxel_size, p0, p1, out)
            times[name].append((time.thread_time() - t) / len(p0) * 1e9)
    median = {name: round(float(np.median(v))) for name, v in times.items()}
    return {
        "n_terminals": n_terminals,
        "at": at,
        "segments": len(start),
        "ns_per_segment": median,
        "memory_share": round((median["jittered_cold"] - median["jittered_warm"]) / median["jittered_cold"], 3),
        "predictor_share": round((median["jittered_warm"] - median["warm"]) / median["jittered_cold"], 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 6000])
    parser.add_argument("--at", type=float, default=0.4, help="share of the trajectory's moves run first")
    parser.add_argument("--run-budget", type=float, default=0.01, help="the trajectory's budget, times the default")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--quick", action="store_true", help="N = 40, 3 rounds")
    args = parser.parse_args()
    if args.quick:
        args.sizes, args.rounds, args.run_budget = [40], 3, 0.001
    for n in args.sizes:
        print(json.dumps(measure(n, args.at, args.run_budget, args.rounds)), flush=True)


if __name__ == "__main__":
    main()
