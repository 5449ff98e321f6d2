"""Atomic checkpoints of a run store: write a new one, verify it (CRC-32 manifest), fall back to an older one.

A checkpoint is a new group ``checkpoints/c<seq>`` of the run store: arrays first, then a
manifest in the group's attributes (shape, dtype and CRC-32 of every array), then the root
attributes ``checkpoint``, ``steps_done``, ``trace_length`` and ``wall_seconds`` in one write
(the key that makes it valid); only then are older checkpoints pruned (the previous one is
kept as a fallback). On load every array is checked against the manifest; a bad checkpoint is
skipped for the previous good one with a :class:`CheckpointWarning`.

:class:`CheckpointsMixin` holds these methods of :class:`vasc_pipeline.store.RunStore`
(which provides ``group``, ``path`` and ``_set_attrs``).
"""

from __future__ import annotations

import warnings
import zlib
from dataclasses import dataclass
from typing import Mapping

import numpy as np

__all__ = ["Checkpoint", "CheckpointWarning", "CheckpointsMixin", "CHECKPOINTS", "crc32"]

CHECKPOINTS = "checkpoints"


class CheckpointWarning(UserWarning):
    """A checkpoint failed its checks and an older one (or a fresh start) is used instead."""


def crc32(data: np.ndarray) -> int:
    """CRC-32 of an array's bytes (checkpoint manifests, and the checksums of a complete run's results)."""
    return zlib.crc32(np.ascontiguousarray(data).view(np.uint8).reshape(-1).data)


@dataclass
class Checkpoint:
    """A verified checkpoint: the state arrays and where the run stood."""

    name: str
    arrays: dict[str, np.ndarray]
    step: int
    trace_length: int
    wall_seconds: float


class CheckpointsMixin:
    """The checkpoint methods of a run store (see the module docstring)."""

    def _checkpoint_names(self) -> list[str]:
        # From the directory listing, not zarr's member listing: that one parses every
        # member's metadata and fails as a whole on one damaged checkpoint.
        root = self.path / CHECKPOINTS
        return sorted(p.name for p in root.iterdir() if p.is_dir()) if root.is_dir() else []

    def write_checkpoint(
        self, arrays: Mapping[str, np.ndarray], *, step: int, trace_length: int, wall_seconds: float
    ) -> str:
        """Write a new checkpoint group, flip the root pointer to it, prune; returns its name."""
        names = self._checkpoint_names()
        seq = int(names[-1][1:]) + 1 if names else 1
        name = f"c{seq:09d}"
        group = self.group.require_group(CHECKPOINTS).create_group(name)
        manifest = {}
        for key, data in arrays.items():
            data = np.ascontiguousarray(data)
            arr = group.create_array(key, shape=data.shape, dtype=data.dtype, chunks=data.shape or None)
            arr[...] = data
            manifest[key] = {"shape": list(data.shape), "dtype": data.dtype.str, "crc32": crc32(data)}
        # The manifest is the group's last key: a checkpoint without one is incomplete.
        group.update_attributes(
            {
                "manifest": manifest,
                "step": int(step),
                "trace_length": int(trace_length),
                "wall_seconds": float(wall_seconds),
            }
        )
        previous = self.group.attrs.get("checkpoint")
        self._set_attrs(
            checkpoint=name, steps_done=int(step), trace_length=int(trace_length), wall_seconds=float(wall_seconds)
        )
        # Keep the new checkpoint and the one committed before it (the fallback); anything
        # else is older or a partial leftover of a crashed write.
        for n in names:
            if n != previous:
                del self.group[CHECKPOINTS][n]
        return name

    def _read_checkpoint(self, name: str) -> Checkpoint:
        """Read and verify one checkpoint; raises ValueError (or a zarr/codec error) when bad."""
        group = self.group[f"{CHECKPOINTS}/{name}"]
        meta = dict(group.attrs)
        manifest = meta.get("manifest")
        if not manifest:
            raise ValueError("no manifest (written partially)")
        arrays = {}
        for key, info in manifest.items():
            data = group[key][...]
            if list(data.shape) != info["shape"] or data.dtype.str != info["dtype"]:
                raise ValueError(
                    f"array {key!r} has shape {data.shape} {data.dtype.str}, expected "
                    f"{tuple(info['shape'])} {info['dtype']}"
                )
            if crc32(data) != info["crc32"]:
                raise ValueError(f"array {key!r} fails its CRC-32 check")
            arrays[key] = data
        return Checkpoint(name, arrays, int(meta["step"]), int(meta["trace_length"]), float(meta["wall_seconds"]))

    def load_checkpoint(self) -> Checkpoint | None:
        """The newest good checkpoint at or before the root pointer, or None (start afresh).

        A checkpoint that fails to read or verify is reported with a :class:`CheckpointWarning`
        and the previous one is tried.
        """
        current = self.group.attrs.get("checkpoint")
        if current is None:
            return None
        names = [n for n in self._checkpoint_names() if n <= current]
        if current not in names:
            warnings.warn(f"{self.path}: checkpoint {current} is missing", CheckpointWarning, stacklevel=2)
        for name in reversed(names):
            try:
                return self._read_checkpoint(name)
            except Exception as exc:  # any failure to read or verify means: not a good checkpoint
                warnings.warn(
                    f"{self.path}: checkpoint {name} is truncated or corrupted ({exc}); "
                    "falling back to the previous good checkpoint",
                    CheckpointWarning,
                    stacklevel=2,
                )
        warnings.warn(
            f"{self.path}: no good checkpoint left; the run restarts from step 0", CheckpointWarning, stacklevel=2
        )
        return None

    def record_resume(self, checkpoint: Checkpoint | None) -> None:
        """Note in the attributes where this session starts (step 0 for a fresh start).

        The root pointer moves to the checkpoint resumed from, so that the next write keeps it
        as the fallback and prunes a bad one that :meth:`load_checkpoint` passed over.
        """
        entry = {"step": checkpoint.step if checkpoint else 0, "checkpoint": checkpoint.name if checkpoint else None}
        resumes = list(self.group.attrs.get("resumes", [])) + [entry]
        if checkpoint is None:  # a restart from scratch also forgets any committed progress
            self._set_attrs(resumes=resumes, checkpoint=None, steps_done=0, trace_length=0, wall_seconds=0.0)
        else:
            self._set_attrs(
                resumes=resumes,
                checkpoint=checkpoint.name,
                steps_done=checkpoint.step,
                trace_length=checkpoint.trace_length,
                wall_seconds=checkpoint.wall_seconds,
            )
