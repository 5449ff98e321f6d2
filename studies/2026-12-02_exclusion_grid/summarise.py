"""The exclusion-grid study's tables from its rows (rows.jsonl beside this script, or a path).

Per variant and N, mean ± SE over seeds: (A_o/A_wv) C_o and C_v + C_w [W], their ratio,
C_w / C_v, the mean pressure drop C_w / Q0 [kPa], C_s, the order count, the mean |log10
model/Kassab| of element diameter and length per artery (RCA/LAD/LCX; trunk at 11 and
terminal-aligned), the cavity share, the runs that abandoned an artery (an inlet feeding under
1 % of the terminals), wall time. Then the targets: whether the mean over the arteries of the
diameter and of the length error falls (or holds) from N = 1000 to 6000, and the LAD's element
lengths of orders 8-10 against Kassab's at the largest N. At N = 6000 the supply grid's voxel
is 0.504 mm, so a's runs there are b''s and c's too (the same grids, the same runs bit for bit):
they are counted under all three.

    python studies/2026-12-02_exclusion_grid/summarise.py [ROWS]
    python studies/2026-12-02_exclusion_grid/summarise.py --quick   # the rows and one tiny run's

``--quick`` adds the row of a tiny run (N = 40, made and scored in a temporary directory) to the
rows, so that the tables are checked on a row of today's scoring as well as on the study's.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

ARTERIES = ("RCA", "LAD", "LCX")
TOTAL_FLOW = 4.16e-6  # Q0 of the heart's physics, m^3 s^-1
ABANDONED = 0.01  # an inlet feeding fewer than this share of the terminals


def mean_se(values) -> tuple[float, float]:
    v = np.asarray(values, dtype=float)
    return float(v.mean()), float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else float("nan")


def pm(values, fmt: str) -> str:
    m, se = mean_se(values)
    return f"{m:{fmt}}" if np.isnan(se) else f"{m:{fmt}} ± {se:{fmt}}"


def errors(rows, what: str, suffix: str = "") -> str:
    return "/".join(f"{mean_se([r[f'{what}_error{suffix}_{a}'] for r in rows])[0]:.2f}" for a in ARTERIES)


def abandoned(row) -> bool:
    return any(v < ABANDONED for k, v in row.items() if k.startswith("terminal_share_"))


def table(rows: list[dict]) -> list[str]:
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["anneal"], r["n_terminals"]), []).append(r)
    lines = [
        "| variant | N | seeds | (A_o/A_wv) C_o [W] | C_v + C_w [W] | ratio | C_w/C_v | C_w/Q0 [kPa] | C_s | orders "
        "| D error | L error | D, L terminal-aligned | cavity | abandoned | wall [s] |",
        "|" + "---|" * 16,
    ]
    for (variant, n), sel in sorted(groups.items()):
        exclusion = [r["cost_exclusion_weighted"] for r in sel]
        vascular = [r["cost_volume"] + r["cost_power"] for r in sel]
        lines.append(
            f"| {variant} | {n} | {len(sel)} | {pm(exclusion, '.4g')} | {pm(vascular, '.4f')} "
            f"| {np.mean(np.array(exclusion) / np.array(vascular)):.4g} "
            f"| {np.mean([r['cost_power'] / r['cost_volume'] for r in sel]):.0f} "
            f"| {np.mean([r['cost_power'] / TOTAL_FLOW for r in sel]) / 1e3:.0f} "
            f"| {pm([r['cost_supply'] for r in sel], '.0f')} | {np.mean([r['n_orders'] for r in sel]):.2f} "
            f"| {errors(sel, 'diameter')} | {errors(sel, 'length')} "
            f"| {errors(sel, 'diameter', '_terminal_aligned')}, {errors(sel, 'length', '_terminal_aligned')} "
            f"| {np.nanmax([r['cavity_share'] for r in sel]):.4f} | {sum(map(abandoned, sel))} "
            f"| {np.mean([r['wall_seconds'] for r in sel]):.0f} |"
        )
    return lines


def trend(rows: list[dict]) -> list[str]:
    """The mean over the arteries of each error by N, per variant (the paper's claim: falling)."""
    lines = ["", "mean over RCA/LAD/LCX, mean over seeds (trunk at 11):"]
    variants = sorted({r["anneal"] for r in rows})
    for variant in variants:
        by_n: dict[int, list[dict]] = {}
        for r in rows:
            if r["anneal"] == variant:
                by_n.setdefault(r["n_terminals"], []).append(r)
        parts = []
        for n, sel in sorted(by_n.items()):
            d = np.mean([r[f"diameter_error_{a}"] for r in sel for a in ARTERIES])
            length = np.mean([r[f"length_error_{a}"] for r in sel for a in ARTERIES])
            parts.append(f"N={n}: D {d:.3f}, L {length:.3f}")
        lines.append(f"- {variant}: " + "; ".join(parts))
    return lines


def upper_order_lengths(rows: list[dict], orders=(8, 9, 10)) -> list[str]:
    """|log10 model/Kassab| of the element length of ``orders`` (trunk at 11) against each
    artery's, at each variant's largest N, mean over seeds (the target: within 0.25 dex)."""
    from vasc_pipeline.reduce.reference import kassab_dataset

    kassab = kassab_dataset().sel(level="element")
    lines = ["", f"element length of orders {', '.join(map(str, orders))} (trunk at 11), |log10 model/Kassab|:"]
    for variant in sorted({r["anneal"] for r in rows}):
        n = max(r["n_terminals"] for r in rows if r["anneal"] == variant)
        sel = [r for r in rows if r["anneal"] == variant and r["n_terminals"] == n]
        parts = []
        for artery in ARTERIES:
            ref = kassab.sel(artery=artery)
            per_order = []
            for o in orders:
                model = [r["orders"][str(o)]["length_mm"] for r in sel if str(o) in r["orders"]]
                length_ref = float(ref.L_mean.sel(order=o)) * 1e3  # m -> mm
                per_order.append(abs(np.log10(np.mean(model) / length_ref)) if model else float("nan"))
            parts.append(f"{artery} " + "/".join(f"{e:.2f}" for e in per_order))
        lines.append(f"- {variant}, N = {n} ({len(sel)} seeds): " + "; ".join(parts))
    return lines


A_LABEL = "exclusion grid a, supply grid"
SAME_AS_A_AT_6000 = ("exclusion grid b-prime, 0.504 mm", "exclusion grid c, both 0.504 mm")


def with_shared_runs(rows: list[dict]) -> list[dict]:
    """``rows`` and a's runs at N = 6000 once more under b' and c, whose grids they are."""
    shared = [r for r in rows if r["anneal"] == A_LABEL and r["n_terminals"] == 6000]
    return rows + [{**r, "anneal": label} for label in SAME_AS_A_AT_6000 for r in shared]


def quick_row() -> dict:
    """The row of one tiny run (N = 40, 20 000 moves), as time_to_quality.py writes it."""
    from vasc_pipeline import config, job, sweep
    from vasc_pipeline.reduce.fidelity import run_row

    with tempfile.TemporaryDirectory() as tmp:
        (j,) = sweep.expand(config.compose(["n_terminals=40", "anneal.steps=20000", f"output_dir={tmp}"]))
        job.run_job(j)
        row = run_row(j.store)
    return {"n_terminals": row.pop("n_terminals"), "anneal": "quick", "budget": 1.0, **row}


def main(argv: list[str] | None = None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("rows", nargs="?", type=Path, default=Path(__file__).with_name("rows.jsonl"))
    parser.add_argument("--quick", action="store_true", help="add one tiny run's row (made in a temporary dir)")
    args = parser.parse_args(argv)
    rows = [json.loads(line) for line in args.rows.read_text().splitlines() if line.strip()]
    if args.quick:
        rows.append(quick_row())
    rows = with_shared_runs(rows)
    text = "\n".join(table(rows) + trend(rows) + upper_order_lengths(rows))
    print(text)
    return text


if __name__ == "__main__":
    main()
