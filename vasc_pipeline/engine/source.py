"""The source of an extension (:mod:`vasc_pipeline.engine.extend`): a complete run store read back.

:func:`read_source` verifies the store and reads the final tree, the physics and the voxel grids
(tissue and exclusion) into a :class:`Source`; :func:`source_digest` names exactly what was read,
so an extended store can tell which run it grew below.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model.physics import Physics
from ..model.topology import KIND_TERMINAL

__all__ = ["ExtendError", "Source", "read_source", "source_digest"]


class ExtendError(ValueError):
    """An extension that cannot be made (a source that is not a complete run, a bad count); names the key."""


@dataclass(frozen=True)
class Source:
    """What the extension reads from a complete run store.

    Attributes
    ----------
    path : Path
    run_id : str
    seed : int
    parent, position, radius, kind : the final tree (run store layout)
    physics : Physics
        The run's (N = its terminals).
    mask : uint8 (z, y, x)
        Supply domain (1 = tissue).
    exclusion : uint8 (z, y, x)
        Exclusion domain on the same grid (tissue plus cavities).
    origin : float64 (3,)
        [x, y, z] of the centre of voxel [0, 0, 0] [m].
    voxel_size : float
        [m].
    ndim : int
    config_hash : str
    digest : str
        ``sha256:...`` of everything read here (:func:`source_digest`).
    """

    path: Path
    run_id: str
    seed: int
    parent: np.ndarray
    position: np.ndarray
    radius: np.ndarray
    kind: np.ndarray
    physics: Physics
    mask: np.ndarray
    exclusion: np.ndarray
    origin: np.ndarray
    voxel_size: float
    ndim: int
    config_hash: str
    digest: str

    @property
    def n_terminals(self) -> int:
        return self.physics.n_terminals

    @property
    def terminals(self) -> np.ndarray:
        """int64 (N,): the annealed terminal nodes; territory i is terminal ``terminals[i]``'s."""
        return np.flatnonzero(self.kind == KIND_TERMINAL)


def source_digest(arrays: dict, attrs: dict) -> str:
    """``sha256:<hex>`` of the named arrays (bytes, dtype, shape) and JSON ``attrs``, in name order."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}:".encode())
        h.update(a.tobytes())
    h.update(json.dumps(attrs, sort_keys=True, default=str).encode())
    return f"sha256:{h.hexdigest()}"


def read_source(path) -> Source:
    """Read a complete run store (verified whole, :func:`vasc_pipeline.store.verify_store`)."""
    from ..store.run_store import STATUS_COMPLETE, StoreError, verify_store

    path = Path(path)
    try:
        store = verify_store(path)
    except StoreError as exc:
        raise ExtendError(str(exc)) from exc
    attrs = store.attrs
    if attrs.get("status") != STATUS_COMPLETE:
        raise ExtendError(
            f"run store {str(path)!r} is not complete (status {attrs.get('status')!r}): nothing to extend"
        )
    tree = store.read_tree()
    tissue = store.group["tissue"]
    mask = np.ascontiguousarray(tissue["mask"][...], dtype=np.uint8)
    exclusion = np.ascontiguousarray(tissue["exclusion"][...], dtype=np.uint8)
    t_attrs = dict(tissue.attrs)
    geometry = {k: t_attrs[k] for k in ("voxel_size", "origin", "ndim")}
    physics = dict(attrs["physics"])
    digest = source_digest(
        {**{f"tree/{k}": v for k, v in tree.items()}, "tissue/mask": mask, "tissue/exclusion": exclusion},
        {"physics": physics, "tissue": geometry},
    )
    return Source(
        path=path,
        run_id=str(attrs["run_id"]),
        seed=int(attrs["seed"]),
        parent=np.asarray(tree["parent"], dtype=np.int64),
        position=np.asarray(tree["position"], dtype=np.float64),
        radius=np.asarray(tree["radius"], dtype=np.float64),
        kind=np.asarray(tree["kind"], dtype=np.int8),
        physics=Physics(**physics),
        mask=mask,
        exclusion=exclusion,
        origin=np.asarray(geometry["origin"], dtype=np.float64),
        voxel_size=float(geometry["voxel_size"]),
        ndim=int(geometry["ndim"]),
        config_hash=str(attrs.get("config_hash", "")),
        digest=digest,
    )
