"""Rows of this study from complete run stores made elsewhere, e.g. the size scan under the
default that the study chose (variant b), whose runs are the variant's runs for the same N and
seed: the same config, the same budget.

    python studies/2026-12-02_exclusion_grid/add_stores.py LABEL STORE.zarr ...
    python studies/2026-12-02_exclusion_grid/add_stores.py --quick   # a tiny store, added to a temporary rows file

Appends one row per store (benchmarks/time_to_quality.py's row:
:func:`vasc_pipeline.reduce.fidelity.run_row` under the variant's label, budget 1) to rows.jsonl
beside this script, skipping stores already there and stores that are not complete.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from vasc_pipeline.reduce.fidelity import run_row
from vasc_pipeline.store import RunStore

HERE = Path(__file__).resolve().parent


def row_of(store: str, label: str) -> dict:
    """The study's row of a complete run store: time_to_quality.py's, at budget 1."""
    row = run_row(store)
    return {"n_terminals": row.pop("n_terminals"), "anneal": label, "budget": 1.0, **row}


def add(label: str, stores: list[str], rows_file: Path) -> int:
    """Append the rows of ``stores`` not yet in ``rows_file``; the count added."""
    stores = [str(Path(s).resolve()) for s in stores]
    lines = rows_file.read_text().splitlines() if rows_file.exists() else []
    known = {json.loads(line)["store"] for line in lines if line.strip()}
    added = 0
    with rows_file.open("a") as out:
        for store in stores:
            if store in known or RunStore.open(store, mode="r").status != "complete":
                continue
            row = row_of(store, label)
            print(json.dumps(row))
            out.write(json.dumps(row) + "\n")
            added += 1
    print(f"{added} rows added to {rows_file}")
    return added


def quick() -> int:
    """One tiny run of variant b's settings, added to a temporary rows file: the script's wiring."""
    from vasc_pipeline import config, job, sweep

    with tempfile.TemporaryDirectory() as tmp:
        cfg = config.compose(["n_terminals=40", "anneal.steps=20000", "seed=0", f"output_dir={Path(tmp) / 'b'}"])
        stores = [j.store for j in sweep.expand(cfg)]
        for j in sweep.expand(cfg):
            job.run_job(j)
        rows = Path(tmp) / "rows.jsonl"
        added = add("exclusion grid b, 1.153 mm", stores, rows)
        assert add("exclusion grid b, 1.153 mm", stores, rows) == 0  # a store is added once
    return added


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("label", nargs="?", help="the variant's label, e.g. 'exclusion grid b, 1.153 mm'")
    parser.add_argument("stores", nargs="*", help="complete run stores")
    parser.add_argument("--rows", type=Path, default=HERE / "rows.jsonl", help="the rows file (default: the study's)")
    parser.add_argument("--quick", action="store_true", help="a tiny store, added to a temporary rows file")
    args = parser.parse_args(argv)
    if args.quick:
        return quick()
    if args.label is None or not args.stores:
        parser.error("give a LABEL and at least one STORE")
    return add(args.label, args.stores, args.rows)


if __name__ == "__main__":
    main()
