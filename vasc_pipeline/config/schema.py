"""Configuration schema, validation and composition.

The dataclasses below, with the sweep and cluster groups of
:mod:`vasc_pipeline.config.pipeline`, are the single source of defaults and types (Hydra
registers them as structured configs, so a wrong type or unknown key fails at once).
:func:`validate` checks ranges and names the offending field before any job starts.
:func:`compose` builds a resolved config from Hydra-style overrides for scripts and tests;
it is the only function here that touches Hydra.
"""

from __future__ import annotations

import inspect
import json
import math
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path
from typing import Any, Optional

from .errors import ConfigError
from .frozen import Settings, _freeze, is_frozen, thawed
from .pipeline import ClusterConfig, SlurmConfig, SweepConfig, TLSConfig
from .rules import MAX_STEPS, MAX_TERMINALS, SEED_ACCEPTED, SWEPT_KEYS, Rule, seed_ok, sweep_axis

__all__ = [  # with the pipeline's groups of vasc_pipeline.config.pipeline (re-exported: public API)
    "ConfigError",
    "KEYS_ADDED_LATER",
    "TissueConfig",
    "LabelsConfig",
    "PhysicsConfig",
    "AnnealConfig",
    "TerminalsConfig",
    "CheckpointConfig",
    "MethodConfig",
    "ExtendConfig",
    "METHODS",
    "ModelConfig",
    "MODELS",
    "RunConfig",
    "SweepConfig",
    "ClusterConfig",
    "TLSConfig",
    "SlurmConfig",
    "to_run_config",
    "from_stored",
    "validate",
    "Rule",
    "SWEPT_KEYS",
    "sweep_axis",
    "HEART_EXCLUSION_VOXEL_SIZE",
    "ORGANS",
    "organ_of",
    "scheduled_steps",
    "packing_steps",
    "CONFIG_DIR",
]

# An installed wheel carries conf/ inside the package; a source checkout has it at the top.
_PACKAGE_DIR = Path(__file__).resolve().parents[1]  # vasc_pipeline/
CONFIG_DIR = _PACKAGE_DIR / "conf" if (_PACKAGE_DIR / "conf").is_dir() else _PACKAGE_DIR.parent / "conf"
STAGES = ("run", "reduce", "extend")  # run: sweep then reduction; reduce: reduction of existing runs only;
# extend: the whole tree below existing runs (vasc_pipeline.pipeline.extend)
EXTEND_RUNS = ("best", "all")  # extend.runs: the lowest-cost seed of each cell, or every complete run
PAPER_STEPS_AT_1000 = 1e9  # the paper's ~1e9 updates for 1000 terminals, steps ∝ N^2
HEART_EXCLUSION_VOXEL_SIZE = 1.1533753893850243e-3  # m: R_supply / 4 of the heart at N = 500
MAX_CALIBRATION_SAMPLES = 10**7  # calibration moves (and adaptation windows): beyond, memory and time, no accuracy
MAX_CHECKPOINT_SECONDS = 7 * 86400.0  # a week: the longest sensible gap between checkpoints
MAX_COARSE_EXCLUSION_FACTOR = 8  # coarser, a coarse voxel is twice R_supply: the map no longer resolves the tissue
# The bifurcation exponent of r_parent^gamma = sum r_child^gamma (radii r = r_t n^(1/gamma)): measured
# trees lie in between (Murray's 3, the paper's coronary 2.1, 2-3 elsewhere). Far outside, the radii
# span hundreds of decades over N (gamma = 0.01: r_t ~ 1e-230 m) and the flow solve is singular.
GAMMA_RANGE = (1.0, 4.0)


# Keys added after runs were already stored, with the value that does what the code did
# before the key existed. A stored config that lacks such a key is the same run as a
# requested config holding that value, so a new option never invalidates old results
# (identity.hashed_config leaves these keys out at these values). A key whose default changed
# the model (tissue.exclude_cavities: True) is listed with its old behaviour, so runs made
# before it are, rightly, a different configuration.
KEYS_ADDED_LATER: dict[str, Any] = {
    "model.name": "paper",
    "tissue.exclude_cavities": False,
    "tissue.exclusion_path": None,
    "tissue.exclusion_array": None,
    "tissue.inlet_share": None,
    "tissue.inlet_share_tolerance": None,
    "tissue.inlet_assignment": "random",
    "tissue.bifurcation_reach": None,
    "tissue.ostium_height": None,
    "tissue.base_cut": None,
    "tissue.elongation": None,
    "tissue.exclusion_voxel_size": None,
    "tissue.labels": {"supply": None, "exclusion": None, "open": None},
    "tissue.inlets_path": None,
    "tissue.organ": None,
    "tissue.cavity_paths": None,
    "tissue.mesh_unit": "m",
    "tissue.demand_path": None,
    "anneal.steps_exponent": 2.0,
    "anneal.packing_steps_per_terminal": 0.0,
    "anneal.packing_T_start": 1.0,
    "anneal.packing_T_end": 0.05,
    "anneal.init": "random",
    "anneal.full_width_phase": 1.0,
    "anneal.cold_from": None,
    "anneal.cold_share": None,
    "anneal.coarse_exclusion_factor": None,
    "anneal.coarse_exclusion_phase": None,
    "anneal.parts": 1,
    "anneal.part_phases": 64,
    "anneal.part_share": 0.9,
    "method.avoid_cavities": False,
}
MODELS = ("paper", "physiological")  # conf/model/: which physics and tissue keys a model sets
METHODS = ("anneal", "cco")  # how a tree is grown: simulated annealing, or constructive (vasc_pipeline.engine.cco)
ANNEAL_INITS = ("random", "cco")  # the anneal's initial tree
INLET_ASSIGNMENTS = ("random", "nearest")  # which terminals of the initial tree each inlet feeds
ORGANS = ("heart", "other")  # tissue.organ: the reduction compares a heart's trees with Kassab's pig coronaries
# Tissue keys that apply to every tissue; each other key is read only by the tissue builders
# (vasc_pipeline.model.tissue.TISSUES) whose signature names it.
TISSUE_KEYS_OF_EVERY_TISSUE = (
    "name",
    "q_required",
    "exclusion_voxel_size",
    "inlet_share",
    "inlet_share_tolerance",
    "inlet_assignment",
    "bifurcation_reach",
    "inlets",
    "inlets_path",
    "organ",
    "demand_path",
)


