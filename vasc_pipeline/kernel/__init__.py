"""The annealing kernel: incremental costs of translate and swap moves (numba, nogil).

The kernel sees only two named tuples of arrays and scalars (built by
:mod:`vasc_pipeline.engine.problem`), defined in :mod:`~vasc_pipeline.kernel.state`. By concern:

- :mod:`~vasc_pipeline.kernel.state`: ``Model``, ``State``, counters, cost indices, running sums
- :mod:`~vasc_pipeline.kernel.schedule`: temperature, supply weight, weighted total, Metropolis
- :mod:`~vasc_pipeline.kernel.exclusion`: the exclusion traversal and its depth map
- :mod:`~vasc_pipeline.kernel.supply`: the supply count map, spheres and shells
- :mod:`~vasc_pipeline.kernel.pressure`: the pressure term
- :mod:`~vasc_pipeline.kernel.cells`: neighbour cells for local swap partners
- :mod:`~vasc_pipeline.kernel.moves`: translate, its ΔC and commit, the helpers both moves share
- :mod:`~vasc_pipeline.kernel.swaps`: swap two subtrees, its ΔC
- :mod:`~vasc_pipeline.kernel.loop`: initialise, :func:`anneal_block`, uphill sampling
- :mod:`~vasc_pipeline.kernel.packing`: the packing phase (supply term alone)
- :mod:`~vasc_pipeline.kernel.margins`: voxels near another part's region (a tree in parts)
- :mod:`~vasc_pipeline.kernel.growth`: the CCO growth (``method=cco``), one terminal at a time
- :mod:`~vasc_pipeline.kernel.fermat`: the weighted Fermat-Weber point, a CCO connection's optimum
- :mod:`~vasc_pipeline.kernel.traversal`: segments' lengths per voxel code (the whole tree's extension)

:func:`anneal_block` runs a block of proposed moves from ``state`` and returns; the
temperature and every random draw depend only on the step number and the saved state, so
S steps in one block or any split of blocks give bit-identical trees.

Every function is module-level and compiled with :mod:`vasc_pipeline._jit`'s flags
(``cache=True``). The cache is keyed by the content of every kernel module
(:func:`vasc_pipeline._jit.kernel_cache_dir`): an edit of any of them, also of a function
that another module's kernel inlines, compiles afresh.
"""

from .cells import (
    build_cells,
    neighbour_partner,
)
from .exclusion import (
    LEAP_BLOCK,
    PREFETCH_LEAD,
    depth_fields,
    exclusion_fields,
    leap_map,
    recompute_exclusion,
    segment_exclusion,
    segment_exclusion_capped,
)
from .fermat import (
    fermat_point,
)
from .growth import (
    MAX_FORBIDDEN_REFUSALS,
    connection_cost,
    crosses,
    grow_terminals,
)
from .loop import (
    anneal_block,
    initialise,
    initialise_segments,
    sample_uphill,
    scaled_total_without_supply,
    translate_node,
)
from .moves import (
    legal_position,
)
from .pressure import (
    pressure_cost,
    pressure_moments,
)
from .schedule import (
    supply_weight,
    temperature,
    weighted_total,
)
from .state import (
    ACCEPTED,
    COUNTER_BIFURCATION_ACCEPTED,
    COUNTER_BIFURCATION_PROPOSED,
    COUNTER_LOCAL_SWAP_PROPOSED,
    COUNTER_STEP,
    COUNTER_SWAP_ACCEPTED,
    COUNTER_SWAP_PROPOSED,
    COUNTER_TERMINAL_ACCEPTED,
    COUNTER_TERMINAL_PROPOSED,
    COUNTER_WINDOW_BIFURCATION_ACCEPTED,
    COUNTER_WINDOW_BIFURCATION_PROPOSED,
    COUNTER_WINDOW_TERMINAL_ACCEPTED,
    COUNTER_WINDOW_TERMINAL_PROPOSED,
    EXCLUSION,
    ILLEGAL,
    MOVE_COUNTERS,
    N_ACCEPTED,
    N_COUNTERS,
    N_PROPOSED,
    POWER,
    PRESSURE,
    REJECTED,
    SUPPLY,
    VOLUME,
    WINDOW_COUNTERS,
    Model,
    State,
)
from .supply import (
    SHELL_BANDS,
    SHELL_WIDTH,
    in_tissue,
    shell_capacity,
    supply_move,
    supply_move_delta,
    supply_sphere,
)
from .swaps import (
    swap_nodes,
    swap_random,
)
from .traversal import (
    voxel_code_lengths,
)

__all__ = [
    "ACCEPTED",
    "COUNTER_BIFURCATION_ACCEPTED",
    "COUNTER_BIFURCATION_PROPOSED",
    "COUNTER_LOCAL_SWAP_PROPOSED",
    "COUNTER_STEP",
    "COUNTER_SWAP_ACCEPTED",
    "COUNTER_SWAP_PROPOSED",
    "COUNTER_TERMINAL_ACCEPTED",
    "COUNTER_TERMINAL_PROPOSED",
    "COUNTER_WINDOW_BIFURCATION_ACCEPTED",
    "COUNTER_WINDOW_BIFURCATION_PROPOSED",
    "COUNTER_WINDOW_TERMINAL_ACCEPTED",
    "COUNTER_WINDOW_TERMINAL_PROPOSED",
    "EXCLUSION",
    "ILLEGAL",
    "MOVE_COUNTERS",
    "Model",
    "N_ACCEPTED",
    "N_COUNTERS",
    "N_PROPOSED",
    "POWER",
    "PRESSURE",
    "REJECTED",
    "SUPPLY",
    "State",
    "VOLUME",
    "WINDOW_COUNTERS",
    "supply_weight",
    "temperature",
    "weighted_total",
    "LEAP_BLOCK",
    "PREFETCH_LEAD",
    "depth_fields",
    "exclusion_fields",
    "leap_map",
    "recompute_exclusion",
    "segment_exclusion",
    "segment_exclusion_capped",
    "SHELL_BANDS",
    "SHELL_WIDTH",
    "in_tissue",
    "shell_capacity",
    "supply_move",
    "supply_move_delta",
    "supply_sphere",
    "pressure_cost",
    "pressure_moments",
    "build_cells",
    "neighbour_partner",
    "legal_position",
    "swap_nodes",
    "swap_random",
    "anneal_block",
    "initialise",
    "initialise_segments",
    "sample_uphill",
    "scaled_total_without_supply",
    "translate_node",
    "voxel_code_lengths",
    "fermat_point",
    "MAX_FORBIDDEN_REFUSALS",
    "connection_cost",
    "crosses",
    "grow_terminals",
]
