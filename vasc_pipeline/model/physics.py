"""Physical parameters of the tree model and the per-segment cost tables.

Radii and flows follow from topology alone (Murray's law at fixed gamma): with ``n`` the number of
terminals downstream of a segment, ``Q = n Q0 / N`` and ``r = r_t n^(1/gamma)`` with
``r_t = r_in N^(-1/gamma)``. Every per-segment cost is therefore a function of ``n``
times a geometric quantity (length, or the exclusion traversal sum), so the kernel looks
the ``n``-dependent factor up in tables built here once per run.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["Physics", "CostTables", "cost_tables", "segment_factors", "supply_radius"]

# Row order of the table array handed to the kernel.
TABLE_VOLUME, TABLE_POWER, TABLE_EXCLUSION, TABLE_RESISTANCE, TABLE_FLOW = range(5)


@dataclass(frozen=True)
class Physics:
    """Model constants, SI units throughout.

    Attributes
    ----------
    n_terminals : int
        N, number of terminal nodes (arterioles).
    n_inlets : int
        K, number of inlet nodes (1; 2 for the coronary model).
    gamma : float
        Bifurcation exponent (2.1 coronary, 3.0 for the 2-D test).
    inlet_radius : float
        Combined inlet radius r_in [m]: the inlet radii satisfy sum r_k^gamma = r_in^gamma.
    total_flow : float
        Q0, total inflow [m^3 s^-1].
    m_b : float
        Metabolic cost of blood volume [W m^-3].
    viscosity : float
        Blood viscosity mu [Pa s].
    supply_radius : float
        R_supply of a terminal's supply sphere (disk in 2-D) [m].
    r_cutoff : float
        Segments with radius above this are excluded from tissue [m].
    A_wv, A_o, A_p, A_s : float
        Weights of the paper's total cost; the annealed cost is
        (C_w + C_v) + (A_o/A_wv) C_o + (A_p/A_wv) C_p + (A_s/A_wv) C_s.
    pressure_inlet, pressure_terminal : float
        Inlet pressure and target terminal pressure for C_p [Pa].
    """

    n_terminals: int
    n_inlets: int
    gamma: float
    inlet_radius: float
    total_flow: float
    m_b: float
    viscosity: float
    supply_radius: float
    r_cutoff: float = 1e-5
    A_wv: float = 1e4
    A_o: float = 100.0
    A_p: float = 0.0
    A_s: float = 1e30
    pressure_inlet: float = 13.3e3
    pressure_terminal: float = 12.0e3

    @property
    def terminal_radius(self) -> float:
        """r_t = r_in N^(-1/gamma) [m]."""
        return self.inlet_radius * self.n_terminals ** (-1.0 / self.gamma)

    @property
    def weights(self) -> tuple[float, float, float]:
        """Scaled weights (A_o, A_p, A_s) / A_wv of exclusion, pressure and supply."""
        return (self.A_o / self.A_wv, self.A_p / self.A_wv, self.A_s / self.A_wv)

    def radius(self, n_downstream: np.ndarray) -> np.ndarray:
        """Radius [m] of segments with ``n_downstream`` terminals (0 where n = 0)."""
        n = np.asarray(n_downstream, dtype=np.float64)
        return self.terminal_radius * n ** (1.0 / self.gamma)

    def flow(self, n_downstream: np.ndarray) -> np.ndarray:
        """Flow [m^3 s^-1] through segments with ``n_downstream`` terminals."""
        return np.asarray(n_downstream, dtype=np.float64) * (self.total_flow / self.n_terminals)

    def as_attrs(self) -> dict:
        """Plain-float dict for the run store's ``physics`` attribute."""
        return {k: (int(v) if isinstance(v, int) else float(v)) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class CostTables:
    """Per-unit factors indexed by the downstream terminal count n = 0..N.

    ``volume[n] * L`` is C_v of a segment of length L, ``power[n] * L`` its C_w,
    ``exclusion[n] * S`` its C_o given the traversal sum S = sum_v (D_v L_v)^6,
    ``resistance[n] * L`` its Poiseuille resistance and ``flow[n]`` its flow.
    """

    array: np.ndarray  # float64 (5, N + 1), rows TABLE_*

    # One named view per row (the kernel takes the whole array): alike on purpose.
    @property
    def volume(self) -> np.ndarray:
        return self.array[TABLE_VOLUME]

    @property
    def power(self) -> np.ndarray:
        return self.array[TABLE_POWER]

    @property
    def exclusion(self) -> np.ndarray:
        return self.array[TABLE_EXCLUSION]

    @property
    def resistance(self) -> np.ndarray:
        return self.array[TABLE_RESISTANCE]

    @property
    def flow(self) -> np.ndarray:
        return self.array[TABLE_FLOW]


def cost_tables(physics: Physics) -> CostTables:
    """Build the n-indexed cost factors of every segment term (n = 0 row is zero)."""
    return CostTables(segment_factors(physics, np.arange(physics.n_terminals + 1)))


def segment_factors(physics: Physics, n_downstream: np.ndarray) -> np.ndarray:
    """float64 (5, len(n)): the rows of :class:`CostTables` for segments with ``n_downstream``
    terminals only (a tree of 10^6 terminals needs a few of its 10^6 rows)."""
    n = np.asarray(n_downstream, dtype=np.float64)
    r = physics.radius(n)
    q = physics.flow(n)
    area = math.pi * r**2
    with np.errstate(divide="ignore"):
        resistance = np.where(r > 0, 8.0 * physics.viscosity / (math.pi * np.where(r > 0, r, 1.0) ** 4), 0.0)
    table = np.zeros((5, n.size), dtype=np.float64)
    table[TABLE_VOLUME] = physics.m_b * area
    table[TABLE_POWER] = q**2 * resistance
    table[TABLE_EXCLUSION] = np.where(r > physics.r_cutoff, area, 0.0)
    table[TABLE_RESISTANCE] = resistance
    table[TABLE_FLOW] = q
    return table


def supply_radius(
    n_terminals: int, tissue_measure: float, ndim: int, q_required: float | None = None, total_flow: float | None = None
) -> float:
    """Radius [m] of one terminal's supply region.

    In 3-D (4/3) pi R^3 = Q_N / q_required with Q_N = Q0 / N; by default q_required =
    Q0 / V_tissue so that the N spheres exactly fill the tissue volume. In 2-D the region
    is a disk of area A_tissue / N (``tissue_measure`` is then the area).
    """
    if ndim == 2:
        return math.sqrt(tissue_measure / n_terminals / math.pi)
    if q_required is None:
        return (3.0 * tissue_measure / n_terminals / (4.0 * math.pi)) ** (1.0 / 3.0)
    volume_per_terminal = total_flow / n_terminals / q_required
    return (3.0 * volume_per_terminal / (4.0 * math.pi)) ** (1.0 / 3.0)
