"""Sweep expansion: a run config (with an optional ``sweep``) -> independent jobs.

A plain function of the config, no Hydra or Dask. The grid is the product of
``sweep.n_terminals`` x ``sweep.m_b`` x ``sweep.seeds`` (x ``sweep.steps`` when given) on
the config's tissue; an axis left ``None`` takes the base config's single value, so a
config without a sweep is a grid of one job (the single-run default).

Run ids are built from the grid coordinates only, e.g. ``sphere-N16-mb641.3-s0`` (and
``plane2d-N64-mb641.3-S100000-s0`` with a steps axis): adding grid points to an existing output_dir adds runs,
and anything else that changes (anneal, physics, ...) is caught by the config hash of the
existing store, never silently mixed.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from ..config.checks import validate
from ..config.identity import INPUTS, input_digests
from ..config.schema import ConfigError, RunConfig, from_stored, sweep_axis, to_run_config
from ..model.tissue.shapes import mask_geometry
from ..store.layout import cell_id, run_id, run_path

__all__ = ["Job", "expand", "run_id", "cell_id", "job_config", "stored_config"]


@dataclass(frozen=True)
class Job:
    """One run of a sweep.

    Attributes
    ----------
    run_id : str
        Stable id from the grid coordinates; the store is ``runs/<run_id>.zarr``.
    cell : str
        The run id without the seed: runs of one cell differ only by seed.
    coords : dict
        tissue, n_terminals, m_b [W m^-3], seed, steps (None without a steps axis), method
        ("anneal" or "cco").
    config : dict
        The run's own resolved config (plain types, no sweep or cluster section): what its
        store records as its identity. Paths are absolute so that workers anywhere find them.
    store : str
        Absolute path of the run store.
    validated : RunConfig, optional
        The same config validated (frozen) when the sweep was expanded: what the job runs.
    """

    run_id: str
    cell: str
    coords: dict = field(hash=False)
    config: dict = field(hash=False, repr=False)
    store: str = ""
    validated: RunConfig | None = field(default=None, hash=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.validated is not None and stored_config(self.validated) != {
            k: v for k, v in self.config.items() if k != INPUTS
        }:
            raise ValueError(f"job {self.run_id}: its validated config is not the config it stores")

    def run_config(self) -> RunConfig:
        """The run's validated config (validated here for a job built without one)."""
        return self.validated if self.validated is not None else validate(from_stored(self.config))


def stored_config(run_cfg: RunConfig) -> dict:
    """The config dict a run store holds: the resolved run config without sweep, cluster, stage and extend.

    Sections that cannot affect the run are left out: ``method`` (the CCO settings) for an
    anneal from a random tree, ``anneal`` for a CCO run (no schedule changes it). Keys that
    are new since older stores were written are handled by the hash
    (:data:`vasc_pipeline.config.KEYS_ADDED_LATER`), so those stores keep resuming.
    """
    config = asdict(run_cfg)
    del config["sweep"], config["cluster"]  # how a run is scheduled is not part of it
    config.pop("stage", None)
    config.pop("extend", None)  # what +stage=extend does with a run, not the run
    if run_cfg.method.name == "anneal" and run_cfg.anneal.init == "random":
        config.pop("method", None)
    if run_cfg.method.name == "cco":
        config.pop("anneal", None)
    return config


def _mask_geometry(tissue) -> dict:
    """A mask's voxel size and origin as its run takes them (a label map's header, a Zarr array's
    attrs), so that the run's config records them; other tissues keep theirs."""
    if tissue.name != "mask" or not tissue.path:
        return {}
    voxel_size, origin = mask_geometry(tissue.path, tissue.array, tissue.voxel_size, tissue.origin)
    return {"voxel_size": voxel_size, "origin": origin}


def _absolute(path: str | None) -> str | None:
    return None if path is None or "://" in path else str(Path(path).expanduser().resolve())


def job_config(cfg: RunConfig, n_terminals: int, m_b: float, seed: int, steps: int | None) -> RunConfig:
    """The run config of one grid point (no sweep; cluster left at its defaults)."""
    anneal = cfg.anneal if steps is None else replace(cfg.anneal, steps=int(steps))
    return replace(
        cfg,
        n_terminals=int(n_terminals),
        seed=int(seed),
        output_dir=str(Path(cfg.output_dir).expanduser().resolve()),
        physics=replace(cfg.physics, m_b=float(m_b)),
        anneal=anneal,
        tissue=replace(
            cfg.tissue,
            **_mask_geometry(cfg.tissue),
            path=_absolute(cfg.tissue.path),
            exclusion_path=_absolute(cfg.tissue.exclusion_path),
            inlets_path=_absolute(cfg.tissue.inlets_path),
        ),
        terminals=replace(cfg.terminals, path=_absolute(cfg.terminals.path)),
        sweep=None,
    )


def expand(cfg: Any) -> list[Job]:
    """The sweep's jobs in grid order (N, m_b, steps, seed), each validated.

    Raises :class:`~vasc_pipeline.config.ConfigError` naming the field for an empty or
    out-of-range axis, duplicate grid points, or a job config that fails
    :func:`~vasc_pipeline.config.validate`.
    """
    cfg = validate(to_run_config(cfg))  # the base config as given (job_config resolves output_dir)
    sw = cfg.sweep
    ns = sweep_axis("n_terminals", sw and sw.n_terminals, cfg.n_terminals)
    mbs = sweep_axis("m_b", sw and sw.m_b, cfg.physics.m_b)
    seeds = sweep_axis("seeds", sw and sw.seeds, cfg.seed)
    has_steps = sw is not None and sw.steps is not None
    steps_axis = sweep_axis("steps", sw.steps, None) if has_steps else [None]
    tissue = cfg.tissue.name
    method = cfg.method.name
    if method == "cco" and has_steps:
        raise ConfigError(
            "sweep.steps (proposed moves) has no meaning for method=cco, which adds N terminals; "
            "drop the steps axis or use method=anneal"
        )
    jobs = []
    digests = None  # the input files' content (identity.INPUTS), read once: the grid shares them
    for n, m_b, steps, seed in itertools.product(ns, mbs, steps_axis, seeds):
        run_cfg = validate(job_config(cfg, n, m_b, seed, steps))
        rid = run_id(tissue, n, m_b, seed, steps, method)
        config = stored_config(run_cfg)
        digests = input_digests(config) if digests is None else digests
        if digests:
            config[INPUTS] = dict(digests)
        coords = {"tissue": tissue, "n_terminals": n, "m_b": m_b, "seed": seed, "steps": steps, "method": method}
        jobs.append(
            Job(
                rid,
                cell_id(tissue, n, m_b, steps, method),
                coords,
                config,
                str(run_path(run_cfg.output_dir, rid)),
                validated=run_cfg,
            )
        )
    ids = [j.run_id for j in jobs]
    if len(set(ids)) != len(ids):  # two m_b equal to 10 significant digits
        raise ConfigError(
            "sweep grid values too close to tell apart in run ids (10 significant digits): "
            f"{sorted({i for i in ids if ids.count(i) > 1})}"
        )
    return jobs
