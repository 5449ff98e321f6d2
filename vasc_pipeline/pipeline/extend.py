"""``+stage=extend``: the whole tree below the complete runs of an output_dir, batch by batch.

:func:`extend_run` is the plain function (no Hydra; Dask only through the ``mapper`` it is
given): it reads a complete run store, plans its territories (:mod:`vasc_pipeline.engine.extend`),
creates ``<output_dir>/extended/<run_id>.zarr`` (:class:`vasc_pipeline.store.extended.ExtendedStore`)
with the annealed tree in it, and streams batches of territories through ``mapper``: each
batch's subtrees are appended to the store as they come back, in territory order, and committed
with one attribute write. Peak memory is the tissue grid and the batches in flight, never the
whole tree. A killed extension resumes from its last committed batch when run again (the result
is the same: a pure function of the source, the config and the seed, whatever the batch size).

:func:`extend_output_dir` picks the runs (the lowest-cost seed of each cell, or every complete
run with ``extend.runs=all``) and fans the batches out on the sweep's Dask cluster
(``cluster=local|address|slurm``, :func:`vasc_pipeline.pipeline.cluster.open_client`);
:func:`extend_stage` is what ``python -m vasc_pipeline +stage=extend`` runs; it ends with the
reduction of the output_dir's whole trees (:func:`vasc_pipeline.reduce.extended.reduce_extended`,
``extend.zerod`` its 0D network).
"""

from __future__ import annotations

import collections
import math
import sys
import time
import uuid
from functools import partial
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, TextIO

import numpy as np

from ..engine.extend import TERRITORY_FIELDS, ExtendError, grow_batch, per_territory, plan_extension, read_source
from ..store.extended import ExtendedStore, extended_lock, identity_hash
from ..store.layout import RUNS_DIR, extended_path
from ..store.run_store import STATUS_COMPLETE, StoreError, is_empty_leftover
from .progress import _duration

__all__ = ["extend_run", "extend_output_dir", "extend_stage", "dask_mapper", "ExtendProgress"]


class ExtendProgress:
    """One line: territories done / total, fine terminals per second, ETA (in place on a TTY)."""

    def __init__(self, name: str, total: int, done: int, per_territory: int, stream: TextIO, interval=None) -> None:
        self.name, self.total, self.done, self.start_done = name, total, done, done
        self.per_territory = per_territory
        self.stream = stream
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.interval = interval if interval is not None else (1.0 if self.tty else 30.0)
        self.started = time.monotonic()
        self.last = 0.0
        self.printed = -1  # territories done at the last line
        self.paced = False  # the clock restarted at the first batch

    def line(self) -> str:
        elapsed = max(time.monotonic() - self.started, 1e-9)
        rate = (self.done - self.start_done) / elapsed if self.done > self.start_done else 0.0
        eta = 0.0 if self.done >= self.total else (self.total - self.done) / rate if rate > 0 else math.inf
        pace = f"{rate * self.per_territory:.3g}" if rate > 0 else "-"
        return (
            f"extend {self.name}: territories {self.done}/{self.total} | {pace} fine terminals/s | ETA {_duration(eta)}"
        )

    def update(self, done: int, force: bool = False) -> None:
        if not self.paced and done > self.done:
            # the pace from the first batch on: the start (compiling, workers loading the kernels) is not it
            self.started, self.start_done, self.paced = time.monotonic(), done, True
        self.done = done
        now = time.monotonic()
        if (force and done != self.printed) or now - self.last >= self.interval:
            self.last, self.printed = now, done
            self.stream.write(("\r\x1b[2K" + self.line()) if self.tty else self.line() + "\n")
            self.stream.flush()

    def close(self) -> None:
        self.update(self.done, force=True)
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def dask_mapper(client: Any, retries: int = 2, window: int | None = None) -> Callable:
    """A ``map`` on a Dask client: results in order, at most ``window`` tasks in flight (default
    twice the workers), so that the driver holds a few batches, never the whole tree."""
    if window is None:
        window = 2 * max(1, len(client.scheduler_info().get("workers", {})))

    def mapper(fn: Callable, items: Iterable) -> Iterator:
        token = uuid.uuid4().hex[:8]
        pending: collections.deque = collections.deque()
        try:
            for n, item in enumerate(items):
                pending.append(client.submit(fn, item, key=f"vasc-extend-{token}-{n}", pure=False, retries=retries))
                while len(pending) >= window:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            if pending:
                client.cancel(list(pending))

    return mapper


