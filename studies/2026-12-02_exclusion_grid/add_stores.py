"""Rows of this study from complete run stores made elsewhere, e.g. the size scan under the
default that the study chose (variant b), whose runs are the variant's runs for the same N and
seed: the same config, the same budget.

    python benchmarks/studies/2026-12-02_exclusion_grid/add_stores.py LABEL STORE.zarr ...

Appends one row per store (benchmarks/time_to_quality.py's row) to rows.jsonl beside this
script, skipping stores already there and stores that are not complete.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))  # benchmarks/, for time_to_quality

from time_to_quality import row_of  # noqa: E402

from vasc_pipeline.store import RunStore  # noqa: E402


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    label, stores = argv[0], [str(Path(s).resolve()) for s in argv[1:]]
    rows_file = HERE / "rows.jsonl"
    known = {json.loads(line)["store"] for line in rows_file.read_text().splitlines() if line.strip()}
    added = 0
    with rows_file.open("a") as out:
        for store in stores:
            if store in known or RunStore.open(store, mode="r").status != "complete":
                continue
            out.write(json.dumps(row_of(store, label, 1.0)) + "\n")
            added += 1
    print(f"{added} rows added to {rows_file}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
