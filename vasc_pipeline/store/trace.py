"""The cost trace: its columns, one record, and the records of a run so far.

The one home of the trace's layout: the run store writes these columns (``trace/<name>``,
dimension "step"), the engine builds a :class:`TraceRecord` per block by name, the job and
the reduction read columns and records by name. Nothing outside this module knows a
column's position.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..model.costs import COST_TERM_LABELS, COST_TERMS

__all__ = ["TRACE_FIELDS", "TRACE_NAMES", "TRACE_META", "TraceRecord", "Trace"]

# (name, dtype, units, long_name) of the trace variables, in the stores' order; "step" is the dimension.
TRACE_FIELDS = (
    ("step", "int64", "1", "proposed moves so far"),
    ("temperature", "float64", "W", "annealing temperature (cost units)"),
    *((term, "float64", *COST_TERM_LABELS[term]) for term in COST_TERMS),
    ("total", "float64", "W", "annealed total cost C"),
    ("acceptance", "float64", "1", "accepted fraction of the block's proposals"),
)
TRACE_NAMES = tuple(f[0] for f in TRACE_FIELDS)
TRACE_META = {name: (units, long_name) for name, _, units, long_name in TRACE_FIELDS}  # name -> (units, long_name)
_DTYPES = {name: np.dtype(dtype) for name, dtype, *_ in TRACE_FIELDS}


class TraceRecord(NamedTuple):
    """One trace record: the state after a block (or, for CCO, after a terminal)."""

    step: int
    temperature: float
    volume: float
    power: float
    supply: float
    exclusion: float
    pressure: float
    total: float
    acceptance: float


# The record's fields are the columns, derived from COST_TERMS above: a drift fails on import.
if TraceRecord._fields != TRACE_NAMES:
    raise ImportError(f"TraceRecord fields {TraceRecord._fields} differ from the trace columns {TRACE_NAMES}")


class Trace:
    """The trace records of a run not yet written to its store, one per block."""

    def __init__(self) -> None:
        self._records: list[TraceRecord] = []

    def append(self, record: TraceRecord) -> None:
        self._records.append(record)

    def __len__(self) -> int:
        return len(self._records)

    @property
    def last(self) -> TraceRecord:
        """The latest record (IndexError when there is none)."""
        return self._records[-1]

    def clear(self) -> None:
        """Forget the records (after the store has taken them)."""
        self._records.clear()

    def arrays(self) -> dict[str, np.ndarray]:
        """One array per column (:data:`TRACE_NAMES`), of the column's dtype."""
        return {name: np.array([getattr(r, name) for r in self._records], dtype=_DTYPES[name]) for name in TRACE_NAMES}

    def take(self) -> dict[str, np.ndarray]:
        """The records as :meth:`arrays`, forgotten here: a checkpoint hands them to the store."""
        out = self.arrays()
        self.clear()
        return out
