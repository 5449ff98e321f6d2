"""Grow svVascularize's tree in our heart and export its segments (run in the svv venv).

Run in the SEPARATE svv venv (svv 0.0.57 needs numpy < 2; never in our env), after
``export_heart.py`` wrote ``heart_N<N>.npz``:

    python3 -m venv /tmp/svv-venv && /tmp/svv-venv/bin/pip install svv     # svv 0.0.57
    SVV_TELEMETRY_DISABLED=1 nice -n 10 /tmp/svv-venv/bin/python \
        studies/2026-12-02_svv/grow_svv.py --n 1000 --out /tmp/svv_study [--single]
    python studies/2026-12-02_svv/grow_svv.py --dry-run [--n 1000 ...]   # any env: the plan, svv not imported

Steps (each timed, the times written to ``svv_N<N>.json``):

1. the surface: ``skimage.measure.marching_cubes`` on our myocardium mask (padded by one
   voxel so it closes), voxel (z, y, x) -> (x, y, z) metres with our origin and voxel size,
   then centimetres (svv's default CGS unit system), decimated with VTK to about
   ``--surface-points`` vertices (svv fits its implicit function patch by patch, so the
   point count sets the domain's build time); written as ``heart_N<N>.vtp``;
2. svv's Domain: ``Domain(mesh); create(); solve(); build()``;
3. the growth (the wall time the study reports): by default a Forest of one network of two
   trees rooted at our LCA and RCA ostia (``Forest.add`` adds one terminal to each tree per
   call, so the two trees get N/2 terminals each); ``--single``: one Tree at the LCA ostium
   with N terminals. svv's physics set to ours where svv has the parameter: terminal flow
   = our Q0 / N (Q0 = 4.16 mL/s), root pressure 13 300 Pa, terminal pressure 12 000 Pa;
   svv's Murray exponent (3), its viscosity (3.6e-2 cm^2/s x 1.06 g/cm^3) and its own
   cost (volume, radius exponent 2, length exponent 1) are left as svv's;
4. the export: ``svv_N<N>_tree<i>.csv`` per tree, one row per segment: proximal x, y, z,
   distal x, y, z (metres), radius (metres, svv's), flow (m^3/s), svv's parent, left and
   right child indices (-1 none), and its proximal/distal node ids.

The growth runs in chunks of ``--chunk`` terminals per tree and stops after the chunk that
passes ``--budget-seconds`` (default 40 min): the trees reached are exported as they are
(``terminals_reached`` and the progress [terminals, wall s, CPU s] in the JSON).

``--dry-run`` prints, per N, what a run would read, give svv and write (one JSON line each)
and imports neither svv nor its surface tools, so it runs in our env (the tests run it).

Telemetry: svv's Sentry module (``svv/telemetry.py``) is only initialised by its GUI and
honours ``SVV_TELEMETRY_DISABLED=1``; the script sets it before importing svv and never
imports the GUI. The machine has no internet in any case.
"""

from __future__ import annotations

import os

os.environ["SVV_TELEMETRY_DISABLED"] = "1"  # before any svv import

import argparse
import json
import time
from pathlib import Path

import numpy as np

Q0_M3S = 4.16e-6  # our physics.total_flow
P_IN_PA, P_T_PA = 13300.0, 12000.0  # our pressure_inlet, pressure_terminal


def surface(npz: Path, target_points: int):
    import pyvista as pv
    from skimage.measure import marching_cubes

    d = np.load(npz)
    mask = np.pad(d["mask"].astype(np.float32), 1)
    verts, faces, _, _ = marching_cubes(mask, level=0.5)
    verts = verts - 1.0  # the padding
    xyz = verts[:, ::-1] * float(d["voxel_size"]) + d["origin"][None, :]  # (z,y,x) idx -> (x,y,z) m
    cells = np.hstack([np.full((faces.shape[0], 1), 3), faces]).ravel()
    mesh = pv.PolyData(xyz * 100.0, cells)  # cm
    mesh = mesh.clean()
    n0 = mesh.n_points
    if mesh.n_points > target_points:
        mesh = mesh.decimate(1.0 - target_points / mesh.n_points)
    mesh = mesh.smooth(n_iter=20).clean().triangulate()
    mesh = mesh.compute_normals(auto_orient_normals=True, consistent_normals=True)
    return mesh, n0, d["inlets"] * 100.0, [str(s) for s in d["inlet_names"]]


def export_tree(tree, path: Path) -> int:
    data = np.asarray(tree.data)
    data = data[~np.isnan(data[:, 0])]
    out = np.column_stack(
        [
            data[:, 0:6] / 100.0,  # cm -> m
            data[:, 21] / 100.0,
            data[:, 22] * 1e-6,  # cm^3/s -> m^3/s
            np.nan_to_num(data[:, 17], nan=-1),
            np.nan_to_num(data[:, 15], nan=-1),
            np.nan_to_num(data[:, 16], nan=-1),
            data[:, 18],
            data[:, 19],
        ]
    )
    header = "px,py,pz,dx,dy,dz,radius,flow,parent,left,right,proximal_node,distal_node"
    np.savetxt(path, out, delimiter=",", header=header, comments="")
    return int(out.shape[0])


