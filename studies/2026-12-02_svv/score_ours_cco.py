"""Our CCO (``method=cco``) scored by the same code as svv's trees (run in OUR env).

    python benchmarks/studies/2026-12-02_svv/score_ours_cco.py --n 1000 6000 \
        --rows benchmarks/studies/2026-12-02_svv/rows_cco.jsonl

One CCO tree per N (``cco.grow(problem, seed)``, seed 0: random sites with Schreiner's
distance criterion, growth only timed) on the heart of ``tissue=heart n_terminals=N``,
then :func:`score_svv.score_arrays` (our C_v, C_w, C_o, C_s, cavity share, Kassab errors
with our radii). The anneal is not rerun: its rows are quoted from
``benchmarks/results/time_to_quality_rows.jsonl``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, nargs="+", default=[1000, 6000])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rows", type=Path, default=Path(__file__).with_name("rows_cco.jsonl"))
    args = ap.parse_args()
    from score_svv import score_arrays

    from vasc_pipeline import cco, config, engine

    for n in args.n:
        problem = engine.build_problem(config.compose(["tissue=heart", f"n_terminals={n}", "method=cco"]))
        result = cco.grow(problem, args.seed)
        t = result.tree
        row = {"method": "cco (ours)", "seed": args.seed, "wall_seconds": result.wall_seconds}
        row.update(score_arrays(t.parent, t.position, t.n_inlets, t.n_terminals, problem=problem))
        print(json.dumps(row), flush=True)
        with args.rows.open("a") as f:
            f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
