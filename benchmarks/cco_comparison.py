"""CCO against the anneal on the same terminal sites, tissue and cost.

For every N: CCO grows a tree on the heart from random sites (seed 0, Schreiner's distance
criterion); its N sites are written to ``sites_N<N>.csv``. On that one site set:

- ``cco``: CCO with the sites added in a seeded random order (``method.order=random``),
  one tree per seed: the spread between seeds is CCO's dependence on terminal order;
- ``anneal``: ``anneal=fast`` with the sites fixed (``terminals.fixed=true``), one tree per
  seed (random initial tree and moves), recorded before and after the final polish;
- ``cco_grown``: the CCO tree that produced the sites (its own order), one tree.

Per tree: vascular cost C_v + C_w and exclusion, asymmetry D_s/D_p and D_l/D_p by order
(diameter-defined Strahler, trunk = 11), mean |log10 model/Kassab| per artery, and the main
trunk of each inlet (from the inlet down the larger child while it carries at least 1/8
of its inlet's terminals). Printed: one JSON line per run (appended to ``--out``/runs.jsonl;
runs already there are not run again, so an interrupted benchmark resumes), then the
tables (mean ± SE over seeds), also written to ``--out``/tables.json. Trunk spread: the
mean over pairs of seeds of the symmetric mean distance between their trunk centre-lines
(each resampled at 64 points), per inlet, averaged over the inlets.

    python benchmarks/cco_comparison.py --out results/bench_cco                  # N = 100, 500
    python benchmarks/cco_comparison.py --out results/bench_cco --n 1000 --seeds 3
    python benchmarks/cco_comparison.py --out results/bench_cco_a0 --case heart_no_exclusion
    python benchmarks/cco_comparison.py --speed                                  # CCO wall time, N = 1000, 6000
    python benchmarks/cco_comparison.py --quick --out /tmp/cco_quick             # tiny, for the test
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from vasc_pipeline.reduce.reference import ARTERIES

TISSUE = ["tissue=heart"]
# heart: the paper's cost, so the anneal also weighs exclusion (A_o = 100), which CCO's
# growth does not see; heart_no_exclusion: A_o = 0, so both minimise the same C_v + C_w.
CASES = {"heart": [], "heart_no_exclusion": ["physics.A_o=0"]}


# --------------------------------------------------------------------------------------------
# Measures of one tree


def tree_measures(parent, position, radius, kind, gamma) -> dict:
    from vasc_pipeline.reduce.morphometry import compare_with_kassab, morphometry
    from vasc_pipeline.reduce.similarity import main_trunks, resample_polyline

    ds = morphometry(parent, position, radius, kind).sel(scheme="diameter_defined")
    orders = [int(o) for o in ds.order.values]
    out = {
        "orders": orders,
        "ratio_small": [None if not np.isfinite(v) else float(v) for v in ds.diameter_ratio_small_mean.values],
        "ratio_large": [None if not np.isfinite(v) else float(v) for v in ds.diameter_ratio_large_mean.values],
        "bifurcations": [int(v) for v in ds.bifurcation_count.values],
        "symmetric_ratio": 2.0 ** (-1.0 / gamma),
    }
    out["kassab"] = {a: float(compare_with_kassab(ds, a).attrs["mean_abs_log10_ratio"]) for a in ARTERIES}
    out["trunks"] = [resample_polyline(t).tolist() for t in main_trunks(parent, position, kind)]
    return out


# --------------------------------------------------------------------------------------------
# Runs


def _row(kind: str, n: int, seed: int, costs: dict, w_o: float, tree, physics, wall: float, **extra) -> dict:
    from vasc_pipeline.engine import node_radii
    from vasc_pipeline.model.costs import vascular_cost, vascular_exclusion_cost

    m = tree_measures(
        tree.parent,
        tree.position,
        node_radii(tree, physics),
        tree.kind,
        physics.gamma,
    )
    return {
        "method": kind,
        "n": n,
        "seed": seed,
        "vascular": vascular_cost(costs),
        "exclusion_scaled": w_o * costs["exclusion"],
        "vascular_exclusion": vascular_exclusion_cost(costs, w_o),
        "wall_seconds": wall,
        **extra,
        **m,
    }


def grow_sites(n: int, out: Path, extra: list[str]) -> tuple[Path, dict]:
    """The CCO tree on random sites (seed 0) at N and its sites as CSV (in the order grown)."""
    from vasc_pipeline import cco, config, engine

    problem = engine.build_problem(config.compose([*TISSUE, f"n_terminals={n}", "method=cco", *extra]))
    result = cco.grow(problem, 0)
    k = problem.physics.n_inlets
    path = out / f"sites_N{n}.csv"
    np.savetxt(path, result.tree.position[k : k + n], delimiter=",", header="x,y,z", comments="")
    row = _row(
        "cco_grown",
        n,
        0,
        result.costs_recomputed,
        problem.physics.weights[0],
        result.tree,
        problem.physics,
        result.wall_seconds,
        sites_drawn=result.tries,
    )
    return path, row


def one_run(task: tuple) -> dict:
    from vasc_pipeline import cco, config, engine

    kind, n, seed, sites, extra = task
    base = [*TISSUE, f"n_terminals={n}", f"terminals.path={sites}", *extra]
    if kind == "cco":
        problem = engine.build_problem(config.compose([*base, "method=cco", "method.order=random"]))
        result = cco.grow(problem, seed)
        return _row(
            kind,
            n,
            seed,
            result.costs_recomputed,
            problem.physics.weights[0],
            result.tree,
            problem.physics,
            result.wall_seconds,
        )
    cfg = config.compose([*base, "terminals.fixed=true", "anneal=fast", "anneal.trace_every=1000000"])
    result = engine.run(cfg, seed=seed)
    pol = result.anneal.get("polish", {})
    w_o = result.problem.physics.weights[0]
    return _row(
        kind,
        n,
        seed,
        result.costs_recomputed,
        w_o,
        result.tree,
        result.problem.physics,
        result.wall_seconds,
        vascular_before_polish=pol.get("vascular_before"),
        steps=result.steps,
        total_before_polish=pol.get("total_before"),
    )


# --------------------------------------------------------------------------------------------
# Tables


def _mean_se(values) -> tuple[float, float, int]:
    v = np.array([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if v.size == 0:
        return math.nan, math.nan, 0
    return float(v.mean()), float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else 0.0, int(v.size)


def _fmt(mean: float, se: float, scale: float = 1.0, digits: int = 4) -> str:
    return f"{mean * scale:.{digits}g} ± {se * scale:.2g}"


def summarise(rows: list[dict]) -> dict:
    from vasc_pipeline.reduce.similarity import trunk_spread

    tables = {"energy": [], "asymmetry": [], "order": [], "kassab": []}
    for n in sorted({r["n"] for r in rows}):
        by = {k: [r for r in rows if r["n"] == n and r["method"] == k] for k in ("cco", "anneal", "cco_grown")}
        e = {"n": n}
        for k, sel in by.items():
            e[f"{k}_vascular"] = _mean_se(r["vascular"] for r in sel)
            e[f"{k}_vascular_exclusion"] = _mean_se(r["vascular_exclusion"] for r in sel)
        e["anneal_before_polish_vascular"] = _mean_se(r.get("vascular_before_polish") for r in by["anneal"])
        e["cco_wall_seconds"] = _mean_se(r["wall_seconds"] for r in by["cco"])
        e["anneal_wall_seconds"] = _mean_se(r["wall_seconds"] for r in by["anneal"])
        tables["energy"].append(e)
        # asymmetry by order (pooled over seeds: mean of the per-tree means, weighted by bifurcations)
        for k in ("cco", "anneal"):
            sel = by[k]
            if not sel:
                continue
            acc: dict[int, list] = {}
            for r in sel:
                for o, s, l, c in zip(r["orders"], r["ratio_small"], r["ratio_large"], r["bifurcations"]):
                    if c > 0 and s is not None:
                        acc.setdefault(o, []).append((s, l, c))
            for o in sorted(acc):
                s, l, c = (np.array(v, dtype=float) for v in zip(*acc[o]))
                tables["asymmetry"].append(
                    {
                        "n": n,
                        "method": k,
                        "order": o,
                        "trees": int(s.size),
                        "bifurcations": int(c.sum()),
                        "ds_dp": _mean_se(s),
                        "dl_dp": _mean_se(l),
                        "symmetric": sel[0]["symmetric_ratio"],
                    }
                )
            # trunk spread between seeds
            pairs = trunk_spread([[np.array(t) for t in r["trunks"]] for r in sel]).tolist()
            tables["order"].append({"n": n, "method": k, "pairs": len(pairs), "trunk_spread_m": _mean_se(pairs)})
            tables["kassab"].append(
                {"n": n, "method": k, **{a: _mean_se(r["kassab"][a] for r in sel) for a in ARTERIES}}
            )
    return tables


def print_tables(t: dict) -> None:
    print("\nenergy: vascular cost C_v + C_w [mW] (mean ± SE over seeds; same sites)")
    print(
        f"{'N':>5} {'CCO grown':>12} {'CCO (random order)':>22} {'anneal':>20} {'anneal + polish':>20}"
        f" {'CCO s':>8} {'anneal s':>9}"
    )
    for e in t["energy"]:
        print(
            f"{e['n']:>5} {e['cco_grown_vascular'][0] * 1e3:>12.5g} {_fmt(*e['cco_vascular'][:2], 1e3):>22}"
            f" {_fmt(*e['anneal_before_polish_vascular'][:2], 1e3):>20} {_fmt(*e['anneal_vascular'][:2], 1e3):>20}"
            f" {e['cco_wall_seconds'][0]:>8.2f} {e['anneal_wall_seconds'][0]:>9.1f}"
        )
    print("\n  with exclusion: C_v + C_w + (A_o/A_wv) C_o [mW]")
    for e in t["energy"]:
        print(
            f"{e['n']:>5} {e['cco_grown_vascular_exclusion'][0] * 1e3:>12.5g}"
            f" {_fmt(*e['cco_vascular_exclusion'][:2], 1e3):>22}"
            f" {'':>20} {_fmt(*e['anneal_vascular_exclusion'][:2], 1e3):>20}"
        )
    print("\nasymmetry by parent order (diameter-defined, trunk = 11): mean ± SE over seeds")
    print(f"{'N':>5} {'method':>7} {'order':>5} {'D_s/D_p':>16} {'D_l/D_p':>16} {'bif.':>6} {'2^(-1/γ)':>8}")
    for a in t["asymmetry"]:
        print(
            f"{a['n']:>5} {a['method']:>7} {a['order']:>5} {_fmt(*a['ds_dp'][:2], 1, 3):>16}"
            f" {_fmt(*a['dl_dp'][:2], 1, 3):>16} {a['bifurcations']:>6} {a['symmetric']:>8.3f}"
        )
    print("\norder dependence: spread of the main trunks between seeds [mm] (mean ± SE over pairs)")
    for o in t["order"]:
        print(f"{o['n']:>5} {o['method']:>7} {_fmt(*o['trunk_spread_m'][:2], 1e3, 3):>16} ({o['pairs']} pairs)")
    print("\nmorphometry: mean |log10 model/Kassab| (diameter and length, element level), mean ± SE over seeds")
    for k in t["kassab"]:
        print(f"{k['n']:>5} {k['method']:>7} " + " ".join(f"{a} {_fmt(*k[a][:2], 1, 3):>14}" for a in ARTERIES))


# --------------------------------------------------------------------------------------------
# Speed of CCO alone


def speed(ns: list[int], repeats: int, extra: list[str]) -> list[dict]:
    from vasc_pipeline import cco, config, engine

    rows = []
    for n in ns:
        problem = engine.build_problem(config.compose([*TISSUE, f"n_terminals={n}", "method=cco", *extra]))
        cco.grow_tree(problem, np.array([1, 2, 3, 4], dtype=np.uint64))  # compile (cached) outside the timing
        for seed in range(repeats):
            from vasc_pipeline.model.rng import seed_state

            t0, c0 = time.perf_counter(), time.process_time()
            tree, _, drawn, _ = cco.grow_tree(problem, seed_state(seed))
            row = {
                "speed": True,
                "n": n,
                "seed": seed,
                "grow_wall_seconds": time.perf_counter() - t0,
                "grow_cpu_seconds": time.process_time() - c0,
                "sites_drawn": drawn,
            }
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", choices=sorted(CASES), default="heart")
    parser.add_argument("--n", type=int, nargs="+", default=[100, 500])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument(
        "--anneal-steps",
        type=int,
        help="anneal.steps of the anneal runs (default: the schedule's budget, fast: 6.25e7 (N/1000)^1.7); "
        "use a separate --out",
    )
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--out", type=Path, help="directory for sites, runs.jsonl and tables.json")
    parser.add_argument("--speed", action="store_true", help="only time CCO's growth (N = 1000 and 6000)")
    parser.add_argument("--quick", action="store_true", help="tiny sizes and short anneals (tests)")
    parser.add_argument("--tables", action="store_true", help="only print the tables of the runs in --out")
    args = parser.parse_args(argv)
    extra: list[str] = list(CASES[args.case])
    if args.quick:
        args.n, args.seeds = [12, 20], 2
        extra += ["anneal.steps=20000", "anneal.polish_swaps_max_terminals=0"]
    elif args.anneal_steps:
        extra.append(f"anneal.steps={args.anneal_steps}")
    if args.speed:
        return {"speed": speed([200, 600] if args.quick else [1000, 6000], 1 if args.quick else 3, extra)}
    out = args.out or Path("results/bench_cco")
    out.mkdir(parents=True, exist_ok=True)
    runs_file = out / "runs.jsonl"
    rows = [json.loads(line) for line in runs_file.read_text().splitlines()] if runs_file.exists() else []
    rows = list({(r["method"], r["n"], r["seed"]): r for r in rows}.values())  # one row per run
    done = {(r["method"], r["n"], r["seed"]) for r in rows}
    if args.tables:
        tables = summarise(rows)
        print_tables(tables)
        return tables

    def record(row: dict) -> None:
        rows.append(row)
        text = json.dumps(row)
        print(
            json.dumps(
                {
                    k: v
                    for k, v in row.items()
                    if k not in ("trunks", "orders", "ratio_small", "ratio_large", "bifurcations")
                }
            ),
            flush=True,
        )
        with runs_file.open("a") as f:
            f.write(text + "\n")

    tasks = []
    for n in args.n:
        sites = out / f"sites_N{n}.csv"
        if ("cco_grown", n, 0) not in done or not sites.exists():
            sites, row = grow_sites(n, out, extra)
            if ("cco_grown", n, 0) not in done:
                record(row)
        for seed in range(args.seeds):
            for kind in ("cco", "anneal"):
                if (kind, n, seed) not in done:
                    tasks.append((kind, n, seed, str(sites.resolve()), extra))
    tasks.sort(key=lambda t: (t[0] != "anneal", -t[1]))  # long anneals first
    with ProcessPoolExecutor(args.workers) as pool:
        for row in pool.map(one_run, tasks):
            record(row)
    tables = summarise(rows)  # every run in --out: earlier invocations' N and seeds too
    print_tables(tables)
    (out / "tables.json").write_text(json.dumps(tables, indent=1))
    return tables


if __name__ == "__main__":
    main()