@dataclass
class LabelsConfig(Settings):
    """tissue=mask: which label values of the mask (a NIfTI or NRRD label map, or any integer
    array) play which part; all None: nonzero = tissue."""

    supply: Optional[list[int]] = None  # the tissue (myocardium); None: every nonzero label not named below
    exclusion: Optional[list[int]] = None  # not supplied, but not to be crossed by large vessels (cavities)
    open: Optional[list[int]] = None  # outside, looked through by the exclusion map (the space above a base cut)


@dataclass
class TissueConfig(Settings):
    name: str = "heart"
    voxel_size: Optional[float] = None  # m; None: R_supply / 4 (~270 voxels per supply sphere)
    # The grid the exclusion term is summed on, m, fixed whatever N (its D and L are in its
    # voxels); None: the supply grid above (whose voxel follows N unless voxel_size is set).
    # conf/tissue/heart.yaml sets HEART_EXCLUSION_VOXEL_SIZE; None here, as the other tissues
    # (a shape built in code has no N-independent edge that suits it)
    exclusion_voxel_size: Optional[float] = None
    q_required: Optional[float] = None  # s^-1; None: the N supply spheres fill the tissue
    radius: float = 0.02  # sphere radius, m
    size: list[float] = field(default_factory=lambda: [0.04, 0.04, 0.02])  # box edges [x, y, z], m
    side: float = 0.1  # plane2d square side, m
    mass_g: float = 218.0  # heart: myocardial mass, g
    density: float = 1.06e3  # heart: myocardial density, kg m^-3
    exclude_cavities: bool = True  # heart: large vessels also kept out of the ventricular cavities
    ostium_height: Optional[float] = None  # heart: LCA and RCA ostia above the base plane, m; None: 5.8 mm at 218 g
    # heart's shape before scaling to mass_g (tissue.heart): the base plane's height above the
    # LV's equator in LV half-lengths, None: 1/3; the factor on the long-axis lengths, None: 1
    base_cut: Optional[float] = None
    elongation: Optional[float] = None
    path: Optional[str] = None  # mask: .npy file or Zarr array; surface: a closed surface (STL, OBJ, PLY, VTP)
    cavity_paths: Optional[list[str]] = None  # surface: closed surfaces of cavities inside it (excluded, not supplied)
    mesh_unit: str = "m"  # surface: the unit of the surface files' coordinates (m, cm, mm, um)
    # Every tissue: a map of relative perfusion demand (> 0 in the tissue), quantised to the supply
    # term's coverage targets (model.tissue.demand); None: one sphere per voxel everywhere.
    demand_path: Optional[str] = None
    array: Optional[str] = None  # mask: array name inside a Zarr group
    origin: Optional[list[float]] = None  # mask: [x, y, z] of voxel [0, 0, 0] centre, m
    # Inlet positions [x, y, z], m (numbers; checked by validate): a mask's (required, or inlets_path), or
    # the ostia replacing any other tissue's own (the grid stays the tissue's); None: the tissue's own
    inlets: Optional[list[list[Any]]] = None
    exclusion_path: Optional[str] = None  # mask: optional second mask (same grid) large vessels must not cross
    exclusion_array: Optional[str] = None  # mask: its array name inside a Zarr group
    labels: LabelsConfig = field(default_factory=LabelsConfig)  # mask: label values by role
    inlets_path: Optional[str] = None  # as inlets, from a JSON {name: [x, y, z]} or CSV x, y, z[, name] (m)
    # Fraction of the terminals fed by each inlet, in the tissue's inlet order (heart: LCA,
    # RCA); None: free, the anneal finds the split (the paper). Fixed, it is kept exactly.
    inlet_share: Optional[list[float]] = None
    # With inlet_share: how far each inlet's share may stray from it (0.1: 0.62 +- 0.1), the inlet
    # trees trading subtrees freely inside the band; None: kept exactly.
    inlet_share_tolerance: Optional[float] = None
    # Which terminals of the initial tree each inlet feeds: "random" (the paper's), or
    # "nearest" (by distance to the inlets, keeping inlet_share's counts when it is set).
    inlet_assignment: str = "random"
    # How far outside the exclusion domain a bifurcation may lie, m (0: in it, e.g. on the
    # heart); None: anywhere in the voxel grid's box (the paper).
    bifurcation_reach: Optional[float] = None
    # What organ the tissue is: "heart" (the reduction compares the trees with Kassab's pig coronary
    # arteries) or "other" (it does not); None: organ_of decides (a mask with one inlet is "other").
    # Read by the reduction only: the tree does not depend on it.
    organ: Optional[str] = None


