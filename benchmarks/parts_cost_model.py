"""A measured cost model of one tree in parts (``anneal.parts``), and its projection.

One run per (N, K, seed) on the heart (default tissue, physics and schedule) is annealed with
its parts run one after the other on one thread, and every stage of every phase is timed:

- ``cut``: the two cuts of a phase (parts of subtrees, parts of terminals: the border margin);
- ``states``: building the parts' kernel states from the whole tree;
- ``parts``: each part's anneal, per round (what runs concurrently on the workers);
- ``merge``: writing the parts back and recomputing the whole tree's sums;
- ``whole``: the phase's moves on the whole tree (``1 - anneal.part_share`` of them);
- ``fixed``: building the problem, the initial tree, blocks before the phases, the polish.

The model of a run's wall time on W workers is then

    fixed + sum over phases (cut + states + merge + whole + sum over rounds LPT_W(parts)),

with LPT_W the longest-processing-time schedule of a round's parts on W workers (its wall
time), and, on a cluster, the parts' transfer: each part's job is pickled and shipped (its
size is measured: ``bytes_per_part``) at ``--bandwidth`` bytes per second from the run's task.
Per run, one JSON line (appended to ``--out/rows.jsonl``) holds these sums and the predicted
wall time for every ``--predict-workers``.

``--check ROWS.jsonl`` compares the predictions with measured runs of
``time_to_quality.py --parts K --workers W`` (matched on N, K, seed and workers). ``--project``
fits each component's per-move or per-phase cost against N over the measured sizes (a power
law; moves from the schedule's budget law) and prints the projected wall time for
``--project`` N on 16 and 64 workers, with K = W parts.

    python benchmarks/parts_cost_model.py --out results/parts_cost --sizes 1000 2000 6000 --parts 2 4 8
    python benchmarks/parts_cost_model.py --out results/parts_cost --check results/ttq_parts/rows.jsonl
    python benchmarks/parts_cost_model.py --out results/parts_cost --project 100000
    python benchmarks/parts_cost_model.py --quick      # seconds: wiring only

Times are those of one core of this machine; parts on threads of one machine share its
memory bandwidth, which the model does not know (``--check`` shows how much that costs).
"""

from __future__ import annotations

import argparse
import heapq
import importlib
import json
import pickle
import tempfile
import time
from pathlib import Path

import numpy as np

COMPONENTS = ("cut", "states", "merge", "whole")


def lpt_wall(seconds: list[float], workers: int) -> float:
    """Wall time of tasks of these durations on ``workers``, longest first to the idlest worker."""
    loads = [0.0] * max(1, min(workers, len(seconds)))
    for s in sorted(seconds, reverse=True):
        heapq.heapreplace(loads, loads[0] + s)
    return max(loads)


class PhaseTimer:
    """Times the stages of :func:`vasc_pipeline.engine.run.run_phase` by wrapping what it calls
    (the engine is unchanged; the wrappers only read the clock)."""

    def __init__(self) -> None:
        # the module, not the function ``engine.run`` that the package exports under its name
        self.module = importlib.import_module("vasc_pipeline.engine.run")
        self.phases: list[dict] = []
        self.bytes_per_part: list[int] = []
        self._saved = {}

    def _wrap(self, name, record):
        original = getattr(self.module, name)
        self._saved[name] = original

        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                record(time.perf_counter() - start)

        setattr(self.module, name, timed)

    def __enter__(self):
        m = self.module
        run_phase, anneal_parts = m.run_phase, m.anneal_parts

        def phase(*args, **kwargs):
            self.phases.append({**dict.fromkeys(COMPONENTS, 0.0), "parts": [], "in_phase": True})
            try:
                return run_phase(*args, **kwargs)
            finally:
                self.phases[-1]["in_phase"] = False

        def timed_parts(problem, model, state, parts, n_steps, phase_seed, map=map):
            seconds: list[float] = []

            def part_map(f, jobs):
                out = []
                for job in jobs:
                    if len(self.phases) == 1:
                        self.bytes_per_part.append(len(pickle.dumps(job, protocol=5)))
                    start = time.perf_counter()
                    out.append(f(job))
                    seconds.append(time.perf_counter() - start)
                return out

            start = time.perf_counter()
            result = anneal_parts(problem, model, state, parts, n_steps, phase_seed, part_map)
            self.phases[-1]["states"] += time.perf_counter() - start - sum(seconds)
            self.phases[-1]["parts"].append(seconds)
            return result

        self._saved["run_phase"], self._saved["anneal_parts"] = run_phase, anneal_parts
        m.run_phase, m.anneal_parts = phase, timed_parts
        self._wrap("make_parts", lambda s: self._add("cut", s))
        self._wrap("merge_parts", lambda s: self._add("merge", s))
        self._wrap("run_block", self._block)
        return self

    def _add(self, key, seconds):
        self.phases[-1][key] += seconds

    def _block(self, seconds):  # blocks outside the phases (packing) count in the row's "fixed"
        if self.phases and self.phases[-1]["in_phase"]:
            self.phases[-1]["whole"] += seconds

    def __exit__(self, *exc):
        for name, original in self._saved.items():
            setattr(self.module, name, original)


