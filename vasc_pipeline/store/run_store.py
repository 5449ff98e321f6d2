"""The run store: one Zarr (v3) directory store per run, with atomic checkpoints.

Layout::

    runs/<run_id>.zarr
        attrs: run_id, seed, status ("running" | "complete"), steps_done, wall_seconds,
               config, config_hash, physics, cost, cost_recomputed (complete runs), and
               the pipeline's own: coords (grid point), total_steps, checkpoint (name of
               the current checkpoint group), trace_length (committed trace records),
               resumes (one {step, checkpoint} per resumed session), format
        tree/{parent, position, radius, kind}       final tree (complete runs)
        tissue/{mask, exclusion, distance}          the voxelised tissue, written at start
        tissue/supply_target                        with tissue.demand_path: each voxel's coverage target
        trace/{step, temperature, volume, ..., total, acceptance}   dim "step" (columns: store.trace)
        checkpoints/c<seq>/<state field>            kernel state (engine.state_arrays)

Atomicity (a crash mid-write never leaves a store that reads as valid). ``LocalStore``
writes one key atomically (temp file + rename) but nothing more, so every multi-key update
follows one rule: write new keys first, then flip one key (the root ``zarr.json``, i.e. the
root attributes) that makes them valid.

- A checkpoint is a new group ``checkpoints/c<seq>``: arrays first, then a manifest in the
  group's attributes (shape, dtype and CRC-32 of every array), then the root attributes
  ``checkpoint``, ``steps_done``, ``trace_length`` and ``wall_seconds`` in one write; only
  then are older checkpoints pruned (the previous one is kept as a fallback).
- Trace arrays grow by resize-then-write; records beyond the committed ``trace_length``
  (a crash between the two, or records after the last checkpoint) are cut on resume.
- On load every checkpoint's arrays are checked against its manifest (a missing chunk reads
  back as fill values, a truncated one fails to decode); a bad checkpoint is skipped for the
  previous good one with a :class:`CheckpointWarning`.
- A complete run's final tree and committed trace carry CRC-32 checksums (root attribute
  ``checksums``, written with ``status="complete"``); :func:`verify_store` checks a whole store
  before a sweep or the reduction uses it and names a damaged one (:class:`StoreDamaged`).

One writer per store: :func:`run_lock` holds an ``fcntl`` lock (:func:`file_lock`, which the
sweep's output_dir lock uses too) on ``runs/.locks/<run_id>.lock`` while a job writes (a
worker the scheduler gave up on may still be running). The locks, :class:`StoreError` and the base
class every store shares are :mod:`vasc_pipeline.store.group`'s (re-exported here).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import zarr

from ..config.identity import SWEEP_AXES, config_differences, config_hash, hashed_config, identity_differences
from ..config.schema import ConfigError
from .checkpoints import CHECKPOINTS, Checkpoint, CheckpointsMixin, CheckpointWarning, crc32
from .group import GroupStore, StoreError, create_group, file_lock, jsonable, run_lock, write_whole_array
from .layout import RUNS_DIR, run_path
from .trace import TRACE_FIELDS, TRACE_NAMES

__all__ = [
    "RunStore",
    "GroupStore",
    "Checkpoint",
    "CheckpointWarning",
    "StoreError",
    "StoreDamaged",
    "verify_store",
    "is_empty_leftover",
    "run_path",
    "run_lock",
    "file_lock",
    "config_hash",
    "hashed_config",
    "config_differences",
    "identity_differences",
    "SWEEP_AXES",
    "TRACE_FIELDS",
    "STATUS_RUNNING",
    "STATUS_COMPLETE",
    "RUNS_DIR",
]

STATUS_RUNNING, STATUS_COMPLETE = "running", "complete"
FORMAT = "vasc_pipeline.run/1"
TRACE_CHUNK = 4096  # records per trace chunk: a few appends per chunk, small files


class StoreDamaged(StoreError):
    """A run store that fails its checks (:func:`verify_store`): the message says what is wrong and what to do."""


def is_empty_leftover(path: str | os.PathLike) -> bool:
    """An empty directory where a store was about to be created (a crash before its zarr.json)."""
    path = Path(path)
    return path.is_dir() and not any(path.iterdir())


def verify_store(path: str | os.PathLike) -> "RunStore":
    """Open a run store read-only and check it whole, or raise :class:`StoreDamaged`.

    Checked: a readable ``zarr.json`` of this format; the committed trace records decode
    (every store) and, for a complete one, the final tree and trace match the CRC-32
    recorded with them (stores written before checksums existed: they decode). Checkpoints
    are not checked here: a bad one is skipped for the previous one when the run resumes.
    The message names the store, what is wrong, and what to do.
    """
    path = Path(path)
    try:
        store = RunStore.open(path, mode="r")
        store.verify()
    except Exception as exc:
        what = str(exc) if isinstance(exc, StoreError) else f"{type(exc).__name__}: {exc}"
        raise StoreDamaged(
            f"run store {str(path)!r} is damaged: {what}. Move it aside (e.g. mv {path} "
            f"{path}.damaged) and rerun the same command to run it again from the start; the "
            "other runs are not affected"
        ) from exc
    return store


class RunStore(GroupStore, CheckpointsMixin):
    """One run's Zarr store. Create with :meth:`create`, reopen with :meth:`open`.

    The checkpoint methods (:meth:`write_checkpoint`, :meth:`load_checkpoint`,
    :meth:`record_resume`) are :class:`vasc_pipeline.store.checkpoints.CheckpointsMixin`'s.
    """

    # -- creation and opening ---------------------------------------------------------------

    @classmethod
    def create(
        cls,
        path: str | os.PathLike,
        *,
        run_id: str,
        seed: int,
        config: Mapping[str, Any],
        coords: Mapping[str, Any],
        total_steps: int,
    ) -> "RunStore":
        """A new store (refuses to overwrite) holding the run's identity and ``status="running"``."""
        path = Path(path)
        config = jsonable(config)
        attrs = {
            "format": FORMAT,
            "run_id": run_id,
            "seed": int(seed),
            "status": STATUS_RUNNING,
            "steps_done": 0,
            "total_steps": int(total_steps),
            "wall_seconds": 0.0,
            "config": config,
            "config_hash": config_hash(config),
            "coords": jsonable(coords),
            "checkpoint": None,
            "trace_length": 0,
            "resumes": [],
        }
        group = create_group(path, attrs, "run store")
        store = cls(path, group)
        store._create_trace()
        return store

    @classmethod
    def open(cls, path: str | os.PathLike, mode: str = "r+") -> "RunStore":
        """Open an existing store; :class:`StoreError` names the path if it is not a readable run store."""
        path = Path(path)
        if not (path / "zarr.json").is_file():
            raise StoreError(f"{str(path)!r} is not a run store (no zarr.json: its root metadata is missing)")
        try:
            # Finished stores carry consolidated metadata; unfinished ones must be read live.
            group = zarr.open_group(str(path), mode=mode, zarr_format=3)
            attrs = dict(group.attrs)
        except Exception as exc:  # a damaged zarr.json: nothing in it can be trusted
            raise StoreError(
                f"run store {str(path)!r} is unreadable ({exc}); move it away to restart that run"
            ) from exc
        if attrs.get("format") != FORMAT or "config_hash" not in attrs:
            raise StoreError(f"{str(path)!r} is not a vasc_pipeline run store (attrs format={attrs.get('format')!r})")
        return cls(path, group)

    # -- attributes -------------------------------------------------------------------------

    @property
    def run_id(self) -> str:
        return self.group.attrs["run_id"]

    def _set_attrs(self, **values: Any) -> None:
        """One atomic write of the root ``zarr.json`` with the given attributes changed."""
        self.group.update_attributes(jsonable(values))

    def check_config(self, config: Mapping[str, Any]) -> None:
        """Refuse (:class:`ConfigError`) a requested config whose result-determining part differs."""
        requested = jsonable(config)
        # The stored config is hashed anew: the hash's definition may have grown (new keys
        # at their neutral values are left out), the stored string would then be stale.
        if config_hash(requested) == config_hash(self.group.attrs["config"]):
            return
        diff = config_differences(self.group.attrs["config"], requested)
        if not diff:  # a store from before the input digests (identity.INPUTS): compared without them
            return
        raise ConfigError(
            f"run {self.run_id!r} in {str(self.path)!r} was started with a different configuration, and runs "
            f"are never mixed: {'; '.join(diff) or 'config hash differs'}. Restore those settings to resume it, "
            "or choose a new output_dir (output_dir=...) for the changed configuration."
        )

    # -- tissue -----------------------------------------------------------------------------

    def write_start(self, tissue, physics: Mapping[str, Any]) -> None:
        """At a run's first start: the ``physics`` attribute and the voxelised tissue."""
        self._set_attrs(physics=dict(physics))
        self.write_tissue(tissue)

    def write_tissue(self, tissue) -> None:
        """``tissue/mask`` and ``tissue/exclusion`` (uint8) and ``tissue/distance`` (float32, voxel units).

        ``distance`` is the map the exclusion term used: the distance transform of the
        exclusion domain (the tissue plus, for the heart, the ventricular cavities), on the
        exclusion grid (attrs ``voxel_size``, ``origin``). Dims (z, y, x) on the tissue's grid; on
        a grid of its own (``tissue.exclusion_voxel_size``) (z_exclusion, y_exclusion, x_exclusion).
        """
        attrs = {
            "voxel_size": float(tissue.voxel_size),
            "origin": [float(v) for v in tissue.origin],
            "units_voxel_size": "m",
            "name": tissue.name,
            "ndim": int(tissue.ndim),
            "inlet_names": list(tissue.inlet_names),
        }
        grid = tissue.exclusion_grid
        own_grid = grid.distance is not tissue.distance
        attrs["exclusion_voxel_size"] = float(grid.voxel_size)
        attrs["exclusion_origin"] = [float(v) for v in grid.origin]
        group = self.group.require_group("tissue")
        group.update_attributes(attrs)
        zyx = ["z", "y", "x"]
        specs = (
            ("mask", tissue.mask, "uint8", zyx, {**attrs, "long_name": "tissue mask (1 = tissue)", "units": "1"}),
            (
                "exclusion",
                tissue.exclusion,
                "uint8",
                zyx,
                {"long_name": "exclusion domain of large vessels (1 = excluded: tissue and cavities)", "units": "1"},
            ),
            (
                "distance",
                grid.distance,
                "float32",
                [f"{d}_exclusion" for d in zyx] if own_grid else zyx,
                {
                    "long_name": "distance to the nearest voxel outside the exclusion domain",
                    "units": "voxel",
                    "voxel_size": float(grid.voxel_size),
                    "origin": [float(v) for v in grid.origin],
                },
            ),
        )
        if getattr(tissue, "supply_target", None) is not None:  # tissue.demand_path
            specs += (
                (
                    "supply_target",
                    tissue.supply_target,
                    "uint8",
                    zyx,
                    {
                        "long_name": "coverage target of each tissue voxel from the demand map (0 outside the tissue)",
                        "units": "1",
                    },
                ),
            )
        for name, data, dtype, dims, attributes in specs:
            write_whole_array(group, name, data, dtype, dims, attributes)

    def has_tissue(self) -> bool:
        try:
            return "tissue" in self.group and "distance" in self.group["tissue"]
        except Exception:
            return False

    # -- trace ------------------------------------------------------------------------------

    def _create_trace(self) -> None:
        group = self.group.require_group("trace")
        for name, dtype, units, long_name in TRACE_FIELDS:
            group.create_array(
                name,
                shape=(0,),
                chunks=(TRACE_CHUNK,),
                dtype=dtype,
                dimension_names=["step"],
                fill_value=0 if dtype == "int64" else np.nan,
                overwrite=True,
                attributes={"units": units, "long_name": long_name},
            )

    @property
    def trace_length(self) -> int:
        """Committed trace records (records beyond it are not part of the run)."""
        return int(self.group.attrs["trace_length"])

    def set_trace_length(self, length: int) -> None:
        """Cut the trace arrays back to ``length`` records (resume after a crash or a fallback)."""
        for name in TRACE_NAMES:
            arr = self.group[f"trace/{name}"]
            if arr.shape[0] != length:
                arr.resize((length,))

    def append_trace(self, rows: Mapping[str, np.ndarray], start: int) -> int:
        """Write trace ``rows`` at record ``start``; returns the new (not yet committed) length."""
        n = len(rows["step"])
        for name in TRACE_NAMES:
            arr = self.group[f"trace/{name}"]
            arr.resize((start + n,))  # resize first, write second: a crash leaves fill values
            if n:
                arr[start : start + n] = rows[name]
        return start + n

    def read_trace(self) -> dict[str, np.ndarray]:
        """Committed trace records."""
        n = self.trace_length
        return {name: self.group[f"trace/{name}"][:n] for name in TRACE_NAMES}

    def _final_arrays(self, trace_length: int) -> dict[str, np.ndarray]:
        """The arrays a complete run's checksums cover: the final tree and the committed trace."""
        out = {f"tree/{name}": self.group[f"tree/{name}"][...] for name in ("parent", "position", "radius", "kind")}
        out.update({f"trace/{name}": self.group[f"trace/{name}"][:trace_length] for name in TRACE_NAMES})
        return out

    def verify(self) -> None:
        """Raise :class:`StoreError` saying what is wrong unless the store's results read back intact."""
        attrs = self.attrs
        n = int(attrs.get("trace_length", 0))
        try:
            if attrs.get("status") != STATUS_COMPLETE:
                for name in TRACE_NAMES:
                    self.group[f"trace/{name}"][:n]
                return
            arrays = self._final_arrays(n)
        except Exception as exc:  # a missing or truncated chunk or array fails to decode
            raise StoreError(
                f"its {'final tree or ' if attrs.get('status') == STATUS_COMPLETE else ''}trace "
                f"cannot be read ({type(exc).__name__}: {exc})"
            ) from exc
        if arrays["trace/step"].shape != (n,):
            raise StoreError(f"its trace holds {arrays['trace/step'].shape[0]} records, {n} committed")
        for key, crc in (attrs.get("checksums") or {}).items():
            if key not in arrays or crc32(arrays[key]) != crc:
                raise StoreError(f"array {key!r} fails its CRC-32 check")
        cost = attrs.get("cost")
        total = cost.get("total") if isinstance(cost, Mapping) else None
        if isinstance(total, bool) or not isinstance(total, (int, float)):
            raise StoreError(f"its final cost attribute holds no total cost (cost={str(cost)[:80]!r})")

    # -- completion -------------------------------------------------------------------------

    def write_final(
        self,
        *,
        parent: np.ndarray,
        position: np.ndarray,
        radius: np.ndarray,
        kind: np.ndarray,
        physics: Mapping[str, Any],
        cost: Mapping[str, float],
        cost_recomputed: Mapping[str, float],
        steps_done: int,
        trace_length: int,
        wall_seconds: float,
        anneal: Mapping[str, Any] | None = None,
        statistics: Mapping[str, Any] | None = None,
    ) -> None:
        """Write the final tree, then mark the run complete in one attribute write, then tidy up.

        ``anneal``: how the schedule ran (:func:`vasc_pipeline.engine.finish`), stored as attrs["anneal"];
        ``statistics``: diagnostics of the final tree (:func:`vasc_pipeline.engine.tree_statistics`),
        attrs["statistics"].
        """
        group = self.group.require_group("tree")
        specs = (
            ("parent", parent, "int64", ["node"], "parent node (-1 at inlets)", "1"),
            ("position", position, "float64", ["node", "xyz"], "node position", "m"),
            ("radius", radius, "float64", ["node"], "radius of the segment ending at the node", "m"),
            ("kind", kind, "int8", ["node"], "node kind: 0 inlet, 1 bifurcation, 2 terminal", "1"),
        )
        for name, data, dtype, dims, long_name, units in specs:
            data = np.ascontiguousarray(data, dtype=dtype)
            write_whole_array(group, name, data, dtype, dims, {"long_name": long_name, "units": units})
        # CRC-32 of what the run produced (tree and committed trace), read back as stored, in the
        # same attribute write that makes the run complete: verify() checks them.
        checksums = {key: crc32(data) for key, data in self._final_arrays(int(trace_length)).items()}
        self._set_attrs(
            status=STATUS_COMPLETE,
            checkpoint=None,
            steps_done=int(steps_done),
            trace_length=int(trace_length),
            wall_seconds=float(wall_seconds),
            physics=dict(physics),
            cost=dict(cost),
            cost_recomputed=dict(cost_recomputed),
            anneal=dict(anneal or {}),
            statistics=dict(statistics or {}),
            checksums=checksums,
        )
        self.tidy()

    def tidy(self) -> None:
        """For a complete run: drop checkpoints, cut the trace to its committed length, consolidate.

        Idempotent, so a crash in here is repaired by the next sweep that finds the run complete.
        """
        if CHECKPOINTS in self.group:
            del self.group[CHECKPOINTS]
        self.set_trace_length(self.trace_length)
        with warnings.catch_warnings():  # "consolidated metadata is not part of the v3 spec"
            warnings.simplefilter("ignore")
            zarr.consolidate_metadata(str(self.path))
        self.group = zarr.open_group(str(self.path), mode="r+", zarr_format=3)

    def is_tidy(self) -> bool:
        return CHECKPOINTS not in self.group and self.group.metadata.consolidated_metadata is not None

    def read_tree(self) -> dict[str, np.ndarray]:
        """The final tree arrays (complete runs)."""
        return {name: self.group[f"tree/{name}"][...] for name in ("parent", "position", "radius", "kind")}
