"""One rule per key that a sweep can scan: the same check for the key and for its axis.

``n_terminals``, ``physics.m_b``, ``seed`` and ``anneal.steps`` are checked by
:func:`vasc_pipeline.config.validate` with the rule of :data:`SWEPT_KEYS` that their axis
(``sweep.n_terminals``, ``sweep.m_b``, ``sweep.seeds``, ``sweep.steps``) is checked with
(:func:`sweep_axis`), so that a value is accepted or refused alike, with the same words.
"""

from __future__ import annotations

import math
from typing import Any

from .errors import ConfigError
from .keyspec import Rule, page_bound

__all__ = ["MAX_STEPS", "MAX_TERMINALS", "SEED_ACCEPTED", "seed_ok", "Rule", "SWEPT_KEYS", "sweep_axis"]

# Upper bounds, so that a typo'd exponent is refused here rather than overflowing after dispatch
# (Dask's messages carry 64-bit integers). 1e15 proposals are years at the kernel's ~1e7 moves/s.
MAX_STEPS = 10**15
MAX_TERMINALS = 10**8  # organ scale is 1e5-1e6 vessels; beyond, no grid or tree would fit in memory
SEED_ACCEPTED = "an integer in [0, 2^63)"  # seed and sweep.seeds alike (the generator takes 64-bit seeds)


def seed_ok(value: Any) -> bool:
    """A valid seed (``seed`` and every ``sweep.seeds`` entry): an integer in [0, 2^63)."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 2**63


# The keys a sweep can scan: one rule each, for the key (n_terminals, physics.m_b, seed,
# anneal.steps) and for its axis (sweep.n_terminals, sweep.m_b, sweep.seeds, sweep.steps).
SWEPT_KEYS = {
    "n_terminals": Rule(
        int,
        lambda v: 2 <= v <= MAX_TERMINALS,
        f"an integer in [2, {MAX_TERMINALS:.0e}]",
        doc=f"integer in [2, {page_bound(MAX_TERMINALS)}]",
        outside=(1, MAX_TERMINALS + 1, 64.5),
    ),
    "m_b": Rule(
        float, lambda v: v > 0 and math.isfinite(v), "a finite number > 0", doc="> 0", outside=(0.0, -1.0, True)
    ),
    "seeds": Rule(int, seed_ok, SEED_ACCEPTED, doc="integer in [0, 2^63)", outside=(-1, 2**63, 0.5)),
    "steps": Rule(
        int,
        lambda v: 1 <= v <= MAX_STEPS,
        f"an integer in [1, {MAX_STEPS:.0e}] (proposed moves per run)",
        doc=f"integer in [1, {page_bound(MAX_STEPS)}]",
        outside=(0, MAX_STEPS + 1),
    ),
}


def sweep_axis(axis: str, values: Any, default: Any) -> list:
    """The values of ``sweep.<axis>``: a non-empty list of distinct accepted values, or ``[default]``
    when the axis is not given."""
    if values is None:
        return [default]
    name, rule = f"sweep.{axis}", SWEPT_KEYS[axis]
    values = list(values)
    if not values:
        raise ConfigError(f"{name} must be a non-empty list ({rule.accepted}), got []")
    out = [rule.check(f"{name}[{i}]", v) for i, v in enumerate(values)]
    dupes = sorted({v for v in out if out.count(v) > 1})
    if dupes:
        raise ConfigError(f"{name} lists {dupes} more than once; every grid point must be distinct")
    return out