def predicted_wall(row: dict, workers: int, bandwidth: float | None = None) -> float:
    """The model's wall time [s] of the run in ``row`` on ``workers`` workers (transfer only
    with a ``bandwidth``, bytes/s)."""
    rounds = row["part_seconds"]
    wall = row["fixed"] + sum(row[c] for c in COMPONENTS) + sum(lpt_wall(r, workers) for r in rounds)
    if bandwidth:
        wall += row["bytes_per_part"] * sum(len(r) for r in rounds) / bandwidth
    return wall


def measure(n: int, k: int, seed: int, extra: list[str]) -> dict:
    """One instrumented run of the heart with N terminals in K parts (parts on one thread)."""
    from vasc_pipeline import config, engine

    cfg = config.compose(["tissue=heart", f"n_terminals={n}", f"anneal.parts={k}", *extra])
    start = time.perf_counter()
    with PhaseTimer() as timer:
        result = engine.run(cfg, seed=seed)
    wall = time.perf_counter() - start
    a = result.problem.config.anneal
    row = {
        "n_terminals": n,
        "parts": k,
        "seed": seed,
        "steps": result.steps,
        "phases": len(timer.phases),
        "part_share": float(a.part_share),
        "wall_seconds": wall,
        **{c: sum(p[c] for p in timer.phases) for c in COMPONENTS},
        "parts_serial": sum(sum(r) for p in timer.phases for r in p["parts"]),
        "part_seconds": [r for p in timer.phases for r in p["parts"]],
        "bytes_per_part": float(np.mean(timer.bytes_per_part)) if timer.bytes_per_part else 0.0,
        "cost_supply": result.costs_recomputed["supply"],
    }
    row["fixed"] = wall - sum(row[c] for c in COMPONENTS) - row["parts_serial"]
    row["imbalance"] = float(np.mean([max(r) / np.mean(r) for r in row["part_seconds"] if np.mean(r) > 0]))
    return row


def fit_power(ns, values) -> tuple[float, float]:
    """(a, b) of values ≈ a N^b, least squares in log-log (b = 1 for a single size)."""
    ns, values = np.log(np.asarray(ns, float)), np.log(np.maximum(np.asarray(values, float), 1e-12))
    if np.unique(ns).size < 2:
        return float(np.exp(values.mean() - ns.mean())), 1.0
    b, log_a = np.polyfit(ns, values, 1)
    return float(np.exp(log_a)), float(b)


def project(rows: list[dict], n: int, workers: list[int], bandwidth: float, share: float | None = None) -> list[dict]:
    """The model at N = ``n`` on each worker count (K = W parts), from power laws in N fitted
    to the measured rows: per move, the parts' and the whole tree's seconds; per phase, the
    cut, states and merge; per run, the fixed part; per part, the bytes shipped. ``share``:
    the ``anneal.part_share`` to project (default the rows'; the costs are per move, so the
    rows' own share only sets how their time divides)."""
    from vasc_pipeline import config
    from vasc_pipeline.config import scheduled_steps, to_run_config

    ns = [r["n_terminals"] for r in rows]
    measured = rows[0]["part_share"]
    per_move_parts = fit_power(ns, [r["parts_serial"] / (measured * r["steps"]) for r in rows])
    per_move_whole = fit_power(ns, [r["whole"] / ((1 - measured) * r["steps"]) for r in rows])
    s = measured if share is None else share
    per_phase = fit_power(ns, [(r["cut"] + r["states"] + r["merge"]) / r["phases"] for r in rows])
    fixed = fit_power(ns, [r["fixed"] for r in rows])
    bytes_part = fit_power(ns, [r["bytes_per_part"] for r in rows])
    imbalance = float(np.mean([r["imbalance"] for r in rows if r["parts"] == max(x["parts"] for x in rows)]))
    steps = scheduled_steps(to_run_config(config.compose(["tissue=heart", f"n_terminals={n}"])))
    phases = rows[0]["phases"]

    def law(fit):
        return fit[0] * n ** fit[1]

    out = []
    for w in workers:
        parts = s * steps * law(per_move_parts) * imbalance / w
        whole = (1 - s) * steps * law(per_move_whole)
        overhead = phases * law(per_phase)
        transfer = phases * 2 * w * law(bytes_part) / bandwidth
        out.append(
            {
                "n_terminals": n,
                "workers": w,
                "parts": w,
                "steps": steps,
                "hours": (law(fixed) + parts + whole + overhead + transfer) / 3600,
                "parts_hours": parts / 3600,
                "whole_hours": whole / 3600,
                "overhead_hours": overhead / 3600,
                "transfer_hours": transfer / 3600,
                "fixed_hours": law(fixed) / 3600,
                "laws": {
                    "part_s_per_move": per_move_parts,
                    "whole_s_per_move": per_move_whole,
                    "phase_overhead_s": per_phase,
                    "fixed_s": fixed,
                    "bytes_per_part": bytes_part,
                },
                "imbalance": imbalance,
                "part_share": s,
            }
        )
    return out