def _differences(stored: dict, requested: dict) -> list[str]:
    keys = sorted(set(stored) | set(requested))
    return [
        f"{k}: {stored.get(k)!r} (stored) vs {requested.get(k)!r} (requested)"
        for k in keys
        if stored.get(k) != requested.get(k)
    ]


def extend_run(
    source_path,
    out_path,
    n_terminals: int,
    *,
    seed: int | None = None,
    method=None,
    batch_territories: int = 200,
    mapper: Callable = map,
    stream: TextIO | None = None,
    progress_interval: float | None = None,
    compile_first: bool = False,
) -> dict[str, Any]:
    """Grow (or resume, or skip when complete) the whole tree below one complete run.

    Parameters
    ----------
    source_path : path
        A complete run store.
    out_path : path
        The extended store (``<output_dir>/extended/<run_id>.zarr``).
    n_terminals : int
        Fine terminals in all, rounded to a multiple of the run's N (``extend.n_terminals``).
    seed : int, optional
        Default the run's own seed.
    method : MethodConfig, optional
        The CCO settings (``method.candidates``, ``method.max_tries``, ``method.shrink``).
    batch_territories : int
        Territories per task; the result does not depend on it.
    mapper : callable
        ``mapper(fn, items)`` -> iterator of ``fn(item)`` in order (``map``, or :func:`dask_mapper`).
    compile_first : bool
        Grow one territory here before fanning out, so that workers load the compiled kernels.

    Returns
    -------
    dict
        ``run_id``, ``status`` ("complete" | "skipped"), ``resumed_from`` (territories already
        done), ``path``, ``n_terminals``, ``wall_seconds``, ``cost``, ``statistics``.
    """
    stream = stream or sys.stderr
    started = time.monotonic()
    source = read_source(source_path)
    plan = plan_extension(source, int(n_terminals), seed, method)
    out_path = Path(out_path)
    plan_seconds = time.monotonic() - started
    with extended_lock(out_path):
        store = _open_or_create(out_path, source_path, source, plan, _identity_config(plan, n_terminals))
        attrs = store.attrs
        if attrs.get("status") == STATUS_COMPLETE:
            cost, statistics = attrs.get("cost", {}), attrs.get("statistics", {})
            return _outcome(source, "skipped", None, out_path, plan, 0.0, cost, statistics)
        store.start_session()
        wall_before = float(store.attrs.get("wall_seconds", 0.0))
        resumed_from = store.territories_done or None
        if store.nodes_committed == 0:
            store.append(plan.annealed_part(), None, 0, wall_before)
        _announce(stream, source, plan, n_terminals, out_path, store.territories_done)
        clock = (wall_before, started)
        grow_seconds = _grow_territories(
            store, plan, mapper, batch_territories, clock, stream, progress_interval, compile_first
        )
        finish_started = time.monotonic()
        cost, statistics = _summary(plan, store.read_territories())
        wall = wall_before + time.monotonic() - started
        timings = {
            "plan_seconds": plan_seconds,
            "grow_seconds": grow_seconds,
            "finish_seconds": time.monotonic() - finish_started,
        }
        store.finish(cost=cost, statistics=statistics, timings=timings, wall_seconds=wall)
    _report_complete(stream, source.run_id, wall, cost, statistics)
    return _outcome(source, "complete", resumed_from, out_path, plan, wall, cost, statistics)


