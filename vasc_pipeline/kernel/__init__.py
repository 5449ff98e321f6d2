"""The annealing kernel: incremental costs of translate and swap moves (numba, nogil).

The kernel sees only two named tuples of arrays and scalars (built by
:mod:`vasc_pipeline.engine.problem`), defined in :mod:`~vasc_pipeline.kernel.state`. By concern:

- :mod:`~vasc_pipeline.kernel.state`: ``Model``, ``State``, counters, cost indices, running sums
- :mod:`~vasc_pipeline.kernel.schedule`: temperature, supply weight, weighted total, Metropolis
- :mod:`~vasc_pipeline.kernel.exclusion`: the exclusion traversal and its depth map
- :mod:`~vasc_pipeline.kernel.supply`: the supply count map, spheres and shells
- :mod:`~vasc_pipeline.kernel.pressure`: the pressure term
- :mod:`~vasc_pipeline.kernel.cells`: neighbour cells for local swap partners
- :mod:`~vasc_pipeline.kernel.moves`: translate and swap, their ΔC and commit
- :mod:`~vasc_pipeline.kernel.loop`: initialise, :func:`anneal_block`, uphill sampling
- :mod:`~vasc_pipeline.kernel.packing`: the packing phase (supply term alone)
- :mod:`~vasc_pipeline.kernel.margins`: voxels near another part's region (a tree in parts)

:func:`anneal_block` runs a block of proposed moves from ``state`` and returns; the
temperature and every random draw depend only on the step number and the saved state, so
S steps in one block or any split of blocks give bit-identical trees.

Every function is module-level and compiled with :mod:`vasc_pipeline._jit`'s flags
(``cache=True``). The cache is keyed by the content of every kernel module
(:func:`vasc_pipeline._jit.kernel_cache_dir`): an edit of any of them, also of a function
that another module's kernel inlines, compiles afresh.
"""

from . import cells, exclusion, loop, moves, pressure, schedule, state, supply
from .cells import *  # noqa: F403
from .exclusion import *  # noqa: F403
from .loop import *  # noqa: F403
from .moves import *  # noqa: F403
from .pressure import *  # noqa: F403
from .schedule import *  # noqa: F403
from .state import *  # noqa: F403
from .supply import *  # noqa: F403

__all__ = [
    *state.__all__,
    *schedule.__all__,
    *exclusion.__all__,
    *supply.__all__,
    *pressure.__all__,
    *cells.__all__,
    *moves.__all__,
    *loop.__all__,
]
