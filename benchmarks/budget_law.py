"""How many moves a schedule needs as N grows: the exponent of the budget law, fitted.

Reads rows of ``benchmarks/time_to_quality.py`` (one schedule, several N and budgets,
seeds) and answers the organ-scale question "how many moves does today's schedule
need to reach a given quality as N grows?" in two ways, fitting moves ∝ N^alpha by least
squares in log-log over the N that reach each level:

- **absolute, per terminal**: the supply cost per terminal, C_s/N, is roughly comparable
  across N (a packing of N equal spheres). Its floor falls slowly with N, because the
  tissue's boundary, where spheres spill out, is a smaller share of a finer packing, so
  these exponents are if anything too low. For levels of C_s/N, the moves at which the
  mean over seeds reaches the level (interpolated linearly in log moves between budgets);
- **relative to the default**: the moves at which the mean C_s, and the mean vascular cost
  C_v + C_w + (A_o/A_wv) C_o (which grows with N and has no per-terminal scale), come within
  a fraction of what the schedule reaches at its default budget (x1) at that N. The N^2 law
  gives alpha = 2 here by construction when every budget fraction converges alike.

One JSON line per (N, budget) with the means and standard errors, then one per fit.

    python benchmarks/budget_law.py benchmarks/results/time_to_quality_rows.jsonl
    python benchmarks/budget_law.py ROWS.jsonl --label fast_v1 --levels 330 310 300
    python benchmarks/budget_law.py --quick       # synthetic rows obeying a known law (seconds)
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
from time_to_quality import SUMMARY_FIELDS, summarise


def points(rows: list[dict], label: str) -> list[dict]:
    """Mean ± SE over seeds per (N, budget) of one schedule or variant, with C_s/N and moves per terminal."""
    out = []
    for entry in summarise([r for r in rows if r["anneal"] == label]):
        n = entry["n_terminals"]
        entry["moves_per_terminal"] = entry["steps"] / n
        entry["supply_per_terminal"] = entry["cost_supply"] / n
        entry["supply_per_terminal_se"] = entry["cost_supply_se"] / n
        out.append(entry)
    return out


def moves_to_reach(steps: np.ndarray, values: np.ndarray, level: float) -> float | None:
    """Moves at which ``values`` (falling with ``steps``) first reach ``level``, linear in log moves; None outside."""
    order = np.argsort(steps)
    s, v = np.log(steps[order]), values[order]
    for k in range(len(s) - 1):
        if v[k] >= level >= v[k + 1] and v[k] != v[k + 1]:
            return float(np.exp(s[k] + (v[k] - level) / (v[k] - v[k + 1]) * (s[k + 1] - s[k])))
    return None


def fit_exponent(ns: list[int], moves: list[float]) -> dict:
    """Least-squares alpha (and its standard error with three or more N) of moves ∝ N^alpha."""
    x, y = np.log(np.asarray(ns, dtype=float)), np.log(np.asarray(moves, dtype=float))
    if len(x) < 2:
        return {"alpha": None}
    a, b = np.polyfit(x, y, 1)
    out = {"alpha": round(float(a), 3)}
    if len(x) > 2:
        resid = y - (a * x + b)
        out["alpha_se"] = round(float(np.sqrt(resid @ resid / (len(x) - 2) / ((x - x.mean()) @ (x - x.mean())))), 3)
    return out


def fits(pts: list[dict], levels: list[float], within: list[float]) -> list[dict]:
    """The exponent per absolute level of C_s/N and per relative distance from the default budget's result."""
    by_n = defaultdict(list)
    for p in pts:
        by_n[p["n_terminals"]].append(p)
    out = []
    for level in levels:
        reached = {}
        for n, ps in by_n.items():
            m = moves_to_reach(
                np.array([p["steps"] for p in ps]), np.array([p["supply_per_terminal"] for p in ps]), level
            )
            if m is not None:
                reached[n] = m
        out.append(_fit_row({"fit": "supply_per_terminal", "level": level}, reached))
    for key in ("cost_supply", "cost_vascular"):
        for frac in within:
            reached = {}
            for n, ps in by_n.items():
                default = [p for p in ps if p["budget"] == 1.0]
                if not default:
                    continue
                rel = np.array([p[key] / default[0][key] for p in ps])
                m = moves_to_reach(np.array([p["steps"] for p in ps]), rel, 1.0 + frac)
                if m is not None:
                    reached[n] = m
            out.append(_fit_row({"fit": f"{key}_within_default", "within": frac}, reached))
    return out


def _fit_row(head: dict, reached: dict[int, float]) -> dict:
    """One printed fit: what was fitted, the moves at which each N reached it, the exponent."""
    ns = sorted(reached)
    return head | {"moves": {n: f"{reached[n]:.3g}" for n in ns}} | fit_exponent(ns, [reached[n] for n in ns])


def synthetic_rows(alpha: float = 1.5) -> list[dict]:
    """Rows whose C_s/N = 250 + 2e3 (moves / N^alpha)^(-1/4) exactly: the fits must return alpha."""
    rows = []
    for n in (500, 1000, 2000):
        default = 1e8 * (n / 1000) ** 2
        for budget in (0.03, 0.1, 0.3, 1.0):
            steps = budget * default
            c = 250.0 + 2e3 * (steps / n**alpha) ** -0.25
            for seed in (0, 1):
                rows.append(
                    {"anneal": "fast_v1", "n_terminals": n, "steps": steps, "budget": budget, "seed": seed}
                    | dict.fromkeys(SUMMARY_FIELDS, 0.0)
                    | {"cost_supply": c * n, "cost_vascular": 1.0}
                )
    return rows


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rows", type=Path, nargs="*", help="rows.jsonl files of time_to_quality.py")
    parser.add_argument("--label", default="fast_v1", help="the schedule or variant label (default fast_v1)")
    parser.add_argument("--levels", type=float, nargs="+", default=[330.0, 320.0, 310.0, 300.0, 290.0])
    parser.add_argument("--within", type=float, nargs="+", default=[0.02, 0.05, 0.1])
    parser.add_argument("--quick", action="store_true", help="synthetic rows of a known law (alpha = 1.5), seconds")
    args = parser.parse_args(argv)
    if args.quick:
        rows, args.levels = synthetic_rows(), [700.0, 600.0]
    else:
        if not args.rows:
            parser.error("give rows.jsonl files (or --quick)")
        rows = [json.loads(line) for path in args.rows for line in path.read_text().splitlines() if line.strip()]
    pts = points(rows, args.label)
    found = fits(pts, args.levels, args.within)
    for line in [*pts, *found]:
        print(json.dumps(line))
    return found


if __name__ == "__main__":
    main()