def _identity_config(plan, n_terminals) -> dict:
    """The settings an extended store is made with (its identity, with the source's digest)."""
    g = plan.growth
    return {
        "n_terminals_requested": int(n_terminals),
        "n_terminals": plan.n_fine,
        "per_territory": g.per_territory,
        "seed": g.seed,
        "method": {"candidates": g.candidates, "max_tries": g.max_tries, "shrink": g.shrink},
    }


def _open_or_create(out_path: Path, source_path, source, plan, config: dict) -> ExtendedStore:
    """The extended store at ``out_path``: reopened when it was made with this configuration and
    source (ExtendError otherwise), else created (an empty leftover directory replaced)."""
    if ExtendedStore.exists(out_path):
        store = ExtendedStore.open(out_path, mode="r+")
        attrs = store.attrs
        if attrs.get("identity") != identity_hash(config, source.digest):
            diff = _differences(attrs.get("config", {}), config)
            if attrs.get("source", {}).get("digest") != source.digest:
                diff.append(f"the source run {source.run_id} differs from the one extended ({source_path})")
            raise ExtendError(
                f"extended store {str(out_path)!r} was made with another configuration: {'; '.join(diff)}. "
                "Restore those settings (extend.n_terminals, extend.seed, method.*) to resume it, or move "
                "it aside for the new one"
            )
        return store
    if is_empty_leftover(out_path):
        out_path.rmdir()
    info = {
        "store": str(Path(source_path).resolve()),
        "run_id": source.run_id,
        "digest": source.digest,
        "config_hash": source.config_hash,
    }
    return ExtendedStore.create(
        out_path,
        run_id=source.run_id,
        source=info,
        config=config,
        n_nodes=plan.n_nodes,
        n_territories=plan.n_territories,
        physics=plan.whole_physics.as_attrs(),
        territory_fields=TERRITORY_FIELDS,
    )


def _announce(stream: TextIO, source, plan, n_terminals, out_path: Path, done: int) -> None:
    """The line that says what is grown: fine terminals, territories, rounding, resumption."""
    total = plan.n_territories
    stream.write(
        f"vasc_pipeline: extend {source.run_id}: {plan.n_fine} fine terminals ({plan.growth.per_territory} in each of "
        f"{total} territories"
        + (
            f"; extend.n_terminals={n_terminals} rounded to a multiple of N = {total}"
            if plan.n_fine != int(n_terminals)
            else ""
        )
        + (f"; resuming after {done} territories" if done else "")
        + f") into {out_path}\n"
    )
    stream.flush()


def _grow_territories(store, plan, mapper, batch_territories, clock, stream, progress_interval, compile_first) -> float:
    """Grow the territories not yet in ``store``, a batch a task, appended in order as they come;
    returns the seconds the growth took (after the compilation).

    ``clock``: (wall seconds of earlier sessions, this session's start on ``time.monotonic``).
    With ``compile_first`` one territory is grown here first, so that workers load compiled kernels.
    """
    g, total, done = plan.growth, plan.n_territories, store.territories_done
    wall_before, started = clock
    if compile_first and done < total:
        grow_batch(g, plan.batch(done, done + 1))
    progress = ExtendProgress(plan.source.run_id, total, done, g.per_territory, stream, progress_interval)
    grow_started = time.monotonic()
    size = max(1, int(batch_territories))
    batches = (plan.batch(lo, min(lo + size, total)) for lo in range(done, total, size))
    for result in mapper(partial(grow_batch, g), batches):
        tree = {k: result[k] for k in ("parent", "position", "radius", "kind")}
        columns = {name: result[name] for name, *_ in TERRITORY_FIELDS}
        store.append(tree, columns, len(result["n_voxels"]), wall_before + time.monotonic() - started)
        progress.update(store.territories_done)
    progress.close()
    return time.monotonic() - grow_started


