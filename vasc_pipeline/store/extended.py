"""The extended store: the whole tree grown below an annealed run, written batch by batch.

Layout::

    extended/<run_id>.zarr
        attrs: format, run_id, status ("running" | "complete"), source {store, run_id, digest,
               config_hash}, config (what determines the result: the requested and actual
               fine counts, m per territory, seed, the CCO settings), identity (its hash),
               n_nodes, n_territories, nodes_committed, territories_done, physics (the whole
               tree's, SI), wall_seconds, sessions (one {territories_done, started} per
               session), and once complete: cost, statistics, timings, checksums
        tree/{parent, position, radius, kind}   the run store's tree layout (dim "node"), kind 3
                                                 for an annealed terminal (one child)
        territory/<field>                        per territory (dim "territory"): n_voxels, C_v,
                                                 C_w, sites drawn, coverage sample, cavity check

Appending is resize-then-write, and a crash between the two leaves fill values past the
committed length; so every batch is written first and committed second, by one write of the
root attributes (``nodes_committed``, ``territories_done``), and :meth:`ExtendedStore.open_for_append`
cuts every array back to the committed length. One writer per store: :func:`extended_lock`.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import time
import warnings
import zlib
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
import zarr

from .group import GroupStore, StoreError, create_group, jsonable, run_lock
from .run_store import STATUS_COMPLETE, STATUS_RUNNING

__all__ = ["ExtendedStore", "EXTENDED_FORMAT", "TREE_CHUNK", "extended_lock", "identity_hash"]

EXTENDED_FORMAT = "vasc_pipeline.extended/1"
TREE_CHUNK = 1 << 16  # nodes per chunk: about 1.5 MB of positions
TERRITORY_CHUNK = 4096
_TREE = (
    ("parent", "int64", ("node",), "parent node (-1 at inlets)", "1"),
    ("position", "float64", ("node", "xyz"), "node position", "m"),
    ("radius", "float64", ("node",), "radius of the segment ending at the node", "m"),
    (
        "kind",
        "int8",
        ("node",),
        "node kind: 0 inlet, 1 bifurcation, 2 terminal, 3 annealed terminal (root of its territory's subtree)",
        "1",
    ),
)
TREE_NAMES = tuple(t[0] for t in _TREE)


def identity_hash(config: Mapping[str, Any], source_digest: str) -> str:
    """SHA-256 of what determines an extension's result: its config and its source's digest."""
    text = json.dumps({"config": jsonable(config), "source": source_digest}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@contextlib.contextmanager
def extended_lock(path: str | os.PathLike, wait: bool = False) -> Iterator[None]:
    """Hold ``extended/.locks/<run_id>.lock`` while writing a store (released on exit or process death)."""
    with run_lock(path, wait, what="extended store"):
        yield


class ExtendedStore(GroupStore):
    """The whole tree of one run. Create with :meth:`create`, reopen with :meth:`open`."""

    @classmethod
    def create(
        cls,
        path: str | os.PathLike,
        *,
        run_id: str,
        source: Mapping[str, Any],
        config: Mapping[str, Any],
        n_nodes: int,
        n_territories: int,
        physics: Mapping[str, Any],
        territory_fields,
    ) -> "ExtendedStore":
        """A new, empty store (refuses to overwrite): its identity, ``status="running"``, empty arrays.

        Built under a temporary name and renamed into place (one atomic step), so that a crash
        while creating it never leaves a store without its arrays.
        """
        path = Path(path)
        if path.exists():
            raise StoreError(f"extended store {str(path)!r} already exists")
        for leftover in path.parent.glob(f"{path.name}.creating-*"):  # a crashed creation's
            shutil.rmtree(leftover, ignore_errors=True)
        final, path = path, path.with_name(f"{path.name}.creating-{os.getpid()}")
        attrs = {
            "format": EXTENDED_FORMAT,
            "run_id": run_id,
            "status": STATUS_RUNNING,
            "source": jsonable(source),
            "config": jsonable(config),
            "identity": identity_hash(config, source["digest"]),
            "n_nodes": int(n_nodes),
            "n_territories": int(n_territories),
            "nodes_committed": 0,
            "territories_done": 0,
            "physics": jsonable(physics),
            "wall_seconds": 0.0,
            "sessions": [],
        }
        group = create_group(path, attrs, "extended store")
        tree = group.require_group("tree")
        for name, dtype, dims, long_name, units in _TREE:
            tree.create_array(
                name,
                shape=(0, 3) if name == "position" else (0,),
                chunks=(TREE_CHUNK, 3) if name == "position" else (TREE_CHUNK,),
                dtype=dtype,
                dimension_names=list(dims),
                attributes={"long_name": long_name, "units": units},
            )
        territory = group.require_group("territory")
        for name, dtype, units, long_name in territory_fields:
            territory.create_array(
                name,
                shape=(0,),
                chunks=(TERRITORY_CHUNK,),
                dtype=dtype,
                dimension_names=["territory"],
                attributes={"long_name": long_name, "units": units},
            )
        os.rename(path, final)
        return cls(final, zarr.open_group(str(final), mode="r+", zarr_format=3))

    @classmethod
    def open(cls, path: str | os.PathLike, mode: str = "r") -> "ExtendedStore":
        """Open an existing store; :class:`StoreError` names the path if it is not one."""
        path = Path(path)
        if not (path / "zarr.json").is_file():
            raise StoreError(f"{str(path)!r} is not an extended store (no zarr.json)")
        try:
            group = zarr.open_group(str(path), mode=mode, zarr_format=3)
        except Exception as exc:
            raise StoreError(f"extended store {str(path)!r} cannot be opened ({type(exc).__name__}: {exc})") from exc
        if group.attrs.get("format") != EXTENDED_FORMAT:
            raise StoreError(f"{str(path)!r} is not an extended store (format {group.attrs.get('format')!r})")
        return cls(path, group)

    @property
    def nodes_committed(self) -> int:
        return int(self.group.attrs["nodes_committed"])

    @property
    def territories_done(self) -> int:
        return int(self.group.attrs["territories_done"])

    def _set_attrs(self, **values: Any) -> None:
        self.group.update_attributes(jsonable(values))

    def _arrays(self) -> Iterator[tuple[zarr.Array, int]]:
        """Every appended array with its committed length."""
        for name in TREE_NAMES:
            yield self.group[f"tree/{name}"], self.nodes_committed
        for name in self.group["territory"].array_keys():
            yield self.group[f"territory/{name}"], self.territories_done

    def cut_back(self) -> None:
        """Cut every array back to its committed length (records past it are a crashed write's)."""
        for arr, length in self._arrays():
            if arr.shape[0] != length:
                arr.resize((length, *arr.shape[1:]))

    def start_session(self) -> None:
        """Cut back, and note where this session starts."""
        self.cut_back()
        sessions = list(self.group.attrs.get("sessions", [])) + [
            {"territories_done": self.territories_done, "started": time.strftime("%Y-%m-%dT%H:%M:%S")}
        ]
        self._set_attrs(sessions=sessions)

    def append(
        self,
        tree: Mapping[str, np.ndarray],
        territory: Mapping[str, np.ndarray] | None,
        n_territories: int,
        wall_seconds: float,
    ) -> None:
        """Write ``tree`` nodes (and ``territory`` rows for ``n_territories`` territories) after the
        committed ones, then commit them with one attribute write."""
        start = self.nodes_committed
        n = len(tree["parent"])
        for name in TREE_NAMES:
            arr = self.group[f"tree/{name}"]
            arr.resize((start + n, *arr.shape[1:]))  # resize first, write second: a crash leaves fill values
            if n:
                arr[start : start + n] = tree[name]
        done = self.territories_done
        if territory is not None:
            for name in self.group["territory"].array_keys():
                arr = self.group[f"territory/{name}"]
                arr.resize((done + n_territories,))
                arr[done : done + n_territories] = territory[name]
        self._set_attrs(
            nodes_committed=start + n, territories_done=done + n_territories, wall_seconds=float(wall_seconds)
        )

    def read_territories(self) -> dict[str, np.ndarray]:
        """The committed per-territory columns."""
        n = self.territories_done
        return {name: self.group[f"territory/{name}"][:n] for name in self.group["territory"].array_keys()}

    def read_tree(self) -> dict[str, np.ndarray]:
        """The committed tree arrays."""
        n = self.nodes_committed
        return {name: self.group[f"tree/{name}"][:n] for name in TREE_NAMES}

    def _crc32(self, name: str) -> int:
        """CRC-32 of ``tree/<name>``'s committed bytes (checkpoints.crc32 of the whole array), read a
        chunk at a time: a million-node tree is never in memory at once."""
        arr, value = self.group[f"tree/{name}"], 0
        for lo in range(0, self.nodes_committed, TREE_CHUNK):
            data = np.ascontiguousarray(arr[lo : min(lo + TREE_CHUNK, self.nodes_committed)])
            value = zlib.crc32(data.view(np.uint8).reshape(-1).data, value)
        return value

    def finish(self, **attrs: Any) -> None:
        """Mark the store complete (with ``attrs``: cost, statistics, timings, ...) in one attribute
        write, with CRC-32 checksums of the tree, then consolidate its metadata."""
        if self.nodes_committed != int(self.group.attrs["n_nodes"]):
            raise StoreError(
                f"extended store {str(self.path)!r} holds {self.nodes_committed} of its "
                f"{self.group.attrs['n_nodes']} nodes: not complete"
            )
        checksums = {f"tree/{name}": self._crc32(name) for name in TREE_NAMES}
        self._set_attrs(status=STATUS_COMPLETE, checksums=checksums, **attrs)
        with warnings.catch_warnings():  # "consolidated metadata is not part of the v3 spec"
            warnings.simplefilter("ignore")
            zarr.consolidate_metadata(str(self.path))
        self.group = zarr.open_group(str(self.path), mode="r", zarr_format=3)

    def verify(self) -> None:
        """Raise :class:`StoreError` unless a complete store's tree reads back as checksummed."""
        attrs = self.attrs
        if attrs.get("status") != STATUS_COMPLETE:
            raise StoreError(f"extended store {str(self.path)!r} is not complete")
        for name in TREE_NAMES:
            if self._crc32(name) != (attrs.get("checksums") or {}).get(f"tree/{name}"):
                raise StoreError(f"extended store {str(self.path)!r}: array tree/{name} fails its CRC-32 check")
