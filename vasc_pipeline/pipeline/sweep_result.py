"""What a sweep did: :class:`SweepResult`, returned by :func:`vasc_pipeline.pipeline.orchestrate.run_sweep`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["SweepResult"]


@dataclass
class SweepResult:
    """The outcome of one call of ``run_sweep`` (run ids name the runs).

    ``runs`` holds the job summaries of this call (:func:`vasc_pipeline.pipeline.job.run_job`);
    ``complete``, ``resumed`` (completed from a checkpoint) and ``skipped`` (complete before)
    are run ids; ``failed`` maps a run id to its error text, and ``deterministic`` names the
    failed runs whose job raised (a rerun fails the same way); ``damaged`` maps a run id to
    what is wrong with its store (left out). ``reduction`` is a
    :class:`vasc_pipeline.reduce.Reduction` (None when not reduced), ``reduction_error`` its
    failure as text. ``dry_run``: only the plan was printed (``cluster.dry_run``).
    """

    output_dir: str
    runs: list[dict[str, Any]] = field(default_factory=list)
    complete: list[str] = field(default_factory=list)
    resumed: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    deterministic: set[str] = field(default_factory=set)
    damaged: dict[str, str] = field(default_factory=dict)
    wall_seconds: float = 0.0
    reduction: Any = None
    reduction_error: str | None = None
    dry_run: bool = False

    @property
    def done(self) -> set[str]:
        """Every run complete now or before."""
        return set(self.complete) | set(self.skipped)