def _report_complete(stream: TextIO, run_id: str, wall: float, cost: dict, statistics: dict) -> None:
    """The closing line: wall time, the whole tree's C_v + C_w and its annealed part's, coverage, cavities."""
    vascular = cost["volume"] + cost["power"]
    annealed = cost["annealed_volume"] + cost["annealed_power"]
    stream.write(
        f"vasc_pipeline: extend {run_id}: complete in {_duration(wall)}: C_v + C_w {vascular:.6g} W "
        f"(annealed part {annealed:.6g} W), coverage {100 * statistics['coverage']:.2f} % within 2 R_fine, "
        f"{statistics['cavity_segments']} fine segments in a cavity\n"
    )
    stream.flush()


def _outcome(source, status: str, resumed_from, out_path: Path, plan, wall: float, cost, statistics) -> dict[str, Any]:
    """What :func:`extend_run` returns."""
    return {
        "run_id": source.run_id,
        "status": status,
        "resumed_from": resumed_from,
        "path": str(out_path),
        "n_terminals": plan.n_fine,
        "wall_seconds": wall,
        "cost": cost,
        "statistics": statistics,
    }


def _summary(plan, columns: dict[str, np.ndarray]) -> tuple[dict, dict]:
    """The whole tree's C_v and C_w (the annealed part and the territories') and its diagnostics."""
    annealed_volume, annealed_power = plan.annealed_costs()
    fine_volume, fine_power = math.fsum(columns["volume"]), math.fsum(columns["power"])  # exact: order-free
    cost = {
        "volume": annealed_volume + fine_volume,
        "power": annealed_power + fine_power,
        "annealed_volume": annealed_volume,
        "annealed_power": annealed_power,
        "fine_volume": fine_volume,
        "fine_power": fine_power,
    }
    samples = int(columns["samples"].sum())
    length = math.fsum(columns["length"])
    voxels = columns["n_voxels"]
    statistics = {
        "coverage": int(columns["covered"].sum()) / samples if samples else math.nan,
        "coverage_samples": samples,
        "coverage_reach": 2.0 * plan.growth.supply_radius,
        "fine_supply_radius": plan.growth.supply_radius,
        "cavity_segments": int(columns["cavity_segments"].sum()),
        "cavity_length": math.fsum(columns["cavity_length"]),
        "outside_share": math.fsum(columns["outside_length"]) / length if length > 0 else math.nan,
        "fine_length": length,
        "sites_drawn": int(columns["drawn"].sum()),
        "per_territory": plan.per_territory,
        "territory_voxels_min": int(voxels.min()),
        "territory_voxels_median": float(np.median(voxels)),
        "territory_voxels_max": int(voxels.max()),
        "empty_territories": int(np.count_nonzero(voxels == 0)),
    }
    return cost, statistics


