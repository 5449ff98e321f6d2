"""What every store of ours shares (:class:`~vasc_pipeline.store.run_store.RunStore`, the whole
tree's :class:`~vasc_pipeline.store.extended.ExtendedStore`): the error, the ``fcntl`` locks that
keep one writer per store, attributes as plain JSON, whole-array writes, and the base class.
"""

from __future__ import annotations

import contextlib
import fcntl
import math
import os
from pathlib import Path
from typing import IO, Any, Iterator, Mapping

import numpy as np
import zarr

__all__ = [
    "GroupStore",
    "StoreError",
    "create_group",
    "file_lock",
    "jsonable",
    "run_lock",
    "write_whole_array",
]


class StoreError(OSError):
    """A run store that cannot be read or written; the message names the path."""


@contextlib.contextmanager
def file_lock(path: str | os.PathLike, wait: bool = True) -> Iterator[IO[str]]:
    """Open ``path`` (created if absent, its content kept) and hold an exclusive ``fcntl`` lock on it.

    The lock is released on exit, and by the kernel when the process dies (even on SIGKILL).
    Without ``wait`` a lock held by another process raises BlockingIOError at once. Yields
    the open file (mode ``a+``) for a holder that records itself in it.
    """
    with open(path, "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        try:
            yield fh
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


@contextlib.contextmanager
def run_lock(path: str | os.PathLike, wait: bool = True, what: str = "run store") -> Iterator[None]:
    """Hold an exclusive lock on ``<store's dir>/.locks/<run_id>.lock`` (released on exit or process
    death); ``what`` names the store in the error.

    A job whose worker was declared dead may still be running; the lock makes a resubmitted
    copy wait for it instead of writing the same store at the same time.
    """
    path = Path(path)
    lock_path = path.parent / ".locks" / (path.name.removesuffix(".zarr") + ".lock")
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(file_lock(lock_path, wait))
        except BlockingIOError as exc:
            raise StoreError(f"{what} {str(path)!r} is being written by another process") from exc
        yield


def jsonable(value: Any) -> Any:
    """Plain JSON types for attributes (numpy scalars and arrays, non-finite floats as strings)."""
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [jsonable(v) for v in value]
    if isinstance(value, (np.integer, bool, np.bool_)):
        return value.item() if isinstance(value, np.generic) else value
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else str(value)
    return value


def write_whole_array(group: zarr.Group, name: str, data: np.ndarray, dtype, dims, attributes: dict) -> None:
    """``group[name]`` = ``data`` in one chunk, with its dimension names and attributes (replacing any)."""
    arr = group.create_array(
        name,
        shape=data.shape,
        dtype=dtype,
        chunks=data.shape,
        dimension_names=dims,
        overwrite=True,
        attributes=attributes,
    )
    arr[...] = data


def create_group(path: Path, attrs: dict, what: str) -> zarr.Group:
    """A new root Zarr group at ``path`` with ``attrs`` (its parent directories made); StoreError,
    naming the store as ``what``, when one is already there (never overwritten)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return zarr.open_group(str(path), mode="w-", attributes=attrs, zarr_format=3)
    except (FileExistsError, zarr.errors.ContainsGroupError, zarr.errors.ContainsArrayError) as exc:
        raise StoreError(f"{what} {str(path)!r} already exists") from exc


class GroupStore:
    """What every store of ours shares: its path, its root Zarr group, whether one exists at a
    path, its attributes and its status (:class:`RunStore`, the whole tree's ExtendedStore)."""

    def __init__(self, path: Path, group: zarr.Group) -> None:
        self.path = Path(path)
        self.group = group

    @staticmethod
    def exists(path: str | os.PathLike) -> bool:
        return (Path(path) / "zarr.json").is_file()

    @property
    def attrs(self) -> dict[str, Any]:
        return dict(self.group.attrs)

    @property
    def status(self) -> str:
        return self.group.attrs["status"]
