"""A run's identity: the part of its config that determines its result, and how two configs differ in it.

:func:`config_hash` (stored as ``attrs["config_hash"]``) and :func:`config_differences` read
only what changes a run's result (:func:`hashed_config`); :func:`identity_differences` is what
keeps two runs out of one output_dir: every difference but the sweep axes (:data:`SWEEP_AXES`).
:func:`mixed_configuration` applies that rule to the runs of an output_dir (the planner before
a sweep, the reduction before it reduces).
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Iterable, Mapping

from .schema import KEYS_ADDED_LATER

__all__ = [
    "hashed_config",
    "config_hash",
    "config_differences",
    "identity_differences",
    "input_digests",
    "mixed_configuration",
    "SWEEP_AXES",
    "INPUTS",
    "INPUT_FILES",
]

# Config sections that do not change a run's result: where it is written, how often it
# checkpoints, how the sweep/cluster around it is organised, and what +stage=extend grows below
# it (which stored configs never hold). Everything else does.
_UNHASHED = ("output_dir", "checkpoint", "sweep", "cluster", "extend")
# The sweep axes (flattened config keys): the only settings in which the runs of one output_dir
# may differ; everything else in it is one configuration (a cell is never a mix of physics).
SWEEP_AXES = ("n_terminals", "physics.m_b", "anneal.steps", "seed")
# The input files a run reads (config key -> the key naming an array inside a Zarr group). Their
# content is part of the run's identity: a stored config holds ``config[INPUTS]``, the SHA-256 of
# each one set ({"tissue.path": "sha256:..."}), so a file overwritten under the same path is a
# different run, refused like a changed key. A key holding a list of files (tissue.cavity_paths)
# has one digest per entry, "tissue.cavity_paths[i]". Stores written before the digests existed
# have no ``INPUTS`` section: their files' content is unknown, and they are compared without it.
INPUT_FILES = {
    "tissue.path": "tissue.array",
    "tissue.exclusion_path": "tissue.exclusion_array",
    "tissue.inlets_path": None,
    "tissue.cavity_paths": None,
    "tissue.demand_path": None,
    "terminals.path": None,
}
INPUTS = "inputs"


def _get(config: Mapping[str, Any], dotted: str) -> Any:
    node: Any = config
    for name in dotted.split("."):
        node = node.get(name) if isinstance(node, Mapping) else None
    return node


def _file_digest(path: str, array: str | None) -> str | None:
    """``sha256:<hex>`` of a file's bytes, or of a Zarr array as read (dtype, shape, data, attrs);
    None when it cannot be read (the tissue or terminal loader then names the problem)."""
    from pathlib import Path

    p = Path(path).expanduser()
    h = hashlib.sha256()
    try:
        if p.is_file():
            with open(p, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
        elif p.is_dir():
            import numpy as np
            import zarr

            node = zarr.open(str(p), mode="r")
            if array:
                node = node[array]
            data = np.ascontiguousarray(node[...])
            h.update(f"zarr:{data.dtype.str}:{data.shape}:".encode())
            h.update(data.tobytes())
            h.update(json.dumps(dict(node.attrs), sort_keys=True, default=str).encode())
        else:
            return None
    except Exception:  # unreadable: left to the loader, whose error names the key
        return None
    return f"sha256:{h.hexdigest()}"


def input_digests(config: Mapping[str, Any]) -> dict[str, str]:
    """The content digest of every input file ``config`` names (:data:`INPUT_FILES`), by key."""
    out = {}
    for key, array_key in INPUT_FILES.items():
        value = _get(config, key)
        listed = isinstance(value, (list, tuple))
        entries = [(f"{key}[{i}]", p) for i, p in enumerate(value)] if listed else [(key, value)]
        for name, path in entries:
            if path:
                digest = _file_digest(str(path), _get(config, array_key) if array_key else None)
                if digest is not None:
                    out[name] = digest
    return out


def _input_path(flat: Mapping[str, Any], key: str) -> Any:
    """The path an input key names in a flattened config, "tissue.cavity_paths[1]" an entry of its list."""
    if key.endswith("]") and "[" in key:
        name, index = key[:-1].split("[")
        values = flat.get(name)
        return values[int(index)] if isinstance(values, (list, tuple)) and int(index) < len(values) else None
    return flat.get(key)


def _comparable(stored: Mapping[str, Any], requested: Mapping[str, Any]) -> tuple[Mapping, Mapping]:
    """Both configs without the input digests when one of them (a store written before them) has none."""
    if (INPUTS in stored) == (INPUTS in requested):
        return stored, requested
    return (
        {k: v for k, v in stored.items() if k != INPUTS},
        {k: v for k, v in requested.items() if k != INPUTS},
    )


def hashed_config(config: Mapping[str, Any]) -> dict:
    """The part of a run config that determines its result (see ``_UNHASHED``).

    Keys added to the schema later (:data:`vasc_pipeline.config.KEYS_ADDED_LATER`) are left
    out where they hold the value that reproduces the older code, so stores written before
    they existed keep their identity.
    """
    out = {k: v for k, v in config.items() if k not in _UNHASHED}
    for dotted, neutral in KEYS_ADDED_LATER.items():
        *parents, leaf = dotted.split(".")
        node = out
        for name in parents:
            node = node.get(name) if isinstance(node, Mapping) else None
        if isinstance(node, Mapping) and leaf in node and node[leaf] == neutral:
            node = out
            path = []
            for name in parents:  # copy the path before removing, the caller's config stays intact
                node[name] = dict(node[name])
                path.append((node, name))
                node = node[name]
            del node[leaf]
            for above, name in reversed(path):  # a section added later (model) leaves no empty trace
                if above[name]:
                    break
                del above[name]
    return out


def config_hash(config: Mapping[str, Any]) -> str:
    """SHA-256 of the result-determining config, canonical JSON (sorted keys)."""
    text = json.dumps(hashed_config(config), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(tree, Mapping):
        out: dict[str, Any] = {}
        for k, v in tree.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: tree}


def config_differences(
    stored: Mapping[str, Any], requested: Mapping[str, Any], ignore: tuple[str, ...] = ()
) -> list[str]:
    """Human-readable ``key: stored -> requested`` lines for every result-determining difference
    (flattened keys in ``ignore``, e.g. :data:`SWEEP_AXES`, are not compared)."""
    stored, requested = _comparable(stored, requested)
    a, b = _flatten(hashed_config(stored)), _flatten(hashed_config(requested))

    def ignored(key: str) -> bool:  # an entry ending in "." ignores a whole section
        return any(key == i or (i.endswith(".") and key.startswith(i)) for i in ignore)

    def line(k: str) -> str:
        if k.startswith(INPUTS + "."):  # a digest: the file named by the key
            key = k[len(INPUTS) + 1 :]
            path = _input_path(b, key) or _input_path(a, key)
            return (
                f"{key}: the content of {path!r} differs from the file the stored run read "
                f"(sha256 {str(a.get(k, '<absent>'))[7:19]}... stored vs {str(b.get(k, '<absent>'))[7:19]}... "
                "now): the file was changed in place"
            )
        return f"{k}: {a.get(k, '<absent>')!r} (stored) vs {b.get(k, '<absent>')!r} (requested)"

    return [line(k) for k in sorted(set(a) | set(b)) if not ignored(k) and a.get(k, "<absent>") != b.get(k, "<absent>")]


# Tissue keys only the anneal reads: where its bifurcations may go and how the terminals start
# divided between the inlets (the CCO growth places bifurcations at their optimum and divides
# the terminals by connection).
ANNEAL_TISSUE_KEYS = (
    "tissue.bifurcation_reach",
    "tissue.bifurcations_in_cavities",
    "tissue.inlet_share",
    "tissue.inlet_share_tolerance",
    "tissue.inlet_assignment",
)


def _method(config: Mapping[str, Any]) -> str:
    return str((config.get("method") or {}).get("name") or "anneal")


def identity_differences(stored: Mapping[str, Any], requested: Mapping[str, Any]) -> list[str]:
    """What keeps two runs out of one output_dir: every difference but the sweep axes.

    Runs of different methods (``method=cco`` beside the anneal: the comparison the
    reduction's ``method`` dimension is for) share everything but what only one of them reads:
    the sections ``anneal`` and ``method``, and the anneal's tissue keys
    (:data:`ANNEAL_TISSUE_KEYS`, which a model sets for the anneal only).
    """
    ignore = SWEEP_AXES
    if _method(stored) != _method(requested):
        ignore += ("anneal.", "method.", *ANNEAL_TISSUE_KEYS)
    return config_differences(stored, requested, ignore=ignore)


def mixed_configuration(
    runs: Iterable[tuple[str, Mapping[str, Any], str | None, int]],
    reference: Mapping[str, Any] | None = None,
    cell_steps: Mapping[str, int] | None = None,
) -> list[tuple[str, list[str], tuple[str, int, int, str] | None]]:
    """The runs that break "one configuration per output_dir".

    The runs of an output_dir share their configuration except the sweep axes
    (:func:`identity_differences`), and the runs of one cell (grid point without the seed)
    share their number of proposed moves: otherwise the reduction's best seed of a cell would
    be picked across different physics or schedules.

    Parameters
    ----------
    runs : (name, config, cell id or None, proposed moves) per run
    reference : the configuration every run must share (default: the first run's)
    cell_steps : the proposed moves each cell must have (default: its first run's)

    Returns
    -------
    Per offending run, in order: (name, config differences, ``(cell, steps, the cell's steps,
    whose: the name of the cell's first run, or "requested")`` or None).
    """
    runs = list(runs)
    if reference is None:
        reference = runs[0][1] if runs else {}
    steps_of = dict(cell_steps or {})
    whose = dict.fromkeys(steps_of, "requested")
    out = []
    for name, config, cell, steps in runs:
        if cell_steps is None and cell is not None:
            whose.setdefault(cell, name)
            steps_of.setdefault(cell, steps)
        clash = (cell, steps, steps_of[cell], whose[cell]) if cell in steps_of and steps != steps_of[cell] else None
        differences = identity_differences(config, reference)
        if differences or clash:
            out.append((name, differences, clash))
    return out
