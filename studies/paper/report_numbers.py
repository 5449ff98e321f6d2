"""Print every number results/paper/REPORT.md quotes, from the tracked outputs in results/paper/ (no run stores needed).

    python studies/paper/report_numbers.py
    python studies/paper/report_numbers.py --quick    # the same: it reads tracked files only

Each block names the file it reads. Diameters in µm, lengths in mm, errors in dex
(|log10 model/Kassab|), as in the report.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from vasc_pipeline.reduce.morphometry import compare_with_kassab, inlet_of, morphometry
from vasc_pipeline.reduce.ordering import READINGS

PAPER = Path(__file__).resolve().parents[2] / "results" / "paper"  # what the study scripts collected
SCHEME = "diameter_defined"


def open_summary(study: str) -> xr.DataTree | None:
    path = PAPER / study / "summary.zarr"
    return xr.open_datatree(path, engine="zarr") if path.is_dir() else None


def tree_arrays(study: str, run_id: str) -> tuple:
    """(parent, position, radius, kind) of an exported tree (trees/<run_id>.csv)."""
    table = pd.read_csv(PAPER / study / "trees" / f"{run_id}.csv")
    parent = table["parent"].fillna(-1).to_numpy(dtype=np.int64)
    position = table[["x_m", "y_m", "z_m"]].to_numpy()
    return parent, position, table["radius_m"].fillna(0.0).to_numpy(), table["kind"].to_numpy(dtype=np.int8)


def inlet_shares(study: str, run_id: str) -> str:
    """Share of the best tree's terminals fed by each inlet, from its exported CSV (trees/<run_id>.csv)."""
    parent, _, _, kind = tree_arrays(study, run_id)
    inlet = inlet_of(parent)
    terminal = kind == 2
    return "/".join(f"{np.mean(inlet[terminal] == i):.2f}" for i in np.flatnonzero(parent < 0))


def size_scan(summary: xr.DataTree, study: str) -> None:
    comp = summary["comparison"].to_dataset().squeeze("m_b", drop=True)
    morph = summary["morphometry"].to_dataset().squeeze("m_b", drop=True)
    costs = summary["costs"].to_dataset().squeeze("m_b", drop=True)
    print(f"## {study}: per N (comparison_summary.csv; summary.zarr /costs)")
    print(
        "N | seeds | wall per run [min] | best C_s | mean dex D RCA/LAD/LCX | mean dex L RCA/LAD/LCX | orders | "
        "terminal share LCA/RCA"
    )
    for n in comp.n_terminals.values:
        c, m = comp.sel(n_terminals=n), morph.sel(n_terminals=n)
        if not str(m["best_run_id"].values):
            continue
        wall = costs["wall_seconds"].sel(n_terminals=n).values
        d = "/".join(f"{v:.3f}" for v in c["mean_abs_log10_ratio_diameter"].values)
        ln = "/".join(f"{v:.3f}" for v in c["mean_abs_log10_ratio_length"].values)
        orders = m.order.values[(m["element_count"].sel(scheme=SCHEME) > 0).values]
        print(
            f"{int(n)} | {int(m['n_seeds'])} | {np.nanmean(wall) / 60:.1f} | "
            f"{float(costs['cost_supply'].sel(n_terminals=n).min()):.4g} | {d} | {ln} | "
            f"{orders.min()}-{orders.max()} | {inlet_shares(study, str(m['best_run_id'].values))}"
        )
    n = int(max(v for v in comp.n_terminals.values if str(morph["best_run_id"].sel(n_terminals=v).values)))
    print(f"\n## {study}: the largest tree, N = {n}, per order (comparison.csv), dex model/Kassab")
    print(
        "order | model D [um] | LAD D | dex D LAD | RCA | LCX | model L [mm] | LAD L | dex L LAD | RCA | LCX | elements"
    )
    c = comp.sel(n_terminals=n)
    for order in c.order.values:
        r = c.sel(order=order)
        if int(r["model_count"].max()) == 0:
            continue
        lad = r.sel(artery="LAD")
        print(
            f"{int(order)} | {float(lad['model_diameter']) * 1e6:.0f} | {float(lad['kassab_diameter']) * 1e6:.0f} | "
            + " | ".join(f"{float(r['diameter_log10_ratio'].sel(artery=a)):+.3f}" for a in ("LAD", "RCA", "LCX"))
            + f" | {float(lad['model_length']) * 1e3:.2f} | {float(lad['kassab_length']) * 1e3:.2f} | "
            + " | ".join(f"{float(r['length_log10_ratio'].sel(artery=a)):+.3f}" for a in ("LAD", "RCA", "LCX"))
            + f" | {int(lad['model_count'])}"
        )
    asym = summary["asymmetry"].to_dataset().squeeze("m_b", drop=True).sel(scheme=SCHEME)
    print(f"\n## {study}: asymmetry by parent order (summary.zarr /asymmetry): D_s/D_p, D_l/D_p (bifurcations)")
    for n in asym.n_terminals.values:
        a = asym.sel(n_terminals=n)
        ok = (a["bifurcation_count"] > 0).values
        if not ok.any():
            continue
        cells = [
            f"{int(o)}: {float(a['diameter_ratio_small_mean'].sel(order=o)):.2f}/"
            f"{float(a['diameter_ratio_large_mean'].sel(order=o)):.2f} ({int(a['bifurcation_count'].sel(order=o))})"
            for o in a.order.values[ok]
        ]
        print(f"N = {int(n)}: " + ", ".join(cells))
    print(f"symmetric value 2^(-1/gamma) = {float(asym['symmetric_ratio'].max()):.3f}")