@dataclass
class PhysicsConfig(Settings):
    gamma: float = 2.1  # bifurcation exponent
    inlet_radius: float = 2.1e-3  # combined inlet radius r_in, m
    total_flow: float = 4.16e-6  # Q0, m^3 s^-1
    m_b: float = 641.3  # W m^-3
    viscosity: float = 3.6e-3  # Pa s
    r_cutoff: float = 1e-5  # m
    A_wv: float = 1e4
    A_o: float = 100.0
    A_p: float = 0.0
    A_s: float = 1e30
    pressure_inlet: float = 13.3e3  # Pa (100 mmHg)
    pressure_terminal: float = 12.0e3  # Pa


@dataclass
class AnnealConfig(Settings):
    """The schedule and moves. The defaults are ``anneal=fast``'s, the composed default;
    ``anneal=paper`` and ``anneal=fast_v1`` (conf/anneal/) set every value they differ in."""

    name: str = "fast"
    T_start: Optional[float] = None  # W; None: calibrated so uphill moves start accept_start accepted
    T_end: Optional[float] = None  # W; None: T_end_rel * (cost of one terminal segment of length R_supply)
    accept_start: float = 0.8  # mean acceptance of uphill moves at a calibrated T_start
    T_end_rel: float = 1e-4  # calibrated T_end relative to w(1) R_supply
    calibration_samples: int = 4000  # infinite-temperature moves measured for T_start
    steps: Optional[int] = None  # proposed moves; None: steps_at_1000 * (N / 1000)^steps_exponent
    steps_at_1000: float = 6.25e7  # the paper: PAPER_STEPS_AT_1000
    steps_exponent: float = 1.7  # budget law in N (the paper's guess: 2)
    packing_steps_per_terminal: float = 0.0  # packing phase (supply alone, terminals only) before the tree
    # anneal, in proposals per terminal, part of the steps; 0: none
    packing_T_start: float = 1.0  # its temperature at the start, in voxels of one supply sphere
    packing_T_end: float = 0.05  # ... and at its end, in C_s units
    p_swap: float = 0.3  # probability that a proposal is a swap
    p_local: float = 0.9  # probability that a swap partner is a spatial neighbour (else uniform)
    neighbour_cell: float = 2.0  # edge of the neighbour cells, in R_supply
    step_terminal: float = 0.5  # translation half-width for terminals, in R_supply (the cap when adapted)
    step_bifurcation: float = 1.0  # translation half-width for bifurcations, in R_supply (the cap when adapted)
    supply_T_start: Optional[float] = 1.0  # supply's own temperature at step 0, in units of the voxels of one
    # supply sphere; None: supply is searched downhill throughout (the paper)
    supply_T_end: float = 0.05  # ... at the end of its phase, in C_s units (0.05: +1 accepted at e^-20)
    supply_phase: float = 0.8  # fraction of the steps the supply schedule runs; then the true weight
    adapt_steps: bool = True  # adapt half-widths to keep acceptance near acceptance_target
    full_width_phase: float = 0.4  # with adapted steps: fraction of the steps in which half of the terminal
    # moves keep the full width step_terminal; afterwards every terminal move takes the adapted step
    cold_from: Optional[float] = 0.5  # where the schedule's cold part starts, as a share of the way from
    # T_start to T_end in log T; None: one exponential from T_start to T_end
    cold_share: Optional[float] = 0.2  # with cold_from: the share of the tree anneal's steps spent in it
    coarse_exclusion_factor: Optional[int] = 2  # the exclusion term on a depth map this many times
    # coarser (ExclusionGrid.coarsened) over the first coarse_exclusion_phase of the tree anneal's steps,
    # then on the true one; None: the true map throughout
    coarse_exclusion_phase: Optional[float] = 0.4
    acceptance_target: float = 0.1  # per node class (terminal, bifurcation)
    adapt_window: int = 1000  # proposals of a class between adaptations
    polish: bool = True  # optimise the final topology's bifurcation positions (engine.polish)
    polish_swaps_max_terminals: int = 8  # with polish, up to this N: single-swap descent (engine.polish.descend_swaps)
    trace_every: int = 100_000  # steps between trace records (with parts > 1: one record a phase)
    # One tree on several workers (engine.parts): the tree anneal in part_phases phases, each
    # part_share of its proposals in `parts` independent parts of the tree (run by the cluster's
    # workers), the rest on the whole tree; parts = 1: the serial anneal
    parts: int = 1
    part_phases: int = 64
    part_share: float = 0.9
    init: str = "random"  # initial tree: "random" (the paper's) or "cco" (vasc_pipeline.engine.cco, method.* settings)


@dataclass
class ModelConfig(Settings):
    """Which model the physics and tissue keys spell (``model=paper``, ``model=physiological``;
    conf/model/): the group sets those keys, this name records the choice. Every key it sets
    stays overridable, so the name is a label, and the keys are the run's identity."""

    name: str = "paper"


@dataclass
class TerminalsConfig(Settings):
    path: Optional[str] = None  # CSV of x, y, z (m)
    fixed: bool = False  # fixed sites never move; the supply term is off


