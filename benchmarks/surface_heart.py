"""The model heart as closed surfaces (``tissue=surface``) against the voxel heart (``tissue=heart``).

Writes the heart's outer surface and its two cavities as STL (marching cubes of its analytic
shapes, :func:`vasc_pipeline.model.tissue.surfaces.write_heart_surfaces`), reads them back at each
N and prints one JSON line per N: the voxelised myocardium and cavities of both and the voxels
where the two masks differ on the voxel heart's own grid; then, per seed, the final costs of a run
on each (the default config, ``anneal=fast``) and the LCA's share of the terminals. The surface
runs take the heart's voxel and exclusion grid (``tissue.voxel_size``, the heart group's
``tissue.exclusion_voxel_size``), so that the tissues differ only in the voxels the surfaces
place otherwise and in the heart's open base; a third run per seed, ``heart_closed_base``, is
the voxel heart with its base closed as the surfaces close it (its exclusion map computed without
``Tissue.open_boundary``), which tells the two differences apart.

Usage: python benchmarks/surface_heart.py [--sizes 200] [--seeds 0 1] [--steps N]
       python benchmarks/surface_heart.py --quick    # N = 20, 5000 moves, coarse surfaces (seconds)
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import tempfile
from pathlib import Path
from unittest import mock

import numpy as np

from vasc_pipeline import config, engine, kernel, tissue
from vasc_pipeline.model.tissue import grid, surfaces

engine_run = importlib.import_module("vasc_pipeline.engine.run")  # the module: engine.run is its function


def compare_grids(n: int, organ: Path, cavities: list[Path], inlets: Path) -> dict:
    heart = tissue.build_tissue("heart", n)
    keys = {"path": str(organ), "cavity_paths": [str(c) for c in cavities], "inlets_path": str(inlets)}
    surface = tissue.build_tissue("surface", n, **keys)
    same_voxel = tissue.build_tissue("surface", n, voxel_size=heart.voxel_size, **keys)
    differ = int(np.count_nonzero(same_voxel.mask != heart.mask)) if same_voxel.shape == heart.shape else None
    return {
        "n_terminals": n,
        "myocardium_ml": {"heart": heart.measure * 1e6, "surface": surface.measure * 1e6},
        "myocardium_rel": surface.measure / heart.measure - 1.0,
        "cavities_ml": {
            "heart": float(heart.cavity.sum() * heart.voxel_size**3 * 1e6),
            "surface": float(surface.cavity.sum() * surface.voxel_size**3 * 1e6),
        },
        "voxel_mm": {"heart": heart.voxel_size * 1e3, "surface": surface.voxel_size * 1e3},
        "mask_voxels_differing_on_the_heart_grid": differ,
        "heart_tissue_voxels": heart.n_tissue_voxels,
        "origin_offset_mm": ((same_voxel.origin - heart.origin) * 1e3).tolist(),
    }


def closed_base(problem):
    """``problem`` (the heart's) with its exclusion map computed as if the base plane were a surface."""
    t = problem.tissue
    h = t.exclusion_grid.voxel_size
    twin = tissue.build_tissue("heart", problem.physics.n_terminals, voxel_size=h) if h != t.voxel_size else t
    closed = grid.ExclusionGrid(grid.exclusion_distance(twin.exclusion, None, 3), twin.origin, h)
    model = problem.model._replace(**kernel.exclusion_fields(closed))
    coarse = problem.coarse_model
    if coarse is not None:
        factor = problem.config.anneal.coarse_exclusion_factor
        coarse = model._replace(**kernel.exclusion_fields(closed.coarsened(factor)))
    return dataclasses.replace(problem, model=model, coarse_model=coarse)


def run_costs(overrides: list[str], seed: int, close_base: bool = False) -> dict:
    build = engine_run.build_problem
    with mock.patch.object(engine_run, "build_problem", (lambda c: closed_base(build(c))) if close_base else build):
        result = engine.run(config.compose(overrides), seed=seed)
    n = result.tree.n_downstream[:2]
    c = result.costs
    return {
        "vascular_W": c["volume"] + c["power"],
        "supply": c["supply"],
        "exclusion": c["exclusion"],
        "total": c["total"],
        "lca_share": float(n[0] / n.sum()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[200])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--steps", type=int, default=None, help="proposed moves (default: the schedule's)")
    parser.add_argument("--spacing", type=float, default=6e-4, help="marching cubes' sampling [m]")
    parser.add_argument("--quick", action="store_true", help="N = 20, 5000 moves, 2 mm surfaces: checks the script")
    args = parser.parse_args()
    if args.quick:
        args.sizes, args.seeds, args.steps, args.spacing = [20], [0], 5000, 2e-3
    with tempfile.TemporaryDirectory() as tmp:
        organ, cavities, inlets = surfaces.write_heart_surfaces(Path(tmp) / "heart.stl", spacing=args.spacing)
        for n in args.sizes:
            row = compare_grids(n, organ, cavities, inlets)
            steps = [f"anneal.steps={args.steps}"] if args.steps else []
            heart = tissue.build_tissue("heart", n)
            surface = [
                "tissue=surface",
                f"tissue.voxel_size={heart.voxel_size!r}",
                f"tissue.exclusion_voxel_size={config.HEART_EXCLUSION_VOXEL_SIZE!r}",
                f"tissue.path={organ}",
                f"tissue.cavity_paths=[{cavities[0]},{cavities[1]}]",
                f"tissue.inlets_path={inlets}",
                "tissue.organ=heart",
            ]
            for seed in args.seeds:
                row[f"seed{seed}"] = {
                    "heart": run_costs([f"n_terminals={n}", *steps], seed),
                    "heart_closed_base": run_costs([f"n_terminals={n}", *steps], seed, close_base=True),
                    "surface": run_costs([f"n_terminals={n}", *steps, *surface], seed),
                }
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