def plan(n: int, out: Path, single: bool) -> dict:
    """What a run of ``n`` terminals reads, gives svv and writes, without svv: the dry run."""
    tag = f"N{n}" + ("_single" if single else "")
    npz = out / f"heart_N{n}.npz"
    row = {
        "n": n,
        "input": str(npz),
        "input_exists": npz.is_file(),
        "trees": 1 if single else 2,
        "terminals_per_tree": n if single else n // 2,
        "terminal_flow_cm3_s": Q0_M3S * 1e6 / n,
        "root_pressure_barye": P_IN_PA * 10.0,
        "terminal_pressure_barye": P_T_PA * 10.0,
        "outputs": [str(out / f"heart_{tag}.vtp"), str(out / f"svv_{tag}.json")]
        + [str(out / f"svv_{tag}_tree{i}.csv") for i in range(1 if single else 2)],
    }
    if npz.is_file():
        d = np.load(npz)
        row["roots_cm"] = (d["inlets"] * 100.0).tolist()[: row["trees"]]
        row["roots"] = [str(s) for s in d["inlet_names"]][: row["trees"]]
    return row


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", help="terminals in all (one N a run; --dry-run: default 1000 6000)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/svv_study"))
    ap.add_argument("--single", action="store_true", help="one tree at the LCA ostium")
    ap.add_argument("--surface-points", type=int, default=4000)
    ap.add_argument("--resolution", type=int, default=25, help="Domain.build resolution")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--chunk", type=int, default=100, help="terminals per tree between progress lines")
    ap.add_argument(
        "--budget-seconds",
        type=float,
        default=2400.0,
        help="stop growing after the chunk that passes this wall time (the N reached is reported)",
    )
    ap.add_argument("--dry-run", action="store_true", help="print the plan per N; svv is not imported")
    args = ap.parse_args(argv)
    if args.dry_run:
        for n in args.n or [1000, 6000]:
            print(json.dumps(plan(n, args.out, args.single)))
        return
    if args.n is None or len(args.n) != 1:
        ap.error("give one N: --n N")

    import svv
    from svv.domain.domain import Domain
    from svv.forest.forest import Forest
    from svv.tree.tree import Tree

    n = args.n[0]
    tag = f"N{n}" + ("_single" if args.single else "")
    info: dict = {"n": n, "svv_version": svv.__version__, "single": args.single, "seed": args.seed}
    t0 = time.perf_counter()
    mesh, n_raw, inlets_cm, names = surface(args.out / f"heart_N{n}.npz", args.surface_points)
    mesh.save(args.out / f"heart_{tag}.vtp")
    info.update(surface_points_raw=n_raw, surface_points=mesh.n_points, surface_cells=mesh.n_cells)
    info["surface_seconds"] = time.perf_counter() - t0
    print(json.dumps(info), flush=True)

    t0 = time.perf_counter()
    dom = Domain(mesh)
    dom.set_random_seed(args.seed)
    dom.create()
    dom.solve()
    dom.build(resolution=args.resolution)
    info["domain_seconds"] = time.perf_counter() - t0
    print(json.dumps({k: info[k] for k in ("domain_seconds",)}), flush=True)

    def set_physics(tree, n_tree):
        p = tree.parameters
        p.terminal_flow = Q0_M3S * 1e6 / n  # cm^3/s per terminal (our equal terminal flows)
        p.root_pressure = P_IN_PA * 10.0  # Pa -> Barye
        p.terminal_pressure = P_T_PA * 10.0
        p.root_flow = None

    t0, c0 = time.perf_counter(), time.process_time()
    if args.single:
        tree = Tree()
        set_physics(tree, n)
        tree.set_domain(dom)
        tree.set_root(start=inlets_cm[0])
        trees, roots, todo = [tree], [names[0]], n - 1
        add = tree.n_add
    else:
        forest = Forest(domain=dom, n_networks=1, n_trees_per_network=[2], start_points=[[inlets_cm[0], inlets_cm[1]]])
        for t in forest.networks[0]:
            set_physics(t, n // 2)
        forest.set_domain(dom)
        forest.set_roots()
        trees, roots, todo = list(forest.networks[0]), list(names), n // 2 - 1
        add = forest.add
    # grow in chunks; after each, log the terminals and time, and stop past the budget
    # (the trees reached are exported and scored at the N they reached)
    info["progress"] = []
    done = 0
    while done < todo:
        step = min(args.chunk, todo - done)
        add(step)
        done += step
        elapsed = time.perf_counter() - t0
        info["progress"].append([sum(int(t.n_terminals) for t in trees), elapsed, time.process_time() - c0])
        print(json.dumps({"terminals": info["progress"][-1][0], "grow_seconds": elapsed}), flush=True)
        if elapsed > args.budget_seconds and done < todo:
            info["stopped_by_budget"] = True
            break
    info["grow_seconds"] = time.perf_counter() - t0
    info["grow_cpu_seconds"] = time.process_time() - c0
    info["roots"] = roots
    info["terminals_per_tree"] = [int(t.n_terminals) for t in trees]
    info["terminals_reached"] = int(sum(info["terminals_per_tree"]))
    info["segments_per_tree"] = [export_tree(t, args.out / f"svv_{tag}_tree{i}.csv") for i, t in enumerate(trees)]
    info["parameters"] = str(trees[0].parameters)
    (args.out / f"svv_{tag}.json").write_text(json.dumps(info, indent=1))
    print(json.dumps(info), flush=True)


if __name__ == "__main__":
    main()