def size_scan_readings(summary: xr.DataTree, study: str) -> None:
    """The best trees under both readings of Jiang's reassignment (vasc_pipeline.reduce.ordering)."""
    morph = summary["morphometry"].to_dataset().squeeze("m_b", drop=True)
    print(f"\n## {study}: the best trees under both readings of the ordering (trees/<run_id>.csv)")
    print("N | reading | orders | mean dex D RCA/LAD/LCX | mean dex L RCA/LAD/LCX | dex D LAD per order (trunk = 11)")
    for n in morph.n_terminals.values:
        run_id = str(morph["best_run_id"].sel(n_terminals=n).values)
        if not run_id:
            continue
        arrays = tree_arrays(study, run_id)
        for reading in READINGS:
            ds = morphometry(*arrays, reading=reading)
            tables = {a: compare_with_kassab(ds, a) for a in ("RCA", "LAD", "LCX")}
            d = "/".join(f"{t.attrs['mean_abs_log10_ratio_diameter']:.3f}" for t in tables.values())
            ln = "/".join(f"{t.attrs['mean_abs_log10_ratio_length']:.2f}" for t in tables.values())
            lad = tables["LAD"].dropna(subset=["diameter_log10_ratio"])
            per_order = ", ".join(f"{o}: {v:+.2f}" for o, v in lad["diameter_log10_ratio"].items())
            n_orders = int((ds["element_count"].sel(scheme=SCHEME) > 0).sum())
            print(f"{int(n)} | {reading} | {n_orders} | {d} | {ln} | {per_order}")


def mb_scan(summary: xr.DataTree) -> None:
    morph = summary["morphometry"].to_dataset().squeeze("n_terminals", drop=True).sel(scheme=SCHEME)
    asym = summary["asymmetry"].to_dataset().squeeze("n_terminals", drop=True).sel(scheme=SCHEME)
    print("\n## mb_scan (summary.zarr): per m_b, the best tree")
    print(
        "m_b | orders | L order 11/10/9 [mm] | D_s/D_p, D_l/D_p at parent orders 11/10/9 | trunk tortuosity | "
        "trunk spread [mm] | terminal share LCA/RCA"
    )
    for mb in morph.m_b.values:
        m, a = morph.sel(m_b=mb), asym.sel(m_b=mb)
        orders = m.order.values[(m["element_count"] > 0).values]
        lengths = "/".join(f"{float(m['element_length_mean'].sel(order=o)) * 1e3:.1f}" for o in (11, 10, 9))
        ratios = ", ".join(
            "/".join(f"{float(a[f'diameter_ratio_{which}_mean'].sel(order=o)):.2f}" for o in (11, 10, 9))
            for which in ("small", "large")
        )
        print(
            f"{float(mb):.4g} | {len(orders)} ({orders.min()}-{orders.max()}) | {lengths} | {ratios} | "
            f"{float(m['trunk_tortuosity']):.2f} | {float(m['trunk_spread']) * 1e3:.1f} | "
            f"{inlet_shares('mb_scan', str(m['best_run_id'].values))}"
        )


def convergence(summaries: dict[str, xr.DataTree]) -> None:
    print("\n## convergence (summary.zarr /costs): mean final total cost ± SE over seeds")
    for label, summary in summaries.items():
        costs = summary["costs"].to_dataset().squeeze(["n_terminals", "m_b"], drop=True)
        total = costs["cost_total"]
        n = total.notnull().sum("seed")
        mean, se = total.mean("seed"), total.std("seed", ddof=1) / np.sqrt(n)
        wall = costs["wall_seconds"].sum().item()
        cells = [
            f"{s:.0e}: {float(mean.sel(steps=s)):.5g} ± {float(se.sel(steps=s)):.2g} (n={int(n.sel(steps=s))})"
            for s in total.steps.values
        ]
        print(f"{label} (total run time {wall / 60:.1f} min): " + "; ".join(cells))
        spread = summary["morphometry"].to_dataset().squeeze(["n_terminals", "m_b"], drop=True)["trunk_spread"]
        print(
            f"{label} trunk spread [mm]: "
            + ", ".join(f"{s:.0e}: {float(v) * 1e3:.1f}" for s, v in zip(spread.steps.values, spread.values))
        )


def consistency(summary: xr.DataTree) -> None:
    morph = summary["morphometry"].to_dataset().squeeze(["n_terminals", "m_b"], drop=True)
    costs = summary["costs"].to_dataset().squeeze(["n_terminals", "m_b"], drop=True)
    print("\n## consistency (summary.zarr /morphometry): trunk spread and tortuosity against moves")
    for s in morph.steps.values:
        wall = float(costs["wall_seconds"].sel(steps=s).sum())
        print(
            f"{s:.0e} moves: trunk spread {float(morph['trunk_spread'].sel(steps=s)) * 1e3:.1f} mm over "
            f"{int(morph['n_seeds'].sel(steps=s))} seeds, best tree's trunk tortuosity "
            f"{float(morph['trunk_tortuosity'].sel(steps=s)):.2f}, wall {wall / 60:.1f} min"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="the same numbers: they need no runs (for the tests)")
    parser.parse_args(argv)
    found = False
    # Today's model, and the scan under the earlier one (exclusion on the supply grid, fast_v1).
    for study in ("size_scan", "size_scan_fast_v1"):
        if (s := open_summary(study)) is not None:
            size_scan(s, study)
            size_scan_readings(s, study)
            found = True
    if (s := open_summary("mb_scan")) is not None:
        mb_scan(s)
        found = True
    conv = {k: s for k in ("paper", "fast") if (s := open_summary(f"convergence_{k}")) is not None}
    if conv:
        convergence(conv)
        found = True
    if (s := open_summary("consistency")) is not None:
        consistency(s)
        found = True
    return 0 if found else 1


if __name__ == "__main__":
    sys.exit(main())
