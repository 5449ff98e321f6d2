"""The model-levers study's table: every lever against the paper's model, N and seeds pooled as asked.

Scores every complete run store of the study (``--out``, run.sh's OUT) and of the baseline (the
paper's model under ``fast``: the size scan's stores) with
:func:`vasc_pipeline.reduce.fidelity.run_row` (costs, each artery's share, the errors against
Kassab, the anatomy), keeps the rows in ``scored.jsonl`` beside this script (a store scored once
is not read again, so the table survives the stores), and prints one markdown row per (lever,
N): means over the seeds, and the worst seed where a target is a bound.

    python studies/2026-12-06_model_levers/summarise.py
    python studies/2026-12-06_model_levers/summarise.py --out results/studies/model_levers --baseline DIR
    python studies/2026-12-06_model_levers/summarise.py --scan results/studies/size_scan_physiological
    python studies/2026-12-06_model_levers/summarise.py --quick     # a tiny store, written and scored
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from vasc_pipeline.reduce.anatomy import MMHG
from vasc_pipeline.reduce.fidelity import run_row
from vasc_pipeline.reduce.reference import ARTERIES

HERE = Path(__file__).resolve().parent
# the paper's model under today's `fast`, seeds 0-3 (off main's tree: results/README.md says how to
# restore them; their rows are in scored.jsonl already)
BASELINE = Path("results/studies/size_scan/runs")


def stores(out: Path, baseline: Path, scan: Path | None = None) -> list[tuple[str, Path]]:
    """(lever, store) of every run store: ``<out>/<lever>/x1/runs/*.zarr``, the baseline's as "paper"
    and, with ``scan``, a size scan's output_dir (``runs/*.zarr``) as "scan:<its name>"."""
    found = [(p.parents[2].name, p) for p in sorted(out.glob("*/x*/runs/*.zarr"))]
    found += [("paper", p) for p in sorted(baseline.glob("heart-N*-s[0-3].zarr"))]
    if scan is not None:
        found += [(f"scan:{scan.name}", p) for p in sorted((scan / "runs").glob("*.zarr"))]
    return found


def score(pairs: list[tuple[str, Path]], rows_path: Path) -> list[dict]:
    """The rows of ``pairs``, from ``rows_path`` where scored before, else from the complete stores."""
    rows = [json.loads(line) for line in rows_path.read_text().splitlines()] if rows_path.exists() else []
    done = {(r["lever"], Path(r["store"]).name) for r in rows}
    with rows_path.open("a") as f:
        for lever, path in pairs:
            if (lever, path.name) in done:
                continue
            try:
                row = {"lever": lever, **run_row(path)}
            except Exception as exc:  # still running, or not a complete store: scored next time
                print(f"skipped {path}: {type(exc).__name__}: {exc}")
                continue
            f.write(json.dumps(row) + "\n")
            rows.append(row)
    return rows


def table(rows: list[dict]) -> str:
    head = (
        "| lever | N | seeds | lowest artery share (min) | bif. > 2 mm off (max) | mean drop mmHg (max) "
        "| min terminal P mmHg (min) | excl. W | cavity | D err | L err | L err LAD | wall s |"
    )
    lines = [head, "|" + "---|" * 13]
    levers = sorted({r["lever"] for r in rows}, key=lambda s: (s != "paper", s))
    for lever in levers:
        for n in sorted({r["n_terminals"] for r in rows if r["lever"] == lever}):
            seeds = 3 if lever.startswith("scan:") else 1  # a scan's four seeds; the levers' two
            group = [r for r in rows if r["lever"] == lever and r["n_terminals"] == n and r["seed"] <= seeds]
            if not group:
                continue
            share = [min(v for k, v in r.items() if k.startswith("terminal_share_")) for r in group]
            off = [100 * r["bifurcations_off_organ_share"] for r in group]
            drop = [r["pressure_drop_mean"] / MMHG for r in group]
            low = [r["terminal_pressure_min"] / MMHG for r in group]
            d_err = [np.mean([r[f"diameter_error_{a}"] for a in ARTERIES]) for r in group]
            l_err = [np.mean([r[f"length_error_{a}"] for a in ARTERIES]) for r in group]
            lines.append(
                f"| {lever} | {n} | {len(group)} | {np.mean(share):.2f} ({min(share):.2f}) "
                f"| {np.mean(off):.1f} % ({max(off):.1f}) | {np.mean(drop):.0f} ({max(drop):.0f}) "
                f"| {np.mean(low):.0f} ({min(low):.0f}) | {np.mean([r['cost_exclusion_weighted'] for r in group]):.3g} "
                f"| {max(r['cavity_share'] for r in group):.3f} | {np.mean(d_err):.3f} | {np.mean(l_err):.3f} "
                f"| {np.mean([r['length_error_LAD'] for r in group]):.3f} "
                f"| {np.mean([r['wall_seconds'] for r in group]):.0f} |"
            )
    return "\n".join(lines)


def quick() -> str:
    """A tiny lever run written and scored in a temporary directory: the script's wiring."""
    from vasc_pipeline import config, job, sweep

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "levers"
        cfg = config.compose(
            ["n_terminals=40", "anneal.steps=20000", "seed=0", f"output_dir={out / 'A' / 'x1'}"]
            + ["tissue.bifurcation_reach=0", "physics.gamma=2.3333333333333335"]
        )
        for j in sweep.expand(cfg):
            job.run_job(j)
        text = table(score(stores(out, Path(tmp) / "none"), Path(tmp) / "scored.jsonl"))
    print(text)
    return text


def main(argv: list[str] | None = None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results/studies/model_levers"), help="run.sh's OUT")
    parser.add_argument("--baseline", type=Path, default=BASELINE, help="the paper's model's run stores")
    parser.add_argument("--scan", type=Path, default=None, help="a size scan's output_dir (scored too)")
    parser.add_argument("--quick", action="store_true", help="a tiny run, scored in a temporary directory")
    args = parser.parse_args(argv)
    if args.quick:
        return quick()
    text = table(score(stores(args.out, args.baseline, args.scan), HERE / "scored.jsonl"))
    print(text)
    return text


if __name__ == "__main__":
    main()
