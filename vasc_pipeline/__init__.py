"""vasc_pipeline: globally optimised arterial trees by simulated annealing (Keelan, Chung & Hague).

The stages of the data's path, one subpackage each::

    config/    the schema, validation, composition from conf/, a run's identity
    model/     tissue, tree arrays, physics, cost terms, topology, geometry
    kernel/    the numba annealing kernel, split by concern
    engine/    one tree: problem, anneal loop, polish, CCO
    pipeline/  the sweep: expansion, jobs, planning, Dask, progress, output dir
    store/     run stores, checkpoints, the output dir's layout
    reduce/    runs -> orders, morphometry, Kassab 1993, summary.zarr, exports
    figures/   matplotlib figures of a reduced sweep

Short names: ``from vasc_pipeline import tissue, tree, physics, costs, cco, sweep, job,
morphometry, reference, summary, export`` give the modules of their stage (imported on first
use); ``from vasc_pipeline import config, engine, reduce, ...`` the stage packages.
"""

import importlib
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("vasc_pipeline")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

# Short public names of modules that live in a stage subpackage (the README's Python API).
_SHORT_NAMES = {
    "tissue": "model.tissue",
    "tree": "model.tree",
    "physics": "model.physics",
    "costs": "model.costs",
    "cco": "engine.cco",
    "sweep": "pipeline.sweep",
    "job": "pipeline.job",
    "morphometry": "reduce.morphometry",
    "reference": "reduce.reference",
    "summary": "reduce.summary",
    "export": "reduce.export",
}
_STAGES = ("config", "model", "kernel", "engine", "pipeline", "store", "reduce", "figures")

__all__ = ["__version__", *_STAGES, *_SHORT_NAMES]


def __getattr__(name: str):
    """A stage package or a short name's module, imported when first asked for (PEP 562): importing
    the package stays cheap, and ``from vasc_pipeline import job`` gives the module itself."""
    if name in _STAGES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _SHORT_NAMES:
        return importlib.import_module(f"{__name__}.{_SHORT_NAMES[name]}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
