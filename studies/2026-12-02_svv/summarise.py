"""The study's table: svv's trees beside our CCO and our anneal (run in OUR env or any python).

    python studies/2026-12-02_svv/summarise.py
    python studies/2026-12-02_svv/summarise.py --quick   # the same: it reads committed rows only

Reads this folder's ``rows.jsonl`` (svv, ``score_svv.py``) and ``rows_cco.jsonl`` (our CCO,
``score_svv.py --cco``), and quotes, without rerunning anything:

- our anneal: ``benchmarks/results/time_to_quality_rows.jsonl``, the rows of today's
  ``anneal=fast`` (label "fast, steps_exponent=1.7, coarse_exclusion_phase=0.4", budget 1;
  N = 1000: 4 seeds, N = 6000: 2 seeds; mean over seeds, min-max in brackets). Those rows
  hold C_v + C_w + (A_o/A_wv) C_o, C_s, cavity share and the D and L errors, not C_v + C_w
  alone;
- our CCO and anneal on CCO's sites: ``benchmarks/results/cco_comparison/heart/runs.jsonl``
  (N = 1000; C_v + C_w, (A_o/A_wv) C_o; their Kassab column is the mean of D and L).

Prints markdown tables.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
ROOT = HERE.parents[1]
FAST = "fast, steps_exponent=1.7, coarse_exclusion_phase=0.4"
ART = ("RCA", "LAD", "LCX")


def _rows(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()] if path.exists() else []


def _agg(vals) -> str:
    v = np.array([x for x in vals if x is not None and np.isfinite(x)], float)
    if v.size == 0:
        return "–"
    if v.size == 1:
        return f"{v[0]:.4g}"
    return f"{v.mean():.4g} [{v.min():.3g}–{v.max():.3g}]"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="the same tables: they need no runs (for the tests)")
    parser.parse_args(argv)
    svv = _rows(HERE / "rows.jsonl")
    cco = _rows(HERE / "rows_cco.jsonl")
    ttq = [
        r
        for r in _rows(ROOT / "benchmarks/results/time_to_quality_rows.jsonl")
        if r["anneal"] == FAST and r["budget"] == 1.0
    ]
    cmp = _rows(ROOT / "benchmarks/results/cco_comparison/heart/runs.jsonl")
    ns = sorted({r["n"] for r in svv} | {1000, 6000})

    print(
        "| N | method | trees | wall s | C_v [mW] | C_w [mW] | C_v + C_w [mW] | (A_o/A_wv) C_o [W] "
        "| C_v + C_w + (A_o/A_wv) C_o [W] | C_s | cavity share |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for n in ns:
        for label, sel in (
            ("svv (our cost: our radii)", [r for r in svv if r["n"] == n]),
            ("our CCO (rerun here, seed 0)", [r for r in cco if r["n"] == n]),
        ):
            if not sel:
                continue
            print(
                f"| {n} | {label} | {len(sel)} | {_agg(r['wall_seconds'] for r in sel)} "
                f"| {_agg(r['cost_volume'] * 1e3 for r in sel)} | {_agg(r['cost_power'] * 1e3 for r in sel)} "
                f"| {_agg(r['vascular'] * 1e3 for r in sel)} | {_agg(r['cost_exclusion_weighted'] for r in sel)} "
                f"| {_agg(r['vascular_exclusion'] for r in sel)} | {_agg(r['cost_supply'] for r in sel)} "
                f"| {_agg(r['cavity_share_ours'] for r in sel)} |"
            )
        sel = [r for r in cmp if r["n"] == n and r["method"] == "cco"]
        if sel:
            print(
                f"| {n} | our CCO, cco_comparison (CCO's sites, random order) | {len(sel)} "
                f"| {_agg(r['wall_seconds'] for r in sel)} | – | – | {_agg(r['vascular'] * 1e3 for r in sel)} "
                f"| {_agg(r['exclusion_scaled'] for r in sel)} | {_agg(r['vascular_exclusion'] for r in sel)} | – | – |"
            )
        sel = [r for r in cmp if r["n"] == n and r["method"] == "anneal"]
        if sel:
            print(
                f"| {n} | our anneal, cco_comparison (fast of 2026-11-27, CCO's sites fixed) | {len(sel)} "
                f"| {_agg(r['wall_seconds'] for r in sel)} | – | – | {_agg(r['vascular'] * 1e3 for r in sel)} "
                f"| {_agg(r['exclusion_scaled'] for r in sel)} | {_agg(r['vascular_exclusion'] for r in sel)} | – | – |"
            )
        sel = [r for r in ttq if r["n_terminals"] == n]
        if sel:
            print(
                f"| {n} | our anneal, time_to_quality (today's fast) | {len(sel)} "
                f"| {_agg(r['wall_seconds'] for r in sel)} | – | – | – | – "
                f"| {_agg(r['cost_vascular'] for r in sel)} | {_agg(r['cost_supply'] for r in sel)} "
                f"| {_agg(r['cavity_share'] for r in sel)} |"
            )

    print("\nKassab: mean |log10 model/Kassab|, diameter D and length L, element level, diameter-defined")
    print("| N | method | radii | " + " | ".join(f"{a} D | {a} L" for a in ART) + " |")
    print("|---|---|---|" + "---|---|" * len(ART))
    for n in ns:
        for label, sel, suffixes in (
            ("svv", [r for r in svv if r["n"] == n], ("ours", "own")),
            ("our CCO (rerun here, seed 0)", [r for r in cco if r["n"] == n], ("ours",)),
        ):
            for s in suffixes:
                if sel:
                    d = [_agg(r[f"diameter_error_{a}_{s}"] for r in sel) for a in ART]
                    ln = [_agg(r[f"length_error_{a}_{s}"] for r in sel) for a in ART]
                    cells = " | ".join(f"{x} | {y}" for x, y in zip(d, ln))
                    radii = "svv’s own (svv’s rule, recomputed)" if s == "own" else "ours"
                    print(f"| {n} | {label} | {radii} | {cells} |")
        sel = [r for r in ttq if r["n_terminals"] == n]
        if sel:
            cells = " | ".join(
                f"{_agg(r[f'diameter_error_{a}'] for r in sel)} | {_agg(r[f'length_error_{a}'] for r in sel)}"
                for a in ART
            )
            print(f"| {n} | our anneal, time_to_quality (today's fast) | ours | {cells} |")


if __name__ == "__main__":
    main()
