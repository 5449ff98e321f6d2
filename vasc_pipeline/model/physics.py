"""Physical parameters of the tree model and the per-segment cost tables.

Radii and flows follow from topology alone (Murray's law at fixed gamma): with ``n`` the number of
terminals downstream of a segment, ``Q = n Q0 / N`` and ``r = r_t n^(1/gamma)`` with
``r_t = r_in N^(-1/gamma)``. Every per-segment cost is therefore a function of ``n``
times a geometric quantity (length, or the exclusion traversal sum), so the kernel looks
the ``n``-dependent factor up in tables built here once per run.

Blood's apparent viscosity may fall with the vessel's diameter (the Fåhræus–Lindqvist effect):
``physics.viscosity_law`` scales ``physics.viscosity``, the viscosity in large vessels, by
:func:`relative_viscosity`. The radius depends on ``n`` alone, so the law, too, lives in the
tables and costs the kernel nothing.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

__all__ = [
    "Physics",
    "CostTables",
    "VISCOSITY_LAWS",
    "cost_tables",
    "exclusion_weight",
    "relative_viscosity",
    "segment_factors",
    "supply_radius",
]

# Row order of the table array handed to the kernel.
TABLE_VOLUME, TABLE_POWER, TABLE_EXCLUSION, TABLE_RESISTANCE, TABLE_FLOW = range(5)


def _pries_large_vessel_term(d_um: np.ndarray) -> np.ndarray:
    """3.2 - 2.44 exp(-0.06 D^0.645): both Pries fits' relative viscosity at discharge
    hematocrit 0.45, less their small-vessel terms; 3.2 in large vessels."""
    return 3.2 - 2.44 * np.exp(-0.06 * d_um**0.645)


def _pries_in_vitro(d_um: np.ndarray) -> np.ndarray:
    """Relative viscosity (to plasma) of blood at discharge hematocrit 0.45 in glass tubes of
    diameter D [µm] (Pries, Neuhaus & Gaehtgens 1992, Am J Physiol 263:H1770, eq. 7)."""
    return 220.0 * np.exp(-1.3 * d_um) + _pries_large_vessel_term(d_um)


def _pries_in_vivo(d_um: np.ndarray) -> np.ndarray:
    """Relative viscosity (to plasma) of blood at discharge hematocrit 0.45 in living
    microvessels of diameter D [µm], the endothelial surface layer's effect included (Pries et
    al. 1994, Circ Res 75:904): at 0.45 the hematocrit factor is 1 and
    mu = [1 + (mu_0.45 - 1) w] w with w = (D / (D - 1.1))^2."""
    w = (d_um / (d_um - 1.1)) ** 2
    mu_045 = 6.0 * np.exp(-0.085 * d_um) + _pries_large_vessel_term(d_um)
    return (1.0 + (mu_045 - 1.0) * w) * w


# Relative viscosity functions of the diameter in µm, each divided by its large-vessel value 3.2
# in relative_viscosity so that physics.viscosity keeps its meaning in the large vessels.
_RELATIVE_VISCOSITY = {"pries_in_vitro": _pries_in_vitro, "pries_in_vivo": _pries_in_vivo}
VISCOSITY_LAWS = ("constant", *_RELATIVE_VISCOSITY)
# Below this diameter neither fit is defined (the in-vivo one diverges at 1.1 µm); no modelled
# vessel is this small (a capillary is ~5 µm).
_MIN_FIT_DIAMETER_UM = 2.0


def relative_viscosity(diameter: np.ndarray, law: str) -> np.ndarray:
    """Apparent viscosity of blood in a vessel of ``diameter`` [m] relative to that in large
    vessels, under ``law`` (one of :data:`VISCOSITY_LAWS`): 1 everywhere for ``"constant"``;
    for the Pries fits at discharge hematocrit 0.45, their value over their large-vessel limit
    3.2 (in vitro 0.42 at 10 µm, 0.76 at 100 µm; in vivo 1.8 at 10 µm, 0.79 at 100 µm)."""
    d = np.asarray(diameter, dtype=np.float64)
    if law == "constant":
        return np.ones_like(d)
    if law not in _RELATIVE_VISCOSITY:
        raise ValueError(f"physics.viscosity_law: unknown law {law!r}; accepted: {', '.join(VISCOSITY_LAWS)}")
    d_um = np.maximum(d * 1e6, _MIN_FIT_DIAMETER_UM)
    return _RELATIVE_VISCOSITY[law](d_um) / 3.2


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
        Blood viscosity mu [Pa s] in large vessels.
    supply_radius : float
        R_supply of a terminal's supply sphere (disk in 2-D) [m].
    r_cutoff : float
        Segments with radius above this are excluded from tissue [m].
    r_cutoff_ramp : float
        Width [m] of the radii above ``r_cutoff`` over which the exclusion term's weight rises
        linearly from 0 to 1 (:func:`exclusion_weight`); 0: a step at ``r_cutoff`` (the paper).
    A_wv, A_o, A_p, A_s : float
        Weights of the paper's total cost; the annealed cost is
        (C_w + C_v) + (A_o/A_wv) C_o + (A_p/A_wv) C_p + (A_s/A_wv) C_s.
    pressure_inlet, pressure_terminal : float
        Inlet pressure and target terminal pressure for C_p [Pa].
    viscosity_law : str
        How the viscosity varies with the diameter (:func:`relative_viscosity`); ``"constant"``:
        it does not (the paper).
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
    viscosity_law: str = "constant"
    r_cutoff_ramp: float = 0.0

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
        return {
            k: v if isinstance(v, str) else int(v) if isinstance(v, int) else float(v) for k, v in asdict(self).items()
        }


def exclusion_weight(radius: np.ndarray, r_cutoff: float, ramp: float) -> np.ndarray:
    """How much of the exclusion term a vessel of ``radius`` pays: 0 up to ``r_cutoff``, 1 from
    ``r_cutoff + ramp`` on, linear between (``ramp`` = 0: the step, 1 above ``r_cutoff``)."""
    r = np.asarray(radius, dtype=np.float64)
    if ramp <= 0.0:
        return np.where(r > r_cutoff, 1.0, 0.0)
    return np.clip((r - r_cutoff) / ramp, 0.0, 1.0)


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
    real = np.where(r > 0, r, 1.0)  # n = 0: no vessel, its row stays zero
    viscosity = physics.viscosity * relative_viscosity(2.0 * real, physics.viscosity_law)
    resistance = np.where(r > 0, 8.0 * viscosity / (math.pi * real**4), 0.0)
    table = np.zeros((5, n.size), dtype=np.float64)
    table[TABLE_VOLUME] = physics.m_b * area
    table[TABLE_POWER] = q**2 * resistance
    table[TABLE_EXCLUSION] = exclusion_weight(r, physics.r_cutoff, physics.r_cutoff_ramp) * area
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
