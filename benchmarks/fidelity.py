"""Fidelity against Kassab 1993: what the finished heart runs' morphometry is made of.

Reads complete run stores laid out as :mod:`time_to_quality` writes them
(``ROOT/<variant>/x<budget>/runs/*.zarr``) and recomputes, per run, with the package's
current morphometry (diameter-defined Strahler, zero-length segments contracted, element
level):

- ``diameter_error_<artery>`` / ``length_error_<artery>``: mean |log10 model/Kassab| over the
  orders present in both, trunk = 11 (the reduction's alignment), and the same with the
  terminal order placed on Kassab's order of nearest diameter (``..._terminal_aligned_...``);
- the same errors and ``n_orders`` under the confluence reading of the ordering
  (``..._confluence_...``; :mod:`vasc_pipeline.reduce.ordering`: orders never decrease toward the root);
- ``n_orders``, ``diameter_ratio_per_order`` (10^slope of log10 element diameter against
  order; Kassab's LAD, orders 5-11: 1.86) and per order the element count, segments per
  element, mean diameter and length (``orders``);
- the cost balance: C_v, C_w, the weighted exclusion (A_o/A_wv) C_o and the share of C_o
  carried by terminal segments, the mean pressure drop C_w / Q0 [Pa];
- the inlet split: per inlet (LCA, RCA) root diameter and share of the terminals (flow);
- ``cavity_share`` as stored, ``n_contracted_segments`` and the contraction threshold
  ``min_segment_length`` (m) they were ordered with;
- where the branch points sit (:func:`placement_row`): the share of bifurcations outside the
  exclusion domain, their median distance from it, the terminal segments' median length.

One JSON line per run, then mean ± SE over seeds per (variant, budget, N):

    python benchmarks/time_to_quality.py --out results/ttq --anneal fast_v1 --seeds 0 1 2 3
    python benchmarks/fidelity.py results/ttq | grep "^{" > fidelity_rows.jsonl
    python benchmarks/fidelity.py --quick          # a tiny run in a temporary dir: wiring only
"""

from __future__ import annotations

import argparse
import json
import re
import tempfile
from pathlib import Path

import numpy as np
from time_to_quality import ARTERIES, jobs_for, run_one, seed_groups, seed_stats

from vasc_pipeline.reduce.anatomy import inlet_shares
from vasc_pipeline.reduce.fidelity import (
    KASSAB_TOP_ORDER,
    diameter_ratio_per_order,
    kassab_diameter_ratio,
    morphometry_errors,
    per_artery_trees,
)


def exclusion_by_segment(tissue, physics: dict, tree: dict) -> np.ndarray:
    """Weighted exclusion cost (A_o/A_wv) pi r^2 sum_v (D_v L_v)^6 of every segment [W]."""
    from vasc_pipeline import costs
    from vasc_pipeline.model.physics import exclusion_weight

    parent, position, radius = tree["parent"], tree["position"], tree["radius"]
    weight = exclusion_weight(radius, physics["r_cutoff"], physics.get("r_cutoff_ramp", 0.0))
    counted = (parent >= 0) & (weight > 0)
    out = np.zeros(parent.size)
    for i in np.flatnonzero(counted):
        area = np.pi * radius[i] ** 2 * weight[i]
        out[i] = area * costs.exclusion_sum(position[parent[i]], position[i], tissue.exclusion_grid)
    return out * physics["A_o"] / physics["A_wv"]


def placement_row(tissue, tree: dict) -> dict:
    """Where the branch points sit: the share of bifurcations outside the exclusion domain
    (the heart and its cavities), their median distance from it, and the terminal segments'
    median length: all of them, and those hanging from a bifurcation outside."""
    from vasc_pipeline.model.tree import KIND_BIFURCATION, KIND_TERMINAL

    kind, position, parent = tree["kind"], tree["position"], tree["parent"]
    up = np.maximum(parent, 0)  # parent -1 (inlets) maps to node 0; only rows of terminals are read
    idx = np.clip(tissue.voxel_index(position), 0, np.array(tissue.shape) - 1)
    outside_mm = tissue.distance_outside()[idx[:, 0], idx[:, 1], idx[:, 2]] * 1e3
    bifurcation, terminal = kind == KIND_BIFURCATION, kind == KIND_TERMINAL
    out = outside_mm[bifurcation] > 0
    hanging = terminal & (outside_mm[up] > 0) & (kind[up] == KIND_BIFURCATION)
    length_mm = np.linalg.norm(position - position[up], axis=1) * 1e3
    return {
        "bifurcations_outside_share": float(out.mean()),
        "bifurcation_outside_distance_mm_median": float(np.median(outside_mm[bifurcation][out])) if out.any() else 0.0,
        "terminal_segment_length_mm_median": float(np.median(length_mm[terminal])),
        "terminal_segment_length_mm_median_parent_outside": (
            float(np.median(length_mm[hanging])) if hanging.any() else float("nan")
        ),
    }