def check(rows: list[dict], measured_file: Path) -> list[dict]:
    """Predicted against measured wall time for every measured run that matches a row."""
    measured = [json.loads(line) for line in measured_file.read_text().splitlines() if line.strip()]
    out = []
    for m in measured:
        k, w = int(m.get("parts", 1)), int(m.get("workers", 1))
        for r in rows:
            if (r["n_terminals"], r["parts"], r["seed"]) == (m["n_terminals"], k, m["seed"]):
                p = predicted_wall(r, w)
                out.append(
                    {
                        **{x: m[x] for x in ("n_terminals", "seed")},
                        "parts": k,
                        "workers": w,
                        "measured_s": m["wall_seconds"],
                        "predicted_s": p,
                        "ratio": p / m["wall_seconds"],
                    }
                )
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[])
    parser.add_argument("--parts", type=int, nargs="+", default=[2, 4, 8])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--out", type=Path, help="directory of rows.jsonl")
    parser.add_argument("--override", action="append", default=[], help="extra config override")
    parser.add_argument("--predict-workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--check", type=Path, help="time_to_quality rows.jsonl of measured runs in parts")
    parser.add_argument("--project", type=int, help="N to project to (on 16 and 64 workers, K = W)")
    parser.add_argument("--project-share", type=float, help="anneal.part_share to project (default: the rows')")
    parser.add_argument("--bandwidth", type=float, default=1e9, help="bytes/s to ship parts (default 1e9)")
    parser.add_argument("--quick", action="store_true", help="one tiny run (N = 200) in a temporary dir")
    args = parser.parse_args(argv)
    if args.quick:
        args.sizes, args.parts, args.project = [200], [2], 1000
        args.override = [*args.override, "anneal.steps=200000", "anneal.part_phases=4"]
    tmp = tempfile.TemporaryDirectory() if args.out is None else None
    out = args.out if args.out is not None else Path(tmp.name)
    out.mkdir(parents=True, exist_ok=True)
    rows_file = out / "rows.jsonl"
    rows = [json.loads(line) for line in rows_file.read_text().splitlines()] if rows_file.exists() else []
    have = {(r["n_terminals"], r["parts"], r["seed"]) for r in rows}
    for n in args.sizes:
        for k in args.parts:
            for seed in args.seeds:
                if (n, k, seed) in have:
                    continue
                row = measure(n, k, seed, args.override)
                row["predicted_wall"] = {str(w): predicted_wall(row, w) for w in args.predict_workers}
                rows.append(row)
                with rows_file.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    print(
        f"{'N':>6} {'K':>3} {'seed':>4} {'wall':>8} {'fixed':>7} {'cut':>7} {'states':>7} {'merge':>7} "
        f"{'whole':>7} {'parts':>8} {'imbal':>6} {'MB/part':>8} "
        + " ".join(f"{'W=' + str(w):>8}" for w in args.predict_workers)
    )
    for r in rows:
        print(
            f"{r['n_terminals']:>6} {r['parts']:>3} {r['seed']:>4} {r['wall_seconds']:>8.1f} {r['fixed']:>7.1f} "
            + " ".join(f"{r[c]:>7.1f}" for c in COMPONENTS)
            + f" {r['parts_serial']:>8.1f} {r['imbalance']:>6.2f} {r['bytes_per_part'] / 1e6:>8.1f} "
            + " ".join(f"{predicted_wall(r, w):>8.1f}" for w in args.predict_workers)
        )
    result = {"rows": rows}
    if args.check:
        result["check"] = check(rows, args.check)
        for c in result["check"]:
            print(
                f"check N={c['n_terminals']} K={c['parts']} W={c['workers']} seed={c['seed']}: "
                f"measured {c['measured_s']:.0f} s, predicted {c['predicted_s']:.0f} s ({c['ratio'] - 1:+.0%})"
            )
    if args.project and rows:
        result["projection"] = project(rows, args.project, [16, 64], args.bandwidth, args.project_share)
        for p in result["projection"]:
            print(
                f"projection N={p['n_terminals']} on {p['workers']} workers (K = {p['parts']}, part_share "
                f"{p['part_share']:g}): {p['hours']:.1f} h "
                f"(parts {p['parts_hours']:.1f}, whole tree {p['whole_hours']:.1f}, phase overhead "
                f"{p['overhead_hours']:.2f}, transfer {p['transfer_hours']:.2f}, fixed {p['fixed_hours']:.2f})"
            )
    if tmp is not None:
        tmp.cleanup()
    return result


if __name__ == "__main__":
    main()
