"""The configuration's schema: the run's dataclasses, their defaults and types.

The dataclasses below, with the sweep and cluster groups of
:mod:`vasc_pipeline.config.pipeline`, are the single source of defaults and types (Hydra
registers them as structured configs, so a wrong type or unknown key fails at once).
:func:`~vasc_pipeline.config.checks.validate` checks ranges and names the offending field before
any job starts; :func:`~vasc_pipeline.config.compose.compose` builds a resolved config from
Hydra-style overrides.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from .errors import ConfigError
from .frozen import Settings
from .pipeline import ClusterConfig, SlurmConfig, SweepConfig, TLSConfig
from .rules import SWEPT_KEYS, Rule, sweep_axis

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
    "Rule",
    "SWEPT_KEYS",
    "sweep_axis",
    "HEART_EXCLUSION_VOXEL_SIZE",
    "ORGANS",
    "organ_of",
    "CONFIG_DIR",
]

# An installed wheel carries conf/ inside the package; a source checkout has it at the top.
_PACKAGE_DIR = Path(__file__).resolve().parents[1]  # vasc_pipeline/
CONFIG_DIR = _PACKAGE_DIR / "conf" if (_PACKAGE_DIR / "conf").is_dir() else _PACKAGE_DIR.parent / "conf"
STAGES = ("run", "reduce", "extend")  # run: sweep then reduction; reduce: reduction of existing runs only;
# extend: the whole tree below existing runs (vasc_pipeline.pipeline.extend)
EXTEND_RUNS = ("best", "all")  # extend.runs: the lowest-cost seed of each cell, or every complete run
# extend.zerod: the whole tree's 0D network, each territory's subtree one lumped resistance or every vessel
EXTEND_ZERODS = ("lumped", "full")
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
    "tissue.bifurcations_in_cavities": True,
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
    "physics.viscosity_law": "constant",
    "physics.r_cutoff_ramp": 0.0,
    "anneal.steps_exponent": 2.0,
    "anneal.packing_steps_per_terminal": 0.0,
    "anneal.packing_T_start": 1.0,
    "anneal.T_start_min": None,
    "anneal.polish_regrafts": False,
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
    "bifurcations_in_cavities",
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
    # False: no bifurcation inside a cavity of the exclusion domain (a ventricle's blood pool);
    # True: anywhere the reach allows (the paper).
    bifurcations_in_cavities: bool = True
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
    viscosity: float = 3.6e-3  # Pa s, in large vessels
    viscosity_law: str = "constant"  # how it varies with the diameter (model.physics.VISCOSITY_LAWS)
    r_cutoff: float = 1e-5  # m
    r_cutoff_ramp: float = 0.0  # m; the exclusion weight rises from 0 at r_cutoff to 1 at r_cutoff + ramp
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
    T_start_min: Optional[float] = None  # W; a calibrated T_start is raised to it (None: not raised)
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
    polish_regrafts: bool = False  # with polish, prune-and-regraft descent (engine.polish.descend_regrafts)
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
    zerod: str = "lumped"  # the reduction's 0D network of the whole tree: "lumped" territories or "full"


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