def row_of(path: Path, root: Path) -> dict:
    from vasc_pipeline import config, engine, morphometry
    from vasc_pipeline.store import RunStore

    store = RunStore.open(path, mode="r")
    a = store.attrs
    variant, budget = path.parent.parent.relative_to(root).parts[-2:]
    c, physics = a["cost_recomputed"], a["physics"]
    tree = store.read_tree()
    parent, kind = tree["parent"], tree["kind"]
    tissue = engine.build_problem(config.from_stored(a["config"])).tissue
    exclusion = exclusion_by_segment(tissue, physics, tree)
    row = {
        "variant": variant,
        "budget": float(budget.removeprefix("x")),
        "n_terminals": int(a["coords"]["n_terminals"]),
        "seed": int(a["seed"]),
        "steps": int(a["steps_done"]),
        "m_b": float(physics["m_b"]),
        "r_cutoff": float(physics["r_cutoff"]),
        "cavity_share": float((a.get("statistics") or {}).get("cavity_share", float("nan"))),
        "cost_supply": float(c["supply"]),
        "cost_volume": float(c["volume"]),
        "cost_power": float(c["power"]),
        "cost_exclusion_weighted": float(exclusion.sum()),
        "exclusion_share_terminal_segments": float(exclusion[kind == 2].sum() / max(exclusion.sum(), 1e-300)),
        "pressure_drop_mean_Pa": float(c["power"] / physics["total_flow"]),
    }
    row.update(placement_row(tissue, tree))
    shares = inlet_shares(parent, kind, tissue.inlet_names)
    for name, inlet in zip(tissue.inlet_names, np.flatnonzero(parent < 0)):
        root_segment = np.flatnonzero(parent == inlet)[0]
        row[f"root_diameter_um_{name}"] = float(2e6 * tree["radius"][root_segment])
        row[f"terminal_share_{name}"] = shares[name]
    morph = morphometry.morphometry(parent, tree["position"], tree["radius"], kind)
    dds = morph.sel(scheme="diameter_defined")
    present = (dds.element_count > 0).values
    orders = dds.order.values[present]
    row["n_contracted_segments"] = int(morph.attrs["n_contracted_segments"])
    row["min_segment_length"] = float(morph.attrs["min_segment_length"])  # m; rows before 2026-11-24: 1e-9
    row["diameter_ratio_per_order"] = diameter_ratio_per_order(orders, dds.element_diameter_mean.values[present])
    row.update(morphometry_errors(morph))
    # the other reading of Jiang's reassignment (vasc_pipeline.reduce.ordering): orders monotone toward the root
    confluence = morphometry_errors(
        morphometry.morphometry(parent, tree["position"], tree["radius"], kind, reading="confluence")
    )
    row["n_orders_confluence"] = confluence["n_orders"]
    for artery in ARTERIES:
        for what in ("diameter", "length"):
            row[f"{what}_error_confluence_{artery}"] = confluence[f"{what}_error_{artery}"]
    if {"LCA", "RCA"} <= set(tissue.inlet_names):
        for artery, sub in per_artery_trees(tree, tissue.inlet_names).items():
            top = int(KASSAB_TOP_ORDER[artery])
            table = morphometry.compare_with_kassab(
                morphometry.morphometry(sub["parent"], sub["position"], sub["radius"], sub["kind"], top=top), artery
            )
            row[f"diameter_error_per_artery_{artery}"] = table.attrs["mean_abs_log10_ratio_diameter"]
            row[f"length_error_per_artery_{artery}"] = table.attrs["mean_abs_log10_ratio_length"]
    row["store"] = str(path)
    return row


SUMMARY = (
    "n_orders",
    "diameter_ratio_per_order",
    *(f"diameter_error_{a}" for a in ARTERIES),
    *(f"diameter_error_terminal_aligned_{a}" for a in ARTERIES),
    *(f"diameter_error_per_artery_{a}" for a in ARTERIES),
    "n_orders_confluence",
    *(f"diameter_error_confluence_{a}" for a in ARTERIES),
    *(f"length_error_confluence_{a}" for a in ARTERIES),
    *(f"length_error_{a}" for a in ARTERIES),
    *(f"length_error_per_artery_{a}" for a in ARTERIES),
    "cost_volume",
    "cost_power",
    "cost_exclusion_weighted",
    "exclusion_share_terminal_segments",
    "pressure_drop_mean_Pa",
    "bifurcations_outside_share",
    "bifurcation_outside_distance_mm_median",
    "terminal_segment_length_mm_median",
)