@dataclass
class MethodConfig(Settings):
    """How the tree is grown: ``method=anneal`` (default) or ``method=cco`` (conf/method/)."""

    name: str = "anneal"
    candidates: int = 20  # cco: nearest segments evaluated for each new terminal
    max_tries: int = 10  # cco: rejected sites before the distance criterion shrinks
    shrink: float = 0.9  # cco: factor of that shrink
    order: str = "file"  # cco with terminals.path: "file" order or a seeded "random" order
    avoid_cavities: bool = False  # cco: no new segment crosses a cavity voxel (tissue.cavity); the extension's rule


@dataclass
class ExtendConfig(Settings):
    """``+stage=extend``: the whole tree below the complete runs of output_dir (vasc_pipeline.engine.extend).

    Not part of any run's identity (the run stores never hold it); an extended store holds what
    determines its own result.
    """

    n_terminals: int = 1_000_000  # fine terminals in all, rounded to a multiple of the run's N
    runs: str = "best"  # "best": the lowest-cost seed of each cell; "all": every complete run
    batch_territories: int = 200  # territories per task (the result does not depend on it)
    seed: Optional[int] = None  # None: the run's own seed


@dataclass
class CheckpointConfig(Settings):
    every_seconds: float = 60.0


@dataclass
class RunConfig(Settings):
    n_terminals: int = 200
    seed: int = 0
    output_dir: str = "results/default"
    model: ModelConfig = field(default_factory=ModelConfig)
    tissue: TissueConfig = field(default_factory=TissueConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    anneal: AnnealConfig = field(default_factory=AnnealConfig)
    terminals: TerminalsConfig = field(default_factory=TerminalsConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    method: MethodConfig = field(default_factory=MethodConfig)
    extend: ExtendConfig = field(default_factory=ExtendConfig)
    # The pipeline's groups (dataclasses in vasc_pipeline.config.pipeline): +sweep=NAME adds
    # a sweep, so it is optional; cluster is always present (cluster=local by default).
    sweep: Optional[SweepConfig] = None
    cluster: ClusterConfig = field(default_factory=lambda: ClusterConfig())
    # What the command does: "run" the sweep (then reduce it), only "reduce" the runs already in
    # output_dir (+stage=reduce), or "extend" them (+stage=extend). Not part of a run's identity
    # (sweep.py drops it).
    stage: str = "run"


def organ_of(tissue: str, organ: Optional[str], n_inlets: int) -> str:
    """``tissue.organ`` as the reduction reads it: "heart" (compared with Kassab's pig coronary
    arteries) or "other".

    Unset (None): a heart for ``tissue=heart`` and for the shapes (sphere, box, plane2d: the test
    domains, reduced as stand-ins for the heart as they always were), and for a mask or surface with
    two or more inlets (the coronary ostia: a heart's label map or surfaces); "other" for a mask or
    surface with one inlet.
    """
    if organ is not None:
        return organ
    return "other" if tissue in ("mask", "surface") and n_inlets < 2 else "heart"


def to_run_config(cfg: Any) -> RunConfig:
    """A :class:`RunConfig` from a RunConfig, a dict or an OmegaConf node (extra keys ignored)."""
    if isinstance(cfg, RunConfig):
        return cfg
    from omegaconf import OmegaConf

    container = OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else _plain(dict(cfg))
    known = set(RunConfig.__dataclass_fields__)
    schema = OmegaConf.structured(RunConfig)
    try:
        merged = OmegaConf.merge(schema, {k: v for k, v in container.items() if k in known})
    except Exception as exc:  # omegaconf's message names the key and the type it wanted
        raise ConfigError(f"invalid configuration: {exc}") from exc
    return OmegaConf.to_object(merged)


def _plain(value: Any) -> Any:
    """Nested dicts and lists as plain ones (OmegaConf refuses a list subclass: ReadOnlyList)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def from_stored(stored: Any) -> RunConfig:
    """The :class:`RunConfig` of a run store's config (its ``config`` attribute): the keys it
    lacks, added to the schema after it was written, at the values that reproduce what the
    code did before them (:data:`KEYS_ADDED_LATER`), not at today's defaults."""
    stored = _plain(dict(stored))  # a copy, of plain types
    for dotted, neutral in KEYS_ADDED_LATER.items():
        *path, key = dotted.split(".")
        node = stored
        for part in path:
            node = node.get(part) if isinstance(node, dict) else None
        if isinstance(node, dict) and key not in node:
            node[key] = neutral
    return to_run_config(stored)


def _positive(name: str, value: float) -> None:
    if value is None or not (value > 0 and math.isfinite(value)):
        raise ConfigError(f"{name} must be a finite number > 0, got {value}")


def _check_finite(node: Any, name: str) -> None:
    """Every float anywhere in the config must be finite (NaN and inf pass every range check)."""
    if hasattr(node, "__dataclass_fields__"):
        for key in node.__dataclass_fields__:
            _check_finite(getattr(node, key), f"{name}.{key}" if name else key)
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            _check_finite(value, f"{name}[{i}]")
    elif isinstance(node, float) and not math.isfinite(node):
        raise ConfigError(f"{name} must be a finite number, got {node}")


def scheduled_steps(cfg: RunConfig) -> int:
    """Proposed moves of a run: ``anneal.steps`` exactly when given, else the schedule's default
    ``steps_at_1000 * (N / 1000)^steps_exponent``. A CCO run (``method=cco``) counts terminals
    added instead: N.
    """
    if cfg.method.name == "cco":
        return int(cfg.n_terminals)
    if cfg.anneal.steps is not None:
        return int(cfg.anneal.steps)
    return max(1, int(round(cfg.anneal.steps_at_1000 * (cfg.n_terminals / 1000.0) ** cfg.anneal.steps_exponent)))


def packing_steps(cfg: RunConfig) -> int:
    """Proposals of the packing phase (the first of the run's steps): per terminal times N."""
    return int(round(cfg.anneal.packing_steps_per_terminal * cfg.n_terminals))


def validate(cfg: RunConfig) -> RunConfig:
    """Check every range the model needs; raise :class:`ConfigError` naming the field.

    Returns a validated copy, frozen (:mod:`vasc_pipeline.config.frozen`): the engine and the
    planner take it as it is. A frozen config was validated already and is returned unchanged.
    """
    from ..model.tissue import TISSUES

    if is_frozen(cfg):
        return cfg
    cfg = thawed(cfg)
    _check_finite(cfg, "")
    if not str(cfg.output_dir).strip():
        raise ConfigError("output_dir must name a directory, got an empty string; give one with output_dir=...")
    # as their kind: a script's n_terminals=5.0 is run as 5
    cfg.seed = SWEPT_KEYS["seeds"].check("seed", cfg.seed)
    cfg.n_terminals = SWEPT_KEYS["n_terminals"].check("n_terminals", cfg.n_terminals)
    if cfg.anneal.steps is not None:
        cfg.anneal.steps = SWEPT_KEYS["steps"].check("anneal.steps", cfg.anneal.steps)
    cfg.physics.m_b = SWEPT_KEYS["m_b"].check("physics.m_b", cfg.physics.m_b)
    if cfg.sweep is not None:
        for axis in SWEPT_KEYS:
            sweep_axis(axis, getattr(cfg.sweep, axis), None)
    if cfg.tissue.inlets is not None:
        if not cfg.tissue.inlets:
            raise ConfigError("tissue.inlets must hold at least one [x, y, z] position in metres (or be null), got []")
        for k, p in enumerate(cfg.tissue.inlets):
            if not (
                isinstance(p, (list, tuple))
                and len(p) == 3
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p)
            ):
                raise ConfigError(f"tissue.inlets[{k}] must be an [x, y, z] position in metres, got {p!r}")
        cfg.tissue.inlets = [[float(v) for v in p] for p in cfg.tissue.inlets]
    phys = cfg.physics
    if not phys.pressure_inlet > phys.pressure_terminal >= 0.0:
        raise ConfigError(
            "physics.pressure_inlet must exceed physics.pressure_terminal, which must be >= 0 (Pa; blood "
            f"flows from the inlets to the terminals), got {phys.pressure_inlet:g} and {phys.pressure_terminal:g}"
        )
    if cfg.model.name not in MODELS:
        raise ConfigError(f"model.name: unknown model {cfg.model.name!r}; accepted: {', '.join(MODELS)} (model=...)")
    if cfg.tissue.name not in TISSUES:
        raise ConfigError(f"tissue.name: unknown tissue {cfg.tissue.name!r}; accepted: {', '.join(sorted(TISSUES))}")
    if cfg.tissue.organ is not None and cfg.tissue.organ not in ORGANS:
        raise ConfigError(
            f"tissue.organ must be one of {', '.join(ORGANS)}, or null (decided by the tissue), "
            f"got {cfg.tissue.organ!r}"
        )
    if cfg.tissue.inlet_assignment not in INLET_ASSIGNMENTS:
        raise ConfigError(
            f"tissue.inlet_assignment must be one of {', '.join(INLET_ASSIGNMENTS)}, "
            f"got {cfg.tissue.inlet_assignment!r}"
        )
    share = cfg.tissue.inlet_share
    if share is not None:
        if not share or any(not (s > 0) for s in share) or abs(sum(share) - 1.0) > 1e-6:
            raise ConfigError(
                f"tissue.inlet_share must list one fraction > 0 per inlet, summing to 1 (heart: [LCA, RCA], "
                f"e.g. [0.62, 0.38]), got {list(share)}"
            )
        if cfg.method.name == "cco" or cfg.anneal.init == "cco":
            raise ConfigError(
                "tissue.inlet_share fixes the terminals of every inlet, which the CCO growth (method=cco, "
                "anneal.init=cco) assigns by connection: leave it unset (null) there"
            )
    tolerance = cfg.tissue.inlet_share_tolerance
    if tolerance is not None:
        if share is None:
            raise ConfigError(
                "tissue.inlet_share_tolerance is a band around tissue.inlet_share: set the share too (heart: "
                f"tissue.inlet_share=[0.62,0.38]), or leave the tolerance null; got {tolerance}"
            )
        if not 0.0 < tolerance < 1.0:
            raise ConfigError(f"tissue.inlet_share_tolerance must lie in (0, 1) (a share's +-), got {tolerance}")
    reach = cfg.tissue.bifurcation_reach
    if reach is not None:
        if not (reach >= 0 and math.isfinite(reach)):
            raise ConfigError(f"tissue.bifurcation_reach must be a length >= 0 in metres, or null, got {reach}")
        if cfg.method.name == "cco":
            raise ConfigError(
                "tissue.bifurcation_reach confines the anneal's bifurcations; the CCO growth (method=cco) "
                "places them at their optimum: leave it unset (null) there"
            )
    _check_tissue_keys(cfg.tissue)
    if cfg.tissue.ostium_height is not None and (cfg.tissue.inlets is not None or cfg.tissue.inlets_path):
        given = "tissue.inlets" if cfg.tissue.inlets is not None else "tissue.inlets_path"
        raise ConfigError(
            f"tissue.ostium_height places the heart's own ostia, which {given} replaces: set one of them "
            f"(got ostium_height={cfg.tissue.ostium_height:g} m)"
        )
    if cfg.tissue.inlets is not None and cfg.tissue.inlets_path:
        raise ConfigError("tissue.inlets and tissue.inlets_path both give the inlets: set one of them")
    _check_labels(cfg.tissue.labels)
    _check_surface_keys(cfg.tissue)
    p = cfg.physics
    for name in ("gamma", "inlet_radius", "total_flow", "viscosity", "A_wv"):
        _positive(f"physics.{name}", getattr(p, name))
    for name in ("r_cutoff", "A_o", "A_p", "A_s"):
        value = getattr(p, name)
        if not (value >= 0 and math.isfinite(value)):
            raise ConfigError(f"physics.{name} must be a finite number >= 0, got {value}")
    if not GAMMA_RANGE[0] <= p.gamma <= GAMMA_RANGE[1]:
        raise ConfigError(
            f"physics.gamma must lie in [{GAMMA_RANGE[0]:g}, {GAMMA_RANGE[1]:g}] (the bifurcation exponent of "
            f"r_parent^gamma = sum r_child^gamma: Murray's 3, the paper's 2.1), got {p.gamma:g}"
        )
    _check_segment_costs(cfg)
    a = cfg.anneal
    if a.T_start is not None:
        _positive("anneal.T_start", a.T_start)
    if a.T_end is not None:
        _positive("anneal.T_end", a.T_end)
    if a.T_start is not None and a.T_end is not None and a.T_end >= a.T_start:
        raise ConfigError(f"anneal.T_end must be < anneal.T_start, got T_end={a.T_end} >= T_start={a.T_start}")
    for name in ("accept_start", "acceptance_target"):
        if not 0.0 < getattr(a, name) < 1.0:
            raise ConfigError(f"anneal.{name} must lie in (0, 1), got {getattr(a, name)}")
    _positive("anneal.T_end_rel", a.T_end_rel)
    if a.supply_T_start is not None:
        _positive("anneal.supply_T_start", a.supply_T_start)
        _positive("anneal.supply_T_end", a.supply_T_end)
        if a.supply_T_end >= a.supply_T_start:
            raise ConfigError(
                f"anneal.supply_T_end must be < anneal.supply_T_start, got {a.supply_T_end} >= {a.supply_T_start}"
            )
    if not 0.0 < a.supply_phase <= 1.0:
        raise ConfigError(f"anneal.supply_phase must lie in (0, 1], got {a.supply_phase}")
    if not 0.0 < a.full_width_phase <= 1.0:
        raise ConfigError(f"anneal.full_width_phase must lie in (0, 1], got {a.full_width_phase}")
    if (a.cold_from is None) != (a.cold_share is None):
        raise ConfigError(
            f"anneal.cold_from and anneal.cold_share are set together (both null: one exponential), "
            f"got cold_from={a.cold_from}, cold_share={a.cold_share}"
        )
    if a.cold_from is not None:
        for name in ("cold_from", "cold_share"):
            if not 0.0 < getattr(a, name) < 1.0:
                raise ConfigError(f"anneal.{name} must lie in (0, 1), got {getattr(a, name)}")
    _check_parts(cfg)
    if (a.coarse_exclusion_factor is None) != (a.coarse_exclusion_phase is None):
        raise ConfigError(
            "anneal.coarse_exclusion_factor and anneal.coarse_exclusion_phase are set together (both null: the "
            f"true depth map throughout), got factor={a.coarse_exclusion_factor}, phase={a.coarse_exclusion_phase}"
        )
    if a.coarse_exclusion_factor is not None:
        f = a.coarse_exclusion_factor
        if isinstance(f, bool) or not isinstance(f, int) or not 2 <= f <= MAX_COARSE_EXCLUSION_FACTOR:
            raise ConfigError(
                f"anneal.coarse_exclusion_factor must be an integer in [2, {MAX_COARSE_EXCLUSION_FACTOR}] "
                f"(voxels per coarse voxel edge), got {f!r}"
            )
        if not 0.0 < a.coarse_exclusion_phase < 1.0:
            raise ConfigError(f"anneal.coarse_exclusion_phase must lie in (0, 1), got {a.coarse_exclusion_phase}")
    _positive("anneal.neighbour_cell", a.neighbour_cell)
    if not isinstance(a.polish_swaps_max_terminals, int) or a.polish_swaps_max_terminals < 0:
        raise ConfigError(
            f"anneal.polish_swaps_max_terminals must be an integer >= 0, got {a.polish_swaps_max_terminals}"
        )
    for name in ("calibration_samples", "adapt_window"):
        if not isinstance(getattr(a, name), int) or not 1 <= getattr(a, name) <= MAX_CALIBRATION_SAMPLES:
            raise ConfigError(
                f"anneal.{name} must be an integer in [1, {MAX_CALIBRATION_SAMPLES:.0e}], got {getattr(a, name)}"
            )
    if not 0.0 <= a.p_local <= 1.0:
        raise ConfigError(f"anneal.p_local must lie in [0, 1], got {a.p_local}")
    _positive("anneal.steps_at_1000", a.steps_at_1000)
    if a.steps is None and scheduled_steps(cfg) > MAX_STEPS:
        raise ConfigError(
            f"anneal.steps_at_1000={a.steps_at_1000:g} schedules {scheduled_steps(cfg):.3g} proposed "
            f"moves at n_terminals={cfg.n_terminals}, more than {MAX_STEPS:.0e}; lower it or set "
            "anneal.steps"
        )
    if not (0.0 <= a.steps_exponent <= 4.0):
        raise ConfigError(f"anneal.steps_exponent must lie in [0, 4], got {a.steps_exponent}")
    if not (0.0 <= a.packing_steps_per_terminal < math.inf):
        raise ConfigError(
            f"anneal.packing_steps_per_terminal must be a finite number >= 0, got {a.packing_steps_per_terminal}"
        )
    if a.packing_steps_per_terminal > 0:
        _positive("anneal.packing_T_start", a.packing_T_start)
        _positive("anneal.packing_T_end", a.packing_T_end)
        if cfg.terminals.fixed:
            raise ConfigError(
                "anneal.packing_steps_per_terminal must be 0 with terminals.fixed=true (the packing "
                "phase moves terminals)"
            )
        if packing_steps(cfg) >= scheduled_steps(cfg):
            raise ConfigError(
                f"anneal.packing_steps_per_terminal={a.packing_steps_per_terminal:g} gives "
                f"{packing_steps(cfg)} packing proposals, but the run has only {scheduled_steps(cfg)} "
                "(anneal.steps): leave room for the tree anneal"
            )
    if not 0.0 <= a.p_swap <= 1.0:
        raise ConfigError(f"anneal.p_swap must lie in [0, 1], got {a.p_swap}")
    _positive("anneal.step_terminal", a.step_terminal)
    _positive("anneal.step_bifurcation", a.step_bifurcation)
    if not isinstance(a.trace_every, int) or not 1 <= a.trace_every <= MAX_STEPS:
        raise ConfigError(f"anneal.trace_every must be an integer in [1, {MAX_STEPS:.0e}], got {a.trace_every}")
    for name in ("voxel_size", "exclusion_voxel_size"):
        if getattr(cfg.tissue, name) is not None:
            _positive(f"tissue.{name}", getattr(cfg.tissue, name))
    if cfg.tissue.q_required is not None:
        _positive("tissue.q_required", cfg.tissue.q_required)
    _positive("checkpoint.every_seconds", cfg.checkpoint.every_seconds)
    if cfg.checkpoint.every_seconds > MAX_CHECKPOINT_SECONDS:
        raise ConfigError(
            f"checkpoint.every_seconds must be <= {MAX_CHECKPOINT_SECONDS:g} (a week), got "
            f"{cfg.checkpoint.every_seconds}"
        )
    if cfg.stage not in STAGES:
        raise ConfigError(f"stage must be one of {', '.join(STAGES)}, got {cfg.stage!r}")
    _validate_extend(cfg.extend)
    _validate_method(cfg)
    if cfg.terminals.fixed and not cfg.terminals.path:
        raise ConfigError("terminals.fixed=true needs terminals.path (a CSV of x, y, z in metres)")
    return _freeze(cfg)


def _check_parts(cfg: RunConfig) -> None:
    a = cfg.anneal
    if not isinstance(a.parts, int) or not 1 <= a.parts <= max(1, cfg.n_terminals // 16):
        raise ConfigError(
            f"anneal.parts must be an integer in [1, n_terminals / 16 = {max(1, cfg.n_terminals // 16)}] (parts of at "
            f"least 16 terminals), got {a.parts}"
        )
    if not isinstance(a.part_phases, int) or not 1 <= a.part_phases <= 100_000:
        raise ConfigError(f"anneal.part_phases must be an integer in [1, 100000], got {a.part_phases}")
    if not 0.0 < a.part_share < 1.0:
        raise ConfigError(f"anneal.part_share must lie in (0, 1), got {a.part_share}")
    if a.parts > 1 and cfg.physics.A_p != 0:
        raise ConfigError(
            f"anneal.parts={a.parts} needs physics.A_p = 0: the terminal-pressure term couples every segment of "
            "the tree, so parts could not be annealed apart"
        )
    if a.parts > 1 and cfg.method.name != "anneal":
        raise ConfigError(f"anneal.parts={a.parts} applies to method=anneal only, got method={cfg.method.name}")


def _check_labels(labels: LabelsConfig) -> None:
    """Each of tissue.labels.* null or a non-empty list of integers >= 0, no label in two roles."""
    seen: dict[int, str] = {}
    for role in ("supply", "exclusion", "open"):
        values = getattr(labels, role)
        if values is None:
            continue
        if not values or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in values):
            raise ConfigError(
                f"tissue.labels.{role} must be a non-empty list of integer label values >= 0, or null, got {values!r}"
            )
        for v in values:
            if v in seen:
                raise ConfigError(f"tissue.labels: label {v} is both {seen[v]} and {role}; give each label one role")
            seen[v] = role


def _check_surface_keys(tissue: TissueConfig) -> None:
    """tissue.cavity_paths null or a non-empty list of paths, tissue.mesh_unit a known unit, and
    tissue.demand_path null or a path (the files themselves are read, and refused, by the tissue)."""
    from ..model.tissue.surfaces import MESH_UNITS

    cavities = tissue.cavity_paths
    if cavities is not None and (not cavities or not all(isinstance(c, str) and c.strip() for c in cavities)):
        raise ConfigError(
            "tissue.cavity_paths must be a non-empty list of closed surface files (STL, OBJ, PLY, VTP), or null, "
            f"got {cavities!r}"
        )
    if tissue.mesh_unit not in MESH_UNITS:
        raise ConfigError(f"tissue.mesh_unit must be one of {', '.join(MESH_UNITS)}, got {tissue.mesh_unit!r}")
    if tissue.demand_path is not None and not str(tissue.demand_path).strip():
        raise ConfigError("tissue.demand_path must name a file (.npy, Zarr, NIfTI, NRRD), or be null, got ''")


def _check_segment_costs(cfg: RunConfig) -> None:
    """Every segment's radius, Poiseuille resistance, power and volume cost (n = 1..N terminals
    downstream, r = r_in (n / N)^(1/gamma)) must be a finite number > 0 in float64: where the
    physics parameters together leave that range, the model is not defined (and the flow
    solve fails far from the setting that caused it)."""
    import numpy as np

    p = cfg.physics
    n = np.arange(1, cfg.n_terminals + 1, dtype=np.float64)
    with np.errstate(all="ignore"):
        r = p.inlet_radius * (n / cfg.n_terminals) ** (1.0 / p.gamma)
        resistance = 8.0 * p.viscosity / (math.pi * r**4)
        parts = {
            "radius": r,
            "resistance": resistance,
            "power": (n * p.total_flow / cfg.n_terminals) ** 2 * resistance,
            "volume cost": p.m_b * math.pi * r**2,
        }
    for what, values in parts.items():
        if not (np.all(np.isfinite(values)) and np.all(values > 0)):
            raise ConfigError(
                f"physics.inlet_radius={p.inlet_radius:g}, physics.viscosity={p.viscosity:g}, "
                f"physics.total_flow={p.total_flow:g}, physics.m_b={p.m_b:g} and physics.gamma={p.gamma:g} give "
                f"N={cfg.n_terminals} terminal segments a {what} outside the floating-point range (terminal radius "
                f"{float(r[0]):.3g} m): the model is not defined there"
            )


def _check_tissue_keys(tissue: TissueConfig) -> None:
    """A tissue key the chosen tissue does not read (``tissue.mass_g`` with ``tissue=sphere``)
    must keep its default: set, it would change nothing but the run's identity."""
    from ..model.tissue import TISSUES

    read_by = {name: set(inspect.signature(build).parameters) for name, build in TISSUES.items()}
    defaults = TissueConfig()
    for key in TissueConfig.__dataclass_fields__:
        if key in TISSUE_KEYS_OF_EVERY_TISSUE or key in read_by[tissue.name]:
            continue
        default = getattr(defaults, key)
        if getattr(tissue, key) != default:
            readers = " and ".join(f"tissue={name}" for name, keys in read_by.items() if key in keys)
            raise ConfigError(
                f"tissue.{key} is read by {readers} only; tissue={tissue.name} ignores it: leave it at its "
                f"default ({json.dumps(asdict(default) if is_dataclass(default) else default)})"
            )


def _validate_method(cfg: RunConfig) -> None:
    m = cfg.method
    if m.name not in METHODS:
        raise ConfigError(f"method.name: unknown method {m.name!r}; accepted: {', '.join(METHODS)} (method=cco)")
    if cfg.anneal.init not in ANNEAL_INITS:
        raise ConfigError(f"anneal.init must be one of {', '.join(ANNEAL_INITS)}, got {cfg.anneal.init!r}")
    for name in ("candidates", "max_tries"):
        if not isinstance(getattr(m, name), int) or getattr(m, name) < 1:
            raise ConfigError(f"method.{name} must be an integer >= 1, got {getattr(m, name)}")
    if not 0.0 < m.shrink < 1.0:
        raise ConfigError(f"method.shrink must lie in (0, 1), got {m.shrink}")
    if m.order not in ("file", "random"):
        raise ConfigError(f"method.order must be 'file' or 'random', got {m.order!r}")
    if not isinstance(m.avoid_cavities, bool):
        raise ConfigError(f"method.avoid_cavities must be true or false, got {m.avoid_cavities!r}")


def _validate_extend(e: ExtendConfig) -> None:
    n = e.n_terminals
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_TERMINALS:
        raise ConfigError(
            f"extend.n_terminals must be an integer in [1, {MAX_TERMINALS:.0e}] (fine terminals in all, at least "
            f"the run's N), got {n!r}"
        )
    if e.runs not in EXTEND_RUNS:
        raise ConfigError(f"extend.runs must be one of {', '.join(EXTEND_RUNS)}, got {e.runs!r}")
    b = e.batch_territories
    if isinstance(b, bool) or not isinstance(b, int) or not 1 <= b <= 10**7:
        raise ConfigError(f"extend.batch_territories must be an integer in [1, 1e7], got {b!r}")
    if e.seed is not None and not seed_ok(e.seed):
        raise ConfigError(f"extend.seed must be {SEED_ACCEPTED} or null (the run's own seed), got {e.seed!r}")
