"""The progress display of a sweep: one live line (runs done, steps/s, ETA, best cost per cell) and the end summary.

Workers publish progress events on :data:`PROGRESS_TOPIC`; :class:`Progress` receives them
on the client and redraws its line in place on a terminal (a line every 30 s otherwise).
:func:`print_summary` is the paragraph after the last run: what completed, failed or was
left out, and what to do about it.
"""

from __future__ import annotations

import math
import os
import threading
import time
from typing import TYPE_CHECKING, Any, TextIO

from ..store.layout import RUNS_DIR
from ..store.run_store import RunStore

if TYPE_CHECKING:
    from .planning import Plan
    from .sweep_result import SweepResult

__all__ = ["Progress", "print_summary", "runs_phrase", "PROGRESS_TOPIC"]

PROGRESS_TOPIC = "vasc_pipeline.pipeline.progress"  # a Dask topic name, not a module path


def runs_phrase(n: int) -> str:
    return f"{n} run" if n == 1 else f"{n} runs"


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{s:02d}s" if m else f"{s}s")


class Progress:
    """Runs done / total, steps per second, best cost per cell, ETA: one line, updated in place on a TTY."""

    def __init__(self, p: Plan, stream: TextIO, interval: float | None) -> None:
        jobs = [j for j in p.jobs if j.run_id not in p.damaged]  # damaged stores are left out
        self.total_runs = len(jobs)
        self.totals = {j.run_id: p.total_steps[j.run_id] for j in jobs}
        self.cells = {j.run_id: j.cell for j in jobs}
        self.steps = {
            j.run_id: (self.totals[j.run_id] if j.run_id in p.complete else p.started.get(j.run_id, 0)) for j in jobs
        }
        self.steps_at_start = sum(self.steps.values())
        self.best: dict[str, float] = {}
        self.phases: dict[str, tuple[int, int, int]] = {}  # run_id -> (phases done, phases, parts): anneal.parts > 1
        self.done = len(p.complete)
        self.stream = stream
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.interval = interval if interval is not None else (1.0 if self.tty else 30.0)
        self.started = time.monotonic()
        self.last_print = 0.0
        self.lock = threading.Lock()
        self.any_started = False  # a job of this sweep began on a worker
        for j in jobs:
            if j.run_id in p.complete:
                cost = RunStore.open(j.store, mode="r").attrs.get("cost", {}).get("total")
                self._cost(j.run_id, cost)

    def _cost(self, run_id: str, cost: float | None) -> None:
        if cost is not None and math.isfinite(cost):
            cell = self.cells[run_id]
            self.best[cell] = min(cost, self.best.get(cell, math.inf))

    def event(self, event: Any) -> None:
        """Handler of worker progress events (runs on the client's event-loop thread)."""
        msg = event[1] if isinstance(event, tuple) else event
        with self.lock:
            if msg.get("started"):
                self.any_started = True
            elif msg.get("run_id") in self.steps:
                self.steps[msg["run_id"]] = int(msg["step"])
                self._cost(msg["run_id"], msg.get("cost"))
                if msg.get("phase"):
                    self.phases[msg["run_id"]] = tuple(msg["phase"])

    def finished(self, summary: dict) -> None:
        with self.lock:
            self.done += 1
            self.steps[summary["run_id"]] = self.totals[summary["run_id"]]
            self.phases.pop(summary["run_id"], None)
            self._cost(summary["run_id"], summary.get("cost"))
        how = f"resumed from step {summary['resumed_from']}" if summary["resumed_from"] else "from step 0"
        if summary["status"] == "skipped":
            how = "already complete"
        cost = "?" if summary.get("cost") is None else f"{summary['cost']:.6g}"
        self._write(f"[{self.done}/{self.total_runs}] {summary['run_id']} complete ({how}), cost {cost}", newline=True)
        for text in summary.get("warnings", ()):  # checkpoint fallbacks happen on the worker: say so here
            self._write(f"    warning: {text}", newline=True)

    def failed(self, run_id: str, error: str) -> None:
        with self.lock:
            self.done += 1
        self._write(f"[{self.done}/{self.total_runs}] {run_id} FAILED: {error}", newline=True)

    def line(self) -> str:
        with self.lock:
            elapsed = max(time.monotonic() - self.started, 1e-9)
            done_steps = sum(self.steps.values())
            rate = (done_steps - self.steps_at_start) / elapsed
            remaining = sum(self.totals.values()) - done_steps
            best = ", ".join(f"{c} {v:.4g}" for c, v in sorted(self.best.items()))
            done = self.done
            phases = ", ".join(f"{r} phase {i}/{n} in {k} parts" for r, (i, n, k) in sorted(self.phases.items()))
        eta = remaining / rate if rate > 0 else math.inf
        return (
            f"runs {done}/{self.total_runs} | {rate:.3g} steps/s | ETA {_duration(eta)} | "
            f"best cost per cell: {best or '-'}" + (f" | {phases}" if phases else "")
        )

    def tick(self, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self.last_print >= self.interval:
            self.last_print = now
            self._write(self.line(), newline=not self.tty)

    def close(self) -> None:
        """The last progress line, ended: whatever is written next starts on a line of its own."""
        self.tick(force=True)
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()

    def _write(self, text: str, newline: bool) -> None:
        if self.tty:
            width = max(40, _terminal_width() - 1)
            # Clear the live line, then either leave a permanent line or redraw the live one.
            self.stream.write("\r\x1b[2K" + (text + "\n" if newline else text[:width]))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


def _terminal_width() -> int:
    try:
        return os.get_terminal_size().columns
    except OSError:
        return 120


def print_summary(result: SweepResult, p: Plan, stream: TextIO) -> None:
    n_failed = len(result.failed)
    lines = [
        f"vasc_pipeline: finished in {_duration(result.wall_seconds)}: {runs_phrase(len(p.jobs))}: "
        f"{len(result.complete)} completed now ({len(result.resumed)} resumed from a checkpoint), "
        f"{len(result.skipped)} already complete, {n_failed} failed"
        + (f", {len(result.damaged)} left out (damaged store)" if result.damaged else "")
        + "."
    ]
    deterministic = result.deterministic
    for run_id, error in result.failed.items():
        lines.append(f"  failed: {run_id}: {error}")
    if deterministic:
        lines.append(
            f"  {runs_phrase(len(deterministic))} failed deterministically ({', '.join(sorted(deterministic))}): a run "
            "is a pure function of its configuration and seed, so rerunning fails the same way. Change the "
            "configuration (the error above says what failed) or report it as a bug."
        )
    if n_failed > len(deterministic):
        lines.append(
            f"  Rerun the same command to retry the {'other ' if deterministic else ''}failed runs (finished "
            "runs are skipped; the others resume from their last checkpoint)."
        )
    for run_id, why in result.damaged.items():
        lines.append(f"  left out: {run_id}: {why}")
    lines.append(
        f"Results: {p.output_dir / RUNS_DIR}/<run_id>.zarr (xarray.open_zarr(path, group='trace'); "
        "tree/ and tissue/ groups; attrs cost, cost_recomputed, config)"
    )
    stream.write("\n".join(lines) + "\n")
    stream.flush()
