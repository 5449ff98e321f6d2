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
morphometry, reference, summary, export`` import the modules of their stage
(:data:`_SHORT_NAMES`); the former flat module paths of the rest still import, with a
DeprecationWarning (:data:`_DEPRECATED`).
"""

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings

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
# Former flat module paths, kept as deprecated aliases of their new homes.
_DEPRECATED = {
    "pipeline_config": "config.pipeline",
    "identity": "config.identity",
    "topology": "model.topology",
    "geometry": "model.geometry",
    "rng": "model.rng",
    "topology_search": "model.topology_search",
    "packing": "kernel.packing",
    "finish": "engine.polish",
    "fermat": "engine.fermat",
    "planning": "pipeline.planning",
    "orchestrate": "pipeline.orchestrate",
    "cluster": "pipeline.cluster",
    "progress": "pipeline.progress",
    "outdir": "pipeline.outdir",
    "checkpoints": "store.checkpoints",
    "runs": "reduce.runs",
    "ordering": "reduce.ordering",
    "similarity": "reduce.similarity",
}


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """``vasc_pipeline.<old>[.sub]`` -> the module object of ``vasc_pipeline.<new>[.sub]``.

    The alias is the same module object (one set of classes and numba functions), not a copy.
    """

    def find_spec(self, fullname, path=None, target=None):
        head, _, rest = fullname.partition(".")
        if head != __name__ or not rest:
            return None
        name, _, sub = rest.partition(".")
        new = _SHORT_NAMES.get(name) or _DEPRECATED.get(name)
        if new is None:
            return None
        target_name = f"{__name__}.{new}" + (f".{sub}" if sub else "")
        spec = importlib.machinery.ModuleSpec(fullname, self)
        spec.loader_state = (target_name, name in _DEPRECATED and not sub)
        return spec

    def create_module(self, spec):
        target_name, deprecated = spec.loader_state
        if deprecated:
            warnings.warn(
                f"{spec.name} moved to {target_name}; the old path is a deprecated alias",
                DeprecationWarning,
                stacklevel=2,
            )
        module = importlib.import_module(target_name)
        spec.loader_state = (target_name, deprecated, module.__spec__)
        return module

    def exec_module(self, module):
        # the import system set the alias's spec on the module: give it back its own
        module.__spec__ = module.__spec__.loader_state[2]


if not any(isinstance(finder, _Alias) for finder in sys.meta_path):
    sys.meta_path.insert(0, _Alias())