def summarise(rows: list[dict]) -> list[dict]:
    """Mean and SE over seeds per (variant, budget, N); inlet columns included."""
    keys = ("variant", "budget", "n_terminals")
    table = []
    for key, sel in seed_groups(rows, keys):
        names = [n for n in SUMMARY if n in sel[0]]
        names += sorted(k for k in sel[0] if k.startswith(("root_diameter", "terminal_share")))
        table.append({**dict(zip(keys, key)), "seeds": len(sel), **seed_stats(sel, names)})
    return table


def _pm(entry: dict, name: str, fmt: str = ".3f") -> str:
    se = entry[name + "_se"]
    return f"{entry[name]:{fmt}}" + (f"±{se:{fmt}}" if np.isfinite(se) else "")


def print_table(table: list[dict]) -> None:
    print(f"\nmean ± SE over seeds; Kassab LAD diameter ratio per order (orders 5-11): {kassab_diameter_ratio():.2f}")
    print("diameter / length error: mean |log10 model/Kassab| RCA, LAD, LCX; trunk = 11 unless 'aligned'")
    for t in table:
        diam = " ".join(_pm(t, f"diameter_error_{a}") for a in ARTERIES)
        aligned = " ".join(_pm(t, f"diameter_error_terminal_aligned_{a}") for a in ARTERIES)
        separate = " ".join(_pm(t, f"diameter_error_per_artery_{a}") for a in ARTERIES)
        length = " ".join(_pm(t, f"length_error_{a}") for a in ARTERIES)
        length_separate = " ".join(_pm(t, f"length_error_per_artery_{a}") for a in ARTERIES)
        confluence = " ".join(_pm(t, f"diameter_error_confluence_{a}") for a in ARTERIES)
        length_confluence = " ".join(_pm(t, f"length_error_confluence_{a}") for a in ARTERIES)
        inlets = " ".join(
            f"{name} D {t['root_diameter_um_' + name]:.0f} um, share {t['terminal_share_' + name]:.2f}"
            for name in (k.removeprefix("terminal_share_") for k in t if k.startswith("terminal_share_"))
            if not name.endswith("_se")
        )
        print(
            f"{t['variant']} x{t['budget']:g} N={t['n_terminals']} ({t['seeds']} seeds): "
            f"orders {_pm(t, 'n_orders', '.2f')}, ratio/order {_pm(t, 'diameter_ratio_per_order', '.2f')}\n"
            f"    diameter {diam} | terminal-aligned {aligned} | per artery {separate}\n"
            f"    length {length} | per artery {length_separate}\n"
            f"    confluence reading: orders {_pm(t, 'n_orders_confluence', '.2f')}, diameter {confluence}, "
            f"length {length_confluence}\n"
            f"    C_v {t['cost_volume']:.3g} W, C_w {t['cost_power']:.3g} W, (A_o/A_wv) C_o "
            f"{t['cost_exclusion_weighted']:.3g} W ({t['exclusion_share_terminal_segments']:.4f} on terminal "
            f"segments), mean pressure drop {t['pressure_drop_mean_Pa'] / 1e3:.2f} kPa; {inlets}\n"
            f"    bifurcations outside the exclusion domain {_pm(t, 'bifurcations_outside_share', '.2f')} "
            f"(median {_pm(t, 'bifurcation_outside_distance_mm_median', '.1f')} mm out), terminal segments "
            f"{_pm(t, 'terminal_segment_length_mm_median', '.1f')} mm (median)"
        )


def stores_under(roots: list[Path]) -> list[tuple[Path, Path]]:
    from vasc_pipeline.store import RunStore

    found = []
    for root in roots:
        for path in sorted(root.glob("*/x*/runs/*.zarr")):
            if re.fullmatch(r"x[0-9.]+", path.parent.parent.name) and RunStore.open(path, "r").status == "complete":
                found.append((path, root))
    return found


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("roots", nargs="*", type=Path, help="directories laid out as time_to_quality's --out")
    parser.add_argument("--quick", action="store_true", help="one tiny run (N = 40) in a temporary dir")
    args = parser.parse_args(argv)
    tmp = None
    if args.quick:
        tmp = tempfile.TemporaryDirectory()
        args.roots = [Path(tmp.name)]
        for job in jobs_for(args.roots[0], "fast_v1", 1.0, 40, [0], 20_000, ["anneal.trace_every=10000"]):
            run_one(job)
    if not args.roots:
        parser.error("give at least one directory of runs (or --quick)")
    rows = []
    for path, root in stores_under(args.roots):
        rows.append(row_of(path, root))
        print(json.dumps(rows[-1]), flush=True)
    table = summarise(rows)
    print_table(table)
    if tmp is not None:
        tmp.cleanup()
    return table


if __name__ == "__main__":
    main()
