"""Stage 2, the model: tissue, tree arrays, physics, cost terms, topology and geometry (NumPy).

:mod:`~vasc_pipeline.model.tissue` (voxel domains), :mod:`~vasc_pipeline.model.tree` (the
flat node layout), :mod:`~vasc_pipeline.model.physics` (radii, flows, cost tables),
:mod:`~vasc_pipeline.model.costs` (every cost term in full, the kernel's reference),
:mod:`~vasc_pipeline.model.topology` (parent-array helpers), :mod:`~vasc_pipeline.model.geometry`
(optimal bifurcations for a fixed topology), :mod:`~vasc_pipeline.model.topology_search`
(exhaustive optimum of small instances), :mod:`~vasc_pipeline.model.rng` (checkpointable
random numbers).
"""

__all__ = ["tissue", "tree", "physics", "costs", "topology", "geometry", "topology_search", "rng"]