def extend_output_dir(cfg: Any, client: Any = None, stream: TextIO | None = None, progress_interval=None) -> dict:
    """Extend the chosen complete runs of ``cfg.output_dir`` (``extend.*``) on the cluster of
    ``cfg.cluster`` (or the given ``client``). Returns ``{"runs": [summaries], "failed": {run_id:
    error}, "skipped": {store: why left out}}``; ExtendError when there is nothing to extend."""
    import contextlib

    from ..reduce.runs import best_runs, find_runs
    from .cluster import check_cluster, open_client, probe_scheduler, wait_for_workers

    stream = stream or sys.stderr
    out = Path(cfg.output_dir)
    check_cluster(cfg.cluster)
    runs, skipped = find_runs(out)
    if not runs:
        raise ExtendError(
            f"output_dir {str(out)!r} holds no complete run under {str(out / RUNS_DIR)!r}: nothing to extend "
            "(run the sweep first)"
        )
    chosen = runs if cfg.extend.runs == "all" else list(best_runs(runs, ["cell_id"]).values())
    for r in chosen:  # bad input before anything is written
        per_territory(cfg.extend.n_terminals, r.n_terminals)
    size = cfg.extend.batch_territories
    n_batches = sum(-(-r.n_terminals // size) for r in chosen)
    result: dict[str, Any] = {"runs": [], "failed": {}, "skipped": skipped}
    if client is None and cfg.cluster.address:
        probe_scheduler(cfg.cluster)  # a wrong address is refused at once, never waited on
    with contextlib.ExitStack() as stack:
        if client is None:
            import distributed  # noqa: F401  (its import sets its log levels: before open_client quiets them)

            client = stack.enter_context(open_client(cfg.cluster, n_batches, out))
        wait_for_workers(client, cfg.cluster, n_batches)
        mapper = dask_mapper(client, cfg.cluster.retries)
        for r in chosen:
            try:
                summary = extend_run(
                    r.path,
                    extended_path(out, r.run_id),
                    cfg.extend.n_terminals,
                    seed=cfg.extend.seed,
                    method=cfg.method,
                    batch_territories=cfg.extend.batch_territories,
                    mapper=mapper,
                    stream=stream,
                    progress_interval=progress_interval,
                    compile_first=True,
                )
            except (ExtendError, StoreError) as exc:
                result["failed"][r.run_id] = str(exc)
                stream.write(f"vasc_pipeline: extend {r.run_id} FAILED: {exc}\n")
                continue
            except Exception as exc:  # a lost batch (its worker died each time): the store resumes
                result["failed"][r.run_id] = f"{type(exc).__name__}: {exc}"
                stream.write(
                    f"vasc_pipeline: extend {r.run_id} FAILED: {type(exc).__name__}: {exc}; committed batches "
                    "are kept: the same command resumes it\n"
                )
                continue
            result["runs"].append(summary)
    return result


def extend_stage(cfg: Any, stream: TextIO | None = None) -> int:
    """``+stage=extend``: extend the runs of ``cfg.output_dir``; returns the exit status (0 every
    chosen run extended and the whole trees reduced, 1 one failed or the reduction did, 2 bad input:
    nothing was extended, 130 interrupted)."""
    from .. import config as _config
    from ..config.schema import ConfigError

    stream = stream or sys.stderr
    try:
        cfg = _config.validate(_config.to_run_config(cfg))
    except ConfigError as exc:
        stream.write(f"vasc_pipeline: error: {exc}\nNothing was extended; existing results were left as they were.\n")
        return 2
    if not (Path(cfg.output_dir) / RUNS_DIR).is_dir():
        stream.write(
            f"vasc_pipeline: error: output_dir {cfg.output_dir!r} holds no runs/ directory: nothing to extend. "
            "Give the output_dir of a sweep (output_dir=...).\n"
        )
        return 2
    from .cluster import SweepStartError

    try:
        result = extend_output_dir(cfg, stream=stream)
    except (ExtendError, ConfigError, OSError) as exc:
        stream.write(f"vasc_pipeline: error: {exc}\n")
        return 2
    except SweepStartError as exc:
        stream.write(f"vasc_pipeline: error: {exc}\n")
        return 1
    except KeyboardInterrupt:
        stream.write(
            "\nvasc_pipeline: interrupted (Ctrl-C or SIGTERM). Committed batches are stored; the same command "
            "resumes.\n"
        )
        return 130
    reduced_ok = True
    if result["runs"]:
        from ..figures.extended import draw_extended
        from ..reduce.extended import reduce_extended

        try:  # every complete whole tree of the output_dir: morphometry, pressures, exports, then figures
            reduction = reduce_extended(cfg.output_dir, zerod=cfg.extend.zerod, stream=stream)
            if reduction.summary is not None:
                reduction.figures = draw_extended(reduction)
            reduced_ok = not reduction.errors
        except Exception as exc:  # the extended stores are complete: report; +stage=reduce reduces them again
            stream.write(f"vasc_pipeline: the whole trees' reduction FAILED: {type(exc).__name__}: {exc}\n")
            reduced_ok = False
    return 1 if result["failed"] or not reduced_ok else 0
