"""Terminal density under a two-region perfusion demand map (``tissue.demand_path``).

A 2 cm ball (``tissue=sphere``) whose half x > 0 has ``--ratio`` times the demand of the other
half, annealed with the default schedule (``anneal=fast``) at each N; one JSON line per (N, seed):
terminals per unit tissue volume in each half and their ratio, against the demand ratio, with
the run's time. The map is a Zarr array written once (1 mm voxels, sampled nearest voxel).

Usage: python benchmarks/demand_density.py [--sizes 300 1000] [--seeds 0 1] [--ratio 2] [--steps N]
       python benchmarks/demand_density.py --quick    # N = 24, 20 000 moves (seconds)
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import zarr

from vasc_pipeline import config, engine

H, LO = 1e-3, -0.03  # m: the map's voxel and its box [LO, -LO] on every axis


def write_map(path: Path, ratio: float) -> str:
    n = int(round(-2 * LO / H)) + 1
    x = LO + H * np.arange(n)
    arr = zarr.create_array(str(path), shape=(n, n, n), dtype="float32")
    arr[...] = np.broadcast_to(np.where(x > 0, ratio, 1.0), (n, n, n)).astype(np.float32)
    arr.attrs.update(voxel_size=H, origin=[LO] * 3)
    return str(path)


def measure(n: int, seed: int, demand: str, steps: int | None) -> dict:
    overrides = ["tissue=sphere", f"n_terminals={n}", f"tissue.demand_path={demand}"]
    if steps is not None:
        overrides.append(f"anneal.steps={steps}")
    cfg = config.compose(overrides)
    problem = engine.build_problem(cfg)
    t0 = time.perf_counter()
    result = engine.run(cfg, seed=seed)
    seconds = time.perf_counter() - t0
    tissue = problem.tissue
    idx = tissue.voxel_index(result.tree.position[1 : 1 + n])
    level = tissue.supply_target[idx[:, 0], idx[:, 1], idx[:, 2]]
    volume = {v: np.count_nonzero(tissue.supply_target == v) * tissue.voxel_size**3 for v in (1, 2)}
    density = {v: np.count_nonzero(level == v) / volume[v] for v in (1, 2)}
    return {
        "n_terminals": n,
        "seed": seed,
        "steps": int(result.steps),
        "terminals_low": int(np.count_nonzero(level == 1)),
        "terminals_high": int(np.count_nonzero(level == 2)),
        "density_ratio": round(float(density[2] / density[1]), 4),
        "supply_cost": result.costs["supply"],
        "wall_seconds": round(seconds, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[300, 1000])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--ratio", type=float, default=2.0)
    parser.add_argument("--steps", type=int, default=None, help="proposed moves (default: the schedule's)")
    parser.add_argument("--quick", action="store_true", help="N = 24, 20 000 moves: checks the script runs")
    args = parser.parse_args()
    if args.quick:
        args.sizes, args.seeds, args.steps = [24], [0], 20_000
    with tempfile.TemporaryDirectory() as tmp:
        demand = write_map(Path(tmp) / "demand.zarr", args.ratio)
        for n in args.sizes:
            for seed in args.seeds:
                row = measure(n, seed, demand, args.steps)
                print(json.dumps({"demand_ratio": args.ratio, **row}), flush=True)


if __name__ == "__main__":
    main()
