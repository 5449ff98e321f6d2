"""The key table: one entry per config key, the one home of its unit, accepted range and meaning.

:data:`KEYS` drives :func:`~vasc_pipeline.config.validate` (each entry's ``check``), the key
list of ``python -m vasc_pipeline --help`` and the key tables of ``docs/configuration.md``
(:mod:`vasc_pipeline.config.keypage`; ``python -m vasc_pipeline.config.keypage --write
docs/configuration.md`` writes them, a test fails when the page and the table differ). Defaults
are the schema's (:mod:`vasc_pipeline.config.schema`, :mod:`vasc_pipeline.config.pipeline`): an
entry's ``default`` text only says where a group sets another value, ``{}`` standing for the
schema's.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import replace
from typing import Any

from .keyspec import EVERY, Key, OneOf, Range, format_value
from .rules import MAX_STEPS, MAX_TERMINALS, SWEPT_KEYS
from .schema import (
    ANNEAL_INITS,
    EXTEND_RUNS,
    EXTEND_ZERODS,
    GAMMA_RANGE,
    HEART_EXCLUSION_VOXEL_SIZE,
    INLET_ASSIGNMENTS,
    MAX_CALIBRATION_SAMPLES,
    MAX_CHECKPOINT_SECONDS,
    MAX_COARSE_EXCLUSION_FACTOR,
    METHODS,
    MODELS,
    ORGANS,
    STAGES,
)

__all__ = ["KEYS", "KEY_OF", "schema_defaults"]

POSITIVE = Range(0, lo_open=True)
NON_NEGATIVE = Range(0)
SHARE = Range(0, 1, lo_open=True, hi_open=True)  # a share strictly between none and all
PROBABILITY = Range(0, 1)
BOOLEAN = OneOf((True, False))


def _tissue_names() -> tuple:
    from ..model.tissue import TISSUES  # the model imports the config: looked up when checked

    return tuple(sorted(TISSUES))


def _mesh_units() -> tuple:
    from ..model.tissue.surfaces import MESH_UNITS

    return tuple(MESH_UNITS)


def _packing(cfg) -> bool:
    return cfg.anneal.packing_steps_per_terminal > 0


def _supply_schedule(cfg) -> bool:
    return cfg.anneal.supply_T_start is not None


def _plural(doc: str) -> str:
    """``integer in [2, 1e8]`` as ``integers in [2, 1e8]``, ``> 0`` as ``numbers > 0``."""
    return doc.replace("integer", "integers", 1) if doc.startswith("integer") else f"numbers {doc}"


KEYS: tuple[Key, ...] = (
    Key(
        "n_terminals",
        "1",
        "N, the number of terminals",
        default="{} (`tissue=plane2d`: 64)",
        accepted="{}",
        check=SWEPT_KEYS["n_terminals"],
    ),
    Key("seed", "–", "the run's random stream", accepted="{}", check=SWEPT_KEYS["seeds"]),
    Key(
        "output_dir",
        "path",
        "where runs, summary, figures and trees go ([Results](results.md))",
        default="{} (each sweep sets its own)",
        accepted="a non-empty path",
    ),
    Key(
        "stage",
        "–",
        ("run the sweep then reduce it, only reduce the runs already there, or grow the whole tree below them"),
        accepted="{} (`+stage=reduce`, `+stage=extend`)",
        check=OneOf(STAGES),
    ),
    Key(
        "model.name",
        "–",
        (
            "which model the physics and tissue keys spell: `model=paper` sets the paper's values, "
            "`model=physiological` those of [The two models](model.md#the-two-models) (for the anneal "
            "also the bifurcations' reach, `conf/model_method/`, and on the heart the split, "
            "`conf/model_tissue/`); every key a model sets stays overridable after it"
        ),
        default="`physiological` (the group `model=...` sets it; the schema's own: {})",
        accepted="{}",
        check=OneOf(MODELS, unknown="model", why=" (model=...)"),
    ),
    Key(
        "tissue.name",
        "–",
        "the tissue",
        accepted="{} (the group `tissue=...` sets it)",
        check=OneOf(_tissue_names, unknown="tissue"),
        tissues=EVERY,
    ),
    Key(
        "tissue.voxel_size",
        "m",
        (
            "edge of the supply grid's voxel (and of the exclusion grid's unless "
            "`tissue.exclusion_voxel_size` is set). A grid that would not fit in memory is refused with "
            "its estimate"
        ),
        default="{}: R_supply / 4",
        accepted=(
            "{}; ≤ R_supply; `mask`: from a label map's header or a Zarr array's `voxel_size` "
            "attribute, else required, and at an organ's scale: voxels of 1 µm to 10 mm, the tissue 0.1 "
            "mm to 2 m across (outside, the unit is almost surely wrong: the error names the key or the "
            "file's header)"
        ),
        check=Range(0, lo_open=True, null=True),
        tissues=EVERY,
    ),
    Key(
        "tissue.exclusion_voxel_size",
        "m",
        (
            "the grid on which the exclusion term C_o is summed, fixed in metres and independent of N; "
            "the supply map keeps R_supply / 4. With `anneal.coarse_exclusion_*` the coarse phase "
            "coarsens this grid. `null` on the heart: the model before this key. Why: [The exclusion "
            "term's grid](model.md#the-exclusion-terms-grid)"
        ),
        default=(
            f"`heart` (its group): {format_value(HEART_EXCLUSION_VOXEL_SIZE)} (the N = 500 supply voxel); "
            "otherwise {}: the supply grid's voxel"
        ),
        accepted="{}",
        check=Range(0, lo_open=True, null=True),
        tissues=EVERY,
    ),
    Key(
        "tissue.q_required",
        "s⁻¹",
        "required flow per tissue volume; sets R_supply (the paper: 2e-2)",
        default="{}: the N supply spheres fill the tissue (Q0 / V_tissue)",
        accepted="{}",
        check=Range(0, lo_open=True, null=True),
        tissues=EVERY,
    ),
    Key(
        "tissue.inlet_share",
        "1",
        "fixes how many terminals each inlet feeds ([Several inlets](model.md#several-inlets))",
        default=("heart, anneal: `[0.62,0.38]` (`model=physiological`); else {}: free, the anneal finds the split"),
        accepted=(
            "one fraction > 0 per inlet, summing to 1 (heart: [LCA, RCA], e.g. `[0.62,0.38]`); not with "
            "`method=cco` or `anneal.init=cco`"
        ),
        tissues=EVERY,
    ),
    Key(
        "tissue.inlet_share_tolerance",
        "1",
        (
            "each inlet's share may stray this far from `tissue.inlet_share`, the inlet trees trading "
            "subtrees freely inside the band ([Several inlets](model.md#several-inlets))"
        ),
        default="heart, anneal: 0.15 (`model=physiological`); else {}: the share is kept exactly",
        accepted="{}; needs `tissue.inlet_share`",
        check=Range(0, 1, lo_open=True, hi_open=True, null=True, why=" (a share's +-)"),
        tissues=EVERY,
    ),
    Key(
        "tissue.inlet_assignment",
        "–",
        "which terminals of the initial tree each inlet feeds",
        default="heart, anneal: `nearest` (`model=physiological`); else {}",
        accepted="{}",
        check=OneOf(INLET_ASSIGNMENTS),
        tissues=EVERY,
    ),
    Key(
        "tissue.bifurcation_reach",
        "m",
        (
            "how far outside the exclusion domain a bifurcation may lie ([Where bifurcations may "
            "lie](model.md#where-bifurcations-may-lie))"
        ),
        default="anneal: 0 (`model=physiological`); `model=paper`: {}, anywhere in the grid's box",
        accepted="{} (0: on or in the exclusion domain); not with `method=cco`",
        check=Range(0, null=True, says="be a length >= 0 in metres, or null"),
        tissues=EVERY,
    ),
    Key(
        "tissue.organ",
        "–",
        (
            "what organ the tissue is: the reduction compares a heart's trees with Kassab's pig "
            "coronary arteries (table, CSVs, `/comparison`, figure panels) and leaves that comparison "
            "out for `other`, keeping the rest "
            "([Results](results.md#only-a-heart-is-compared-with-the-pig-heart-tissueorgan)). The tree "
            "does not depend on it; null is the behaviour before this key"
        ),
        default=(
            "{}: `heart` for `tissue=heart`, `sphere`, `box`, `plane2d` and a mask or surface with two "
            "or more inlets; `other` for a mask or surface with one inlet"
        ),
        accepted="{}",
        check=OneOf(ORGANS, null=True, why=" (decided by the tissue)"),
        tissues=EVERY,
    ),
    Key("tissue.mass_g", "g", "myocardial mass the heart is scaled to", accepted="> 0", tissues=("heart",)),
    Key("tissue.density", "kg m⁻³", "myocardial density", default="{}", accepted="> 0", tissues=("heart",)),
    Key(
        "tissue.exclude_cavities",
        "–",
        (
            "the ventricular cavities are part of the exclusion domain (false: the myocardium only, the "
            "model before 2026-11)"
        ),
        accepted="true, false",
        tissues=("heart",),
    ),
    Key(
        "tissue.ostium_height",
        "m",
        "height of both ostia above the base plane, on the aortic root's wall",
        default="{}: 5.8 mm at 218 g (the reference heart's 5 mm, scaled)",
        accepted="[0, 0.05], or null",
        tissues=("heart",),
    ),
    Key(
        "tissue.base_cut",
        "LV half-lengths",
        "the base plane's height above the LV's equator",
        default="{}: 1/3",
        accepted="[0, 0.7], or null",
        tissues=("heart",),
    ),
    Key(
        "tissue.elongation",
        "1",
        "factor on the ventricles' long-axis dimensions (before scaling to `mass_g`)",
        default="{}: 1",
        accepted="[0.5, 2], or null",
        tissues=("heart",),
    ),
    Key("tissue.radius", "m", "the ball's radius", accepted="> 0", tissues=("sphere",)),
    Key("tissue.size", "m", "the block's edges [x, y, z]", accepted="three lengths > 0", tissues=("box",)),
    Key("tissue.side", "m", "the square's side", accepted="> 0", tissues=("plane2d",)),
    Key(
        "tissue.path",
        "path",
        (
            "mask: the voxel mask, (z, y, x), non-zero = tissue (or by `tissue.labels`). A label map's "
            "spacing, origin and orientation come from its header (world frame RAS; an NRRD in LPS is "
            "turned into RAS; flipped or permuted axes are reoriented; anisotropic voxels and oblique "
            "grids are refused: resample first). surface: the organ's outer surface; refused when it is "
            "missing, of another format, unreadable, holds no triangle, is not closed (an edge of one "
            "triangle only, or of three or more), spans under 0.1 mm or over 2 m (the unit: "
            "`tissue.mesh_unit`) or holds no voxel centre"
        ),
        default="{} (`tissue=mask`, `tissue=surface`: required)",
        accepted=(
            "mask: a `.npy` file, a Zarr array/group, or a NIfTI (`.nii`, `.nii.gz`) or NRRD (`.nrrd`, "
            "`.nhdr`) label map (`pip install 'vasc_pipeline[images]'`); surface: a closed triangle "
            "surface, STL (`.stl`), Wavefront OBJ (`.obj`), PLY (`.ply`) or VTK XML PolyData (`.vtp`) "
            "(`pip install 'vasc_pipeline[mesh]'`)"
        ),
        tissues=("mask", "surface"),
    ),
    Key("tissue.array", "–", "the mask's array inside a Zarr group", accepted="an array name", tissues=("mask",)),
    Key(
        "tissue.origin",
        "m",
        "[x, y, z] of voxel [0, 0, 0]'s centre. The run's config records the value taken",
        default="{}: a label map's header, a Zarr array's `origin` attribute, else [0, 0, 0]",
        accepted="three finite numbers; for a label map, its header's or null",
        tissues=("mask",),
    ),
    Key(
        "tissue.inlets",
        "m",
        (
            "inlet positions (ostia), replacing the tissue's own on its own grid ([Own "
            "ostia](getting-started.md#own-ostia-tissueinlets)); unset, the run is the one before this "
            "option, bit for bit and with the same identity"
        ),
        default=(
            "{}: the tissue's own (heart: LCA and RCA ostia; sphere, box, plane2d: one; `tissue=mask` "
            "and `tissue=surface`: required, this or `tissue.inlets_path`)"
        ),
        accepted=(
            "a non-empty list of [x, y, z], each inside the grid's box (plane2d: in its plane, z = 0) "
            "and not inside a cavity (a voxel of the exclusion domain that is no tissue: the heart's "
            "ventricles, `tissue.labels.exclusion`, `tissue.exclusion_path`; one that opens onto the "
            "space outside is the cavity's opening and accepted: an ostium lies in the tissue or next "
            "to it); heart: not with `tissue.ostium_height`"
        ),
        tissues=EVERY,
    ),
    Key(
        "tissue.inlets_path",
        "path",
        "the inlets (ostia) from a file, with their names; not with `tissue.inlets`",
        accepted=(
            'a JSON object `{"name": [x, y, z], ...}` (or a list of [x, y, z]) or a CSV with columns '
            "`x, y, z` (m) and optionally `name`; as `tissue.inlets`"
        ),
        tissues=EVERY,
    ),
    Key(
        "tissue.labels.supply",
        "–",
        "the label values of the tissue that needs supply (myocardium)",
        default="{}: every non-zero label not named below",
        accepted=(
            "a non-empty list of integers ≥ 0, each held by some voxel of the map (in every role: a "
            "label absent from the map is refused, naming the labels it holds)"
        ),
        tissues=("mask",),
    ),
    Key(
        "tissue.labels.exclusion",
        "–",
        (
            "label values large vessels must not cross although they need no supply (cavities); not "
            "with `tissue.exclusion_path`"
        ),
        accepted="as above, no label in two roles",
        tissues=("mask",),
    ),
    Key(
        "tissue.labels.open",
        "–",
        (
            "label values outside the tissue that the exclusion map looks through (the space above a "
            "heart's base cut; what `python -m vasc_pipeline.model.tissue` writes as label 3)"
        ),
        accepted="as above",
        tissues=("mask",),
    ),
    Key(
        "tissue.exclusion_path",
        "path",
        "a second mask large vessels must not cross although it needs no supply (cavities, bone)",
        accepted="as `tissue.path`, on the same grid",
        tissues=("mask",),
    ),
    Key("tissue.exclusion_array", "–", "its array inside a Zarr group", accepted="an array name", tissues=("mask",)),
    Key(
        "tissue.cavity_paths",
        "paths",
        (
            "surfaces of cavities (a heart's blood pools): their voxels are excluded from large vessels "
            "and need no supply. Supply domain: voxel centres inside `tissue.path`'s surface and inside "
            "no cavity; exclusion domain: inside the organ's surface"
        ),
        default="{}: no cavity",
        accepted=(
            "a non-empty list of closed surfaces, in the formats of `tissue.path` (surface), each "
            "inside the organ's surface (a cavity voxel outside it is refused, with the count)"
        ),
        tissues=("surface",),
    ),
    Key(
        "tissue.mesh_unit",
        "–",
        ("the unit of the surface files' coordinates (STL, OBJ and PLY carry none; segmentation tools write mm)"),
        accepted="{}",
        check=OneOf(_mesh_units),
        tissues=("surface",),
    ),
    Key(
        "tissue.demand_path",
        "path",
        (
            "a map of relative perfusion demand. Sampled at the supply grid's voxel centres, nearest "
            "voxel (no interpolation), and quantised to coverage targets t = round(d / min d), halves "
            "up, capped at 4 ([Supply](model.md#the-costs)); R_supply then fills the demand-weighted "
            "volume. A uniform map is no map. The run store keeps the targets as `tissue/supply_target`"
        ),
        default="{}: every tissue voxel needs one supply sphere",
        accepted=(
            "a `.npy` file, a Zarr array (a path inside a group names its array), or a NIfTI or NRRD "
            "image, of numbers > 0 at every tissue voxel (outside the tissue anything). With a geometry "
            "(the image's header, or a Zarr array's `voxel_size` and `origin` attributes, m) it must "
            "cover the tissue's voxel centres; without one it must have the supply grid's shape"
        ),
        tissues=EVERY,
    ),
    Key(
        "physics.gamma",
        "1",
        (
            "bifurcation exponent γ: r = r_t n^(1/γ) (measured trees: 2–3; far outside, the radii span "
            "hundreds of decades and the flow solve is singular)"
        ),
        default="7/3 (`model=physiological`); {} (`model=paper`); `plane2d`: 3.0",
        accepted="{}",
        check=Range(
            *GAMMA_RANGE,
            why=" (the bifurcation exponent of r_parent^gamma = sum r_child^gamma: Murray's 3, the paper's 2.1)",
        ),
    ),
    Key(
        "physics.inlet_radius",
        "m",
        "combined inlet radius r_in: Σ_k r_k^γ = r_in^γ",
        default="{} (`plane2d`: 2.4e-3)",
        accepted="{}",
        check=POSITIVE,
    ),
    Key("physics.total_flow", "m³ s⁻¹", "total inflow Q0", accepted="{}", check=POSITIVE),
    Key(
        "physics.m_b", "W m⁻³", "metabolic cost of blood volume (a sweep axis)", accepted="{}", check=SWEPT_KEYS["m_b"]
    ),
    Key("physics.viscosity", "Pa s", "blood viscosity μ", accepted="{}", check=POSITIVE),
    Key(
        "physics.r_cutoff",
        "m",
        "only segments with r > r_cutoff pay the exclusion term",
        default="2e-4 (`model=physiological`); {} (`model=paper`, the paper's 0.01 mm)",
        accepted="{}",
        check=NON_NEGATIVE,
    ),
    Key("physics.A_wv", "1", "weight of C_w + C_v; the total is divided by it", accepted="{}", check=POSITIVE),
    Key(
        "physics.A_o",
        "1",
        "weight of the exclusion term",
        default="{} (`plane2d`: 0)",
        accepted="{}",
        check=NON_NEGATIVE,
    ),
    Key("physics.A_p", "1", "weight of the pressure term", default="{} (off)", accepted="{}", check=NON_NEGATIVE),
    Key("physics.A_s", "1", "weight of the supply term", accepted="{}", check=NON_NEGATIVE),
    Key(
        "physics.pressure_inlet",
        "Pa",
        "inlet pressure, for C_p",
        default="{} (100 mmHg)",
        accepted="> `pressure_terminal`",
    ),
    Key(
        "physics.pressure_terminal",
        "Pa",
        "target terminal pressure P_term, for C_p",
        default="{}",
        accepted="{}",
        check=NON_NEGATIVE,
    ),
    Key("anneal.name", "–", "the preset's name", accepted="any label"),
    Key(
        "anneal.T_start",
        "W",
        (
            "start temperature; null: calibrated so that uphill moves of a random walk from the initial "
            "tree are accepted with mean probability `accept_start`"
        ),
        accepted="{}; > the end temperature",
        check=Range(0, lo_open=True, null=True),
    ),
    Key(
        "anneal.T_end",
        "W",
        ("end temperature; null: `T_end_rel` times the cost of one terminal segment of length R_supply"),
        accepted="{}; < `T_start`",
        check=Range(0, lo_open=True, null=True),
    ),
    Key("anneal.accept_start", "1", "mean uphill acceptance at a calibrated T_start", accepted="{}", check=SHARE),
    Key(
        "anneal.T_end_rel",
        "1",
        "calibrated T_end relative to one terminal segment's cost",
        accepted="{}",
        check=POSITIVE,
    ),
    Key(
        "anneal.calibration_samples",
        "moves",
        "infinite-temperature moves measured for T_start (on a copy: the run's stream is untouched)",
        accepted="{}",
        check=Range(1, MAX_CALIBRATION_SAMPLES, integer=True),
    ),
    Key(
        "anneal.steps",
        "moves",
        "proposed moves of the run, exact; null: `steps_at_1000` (N/1000)^`steps_exponent`",
        accepted="{}, or null",
        check=replace(SWEPT_KEYS["steps"], null=True),
    ),
    Key(
        "anneal.steps_at_1000",
        "moves",
        "the budget at N = 1000",
        accepted=f"{{}}; the scheduled total ≤ {MAX_STEPS:.0e}".replace("e+", "e"),
        check=POSITIVE,
    ),
    Key("anneal.steps_exponent", "1", "the budget law's exponent in N", accepted="{}", check=Range(0, 4)),
    Key(
        "anneal.packing_steps_per_terminal",
        "moves",
        "packing phase: the first k·N proposals move terminals only, on ΔC_s alone; 0: off",
        accepted="{}; its moves < the run's; not with `terminals.fixed`",
        check=NON_NEGATIVE,
    ),
    Key(
        "anneal.packing_T_start",
        "voxels of one supply sphere",
        "the packing phase's start temperature",
        accepted="{} (with packing)",
        check=POSITIVE,
        applies=_packing,
    ),
    Key(
        "anneal.packing_T_end",
        "C_s units",
        "its end temperature",
        accepted="{} (with packing)",
        check=POSITIVE,
        applies=_packing,
    ),
    Key("anneal.p_swap", "1", "share of the proposals that are swaps", accepted="{}", check=PROBABILITY),
    Key(
        "anneal.p_local",
        "1",
        "share of the swaps whose partner comes from the neighbouring cells",
        accepted="{}",
        check=PROBABILITY,
    ),
    Key(
        "anneal.neighbour_cell",
        "R_supply",
        "edge of those cells (partners from the cell and the 26 around it; 2-D: 8)",
        accepted="{}",
        check=POSITIVE,
    ),
    Key(
        "anneal.step_terminal",
        "R_supply",
        "terminal translation half-width (the cap when adapted)",
        accepted="{}",
        check=POSITIVE,
    ),
    Key(
        "anneal.step_bifurcation",
        "R_supply",
        "bifurcation translation half-width (the cap when adapted)",
        accepted="{}",
        check=POSITIVE,
    ),
    Key(
        "anneal.supply_T_start",
        "voxels of one supply sphere",
        ("supply's own temperature at the start; null: supply searched downhill throughout (the paper)"),
        accepted="{}",
        check=Range(0, lo_open=True, null=True),
    ),
    Key(
        "anneal.supply_T_end",
        "C_s units",
        "its temperature at the end of its phase (0.05: +1 accepted at e^-20)",
        accepted="{} and < `supply_T_start` (with a supply schedule)",
        check=POSITIVE,
        applies=_supply_schedule,
    ),
    Key(
        "anneal.supply_phase",
        "share of the moves",
        "how long the supply schedule runs; then the true weight A_s/A_wv",
        accepted="{}",
        check=Range(0, 1, lo_open=True),
    ),
    Key("anneal.adapt_steps", "–", "adapt the translation half-widths to `acceptance_target`", accepted="true, false"),
    Key(
        "anneal.acceptance_target",
        "1",
        "the adapted steps' target acceptance, per node class",
        accepted="{}",
        check=SHARE,
    ),
    Key(
        "anneal.adapt_window",
        "proposals",
        "proposals of a class between adaptations",
        accepted="{}",
        check=Range(1, MAX_CALIBRATION_SAMPLES, integer=True),
    ),
    Key(
        "anneal.full_width_phase",
        "share of the moves",
        "with adapted steps: how long half of the terminal moves keep the full width",
        accepted="{}",
        check=Range(0, 1, lo_open=True),
    ),
    Key(
        "anneal.cold_from",
        "share of the path",
        "where the schedule's cold part starts; null: one exponential",
        accepted="{}; set with `cold_share`",
        check=replace(SHARE, null=True),
    ),
    Key(
        "anneal.cold_share",
        "share of the tree anneal's moves",
        "the moves spent in the cold part",
        accepted="{}; set with `cold_from`",
        check=replace(SHARE, null=True),
    ),
    Key(
        "anneal.coarse_exclusion_factor",
        "voxels per coarse voxel edge",
        ("the exclusion term on a depth map this many times coarser early in the run; null: the true map throughout"),
        accepted="{}; set with `coarse_exclusion_phase`",
        check=Range(2, MAX_COARSE_EXCLUSION_FACTOR, integer=True, null=True, why=" (voxels per coarse voxel edge)"),
    ),
    Key(
        "anneal.coarse_exclusion_phase",
        "share of the tree anneal's moves",
        "how long the coarse map serves",
        accepted="{}; set with the factor",
        check=replace(SHARE, null=True),
    ),
    Key(
        "anneal.polish",
        "–",
        "bifurcations moved to the final topology's optimum where the total cost does not rise",
        accepted="true, false",
    ),
    Key(
        "anneal.polish_swaps_max_terminals",
        "terminals",
        "with polish, up to this N: a single-swap descent with optimal geometry",
        accepted="{}",
        check=Range(0, integer=True),
    ),
    Key(
        "anneal.trace_every",
        "proposals",
        "proposals between trace records",
        default="{} (`+sweep=smoke`: 50 000)",
        accepted="{}",
        check=Range(1, MAX_STEPS, integer=True),
    ),
    Key(
        "anneal.init",
        "–",
        "the initial tree: random, or the CCO tree grown from the run's generator",
        accepted="{}",
        check=OneOf(ANNEAL_INITS),
    ),
    Key(
        "anneal.parts",
        "1",
        (
            "K: the tree anneal in K parts annealed side by side ([One tree in "
            "parts](model.md#one-tree-in-parts-annealparts)); 1: the serial anneal"
        ),
        accepted="integer in [1, N/16]; > 1 needs `physics.A_p = 0` and `method=anneal`",
    ),
    Key(
        "anneal.part_phases",
        "1",
        "with parts > 1: the phases, each with two new cuts (subtrees, then terminals by place)",
        accepted="{}",
        check=Range(1, 100_000, integer=True),
    ),
    Key(
        "anneal.part_share",
        "1",
        (
            "with parts > 1: the share of a phase's proposals run in the parts; the rest on the whole "
            "tree (on 2 workers, 0.99 with a quarter more moves, `anneal.steps_at_1000` × 1.25, reached "
            "the serial costs at N = 6000 in 0.57 of its wall time)"
        ),
        accepted="{}",
        check=SHARE,
    ),
    Key(
        "terminals.path",
        "path",
        "terminal sites",
        default="{}: sites drawn uniformly in the tissue",
        accepted="a CSV of `x,y,z` in metres",
    ),
    Key(
        "terminals.fixed",
        "–",
        "the sites never move (the supply term is then off)",
        accepted="true needs `terminals.path`; not with a packing phase",
    ),
    Key(
        "method.name",
        "–",
        "how the tree is grown",
        accepted="{}",
        check=OneOf(METHODS, unknown="method", why=" (method=cco)"),
    ),
    Key(
        "method.candidates",
        "segments",
        "cco: nearest segments evaluated for each new terminal",
        accepted="{}",
        check=Range(1, integer=True),
    ),
    Key(
        "method.max_tries",
        "sites",
        "cco: consecutive rejected sites before the distance criterion shrinks",
        accepted="{}",
        check=Range(1, integer=True),
    ),
    Key("method.shrink", "1", "cco: the factor of that shrink", accepted="{}", check=SHARE),
    Key(
        "method.order",
        "–",
        "cco with `terminals.path`: sites in file order or in a seeded random order",
        accepted="{}",
        check=OneOf(("file", "random")),
    ),
    Key(
        "method.avoid_cavities",
        "–",
        (
            "cco: no new segment crosses a voxel of the tissue's cavities (the exclusion domain outside "
            "the tissue): the cheapest connection that crosses none is made, a site with none is drawn "
            "again. False: the earlier growth, bit for bit. The whole tree's territories always grow "
            "with it ([The whole tree](model.md#the-whole-tree-extension-below-the-annealed-terminals))"
        ),
        accepted="{}",
        check=BOOLEAN,
    ),
    Key(
        "extend.n_terminals",
        "1",
        ("fine terminals in all, rounded to the nearest multiple of the run's N (m = round(n / N) in every territory)"),
        accepted="{}, and at least N/2 of each run extended",
        check=Range(1, MAX_TERMINALS, integer=True, why=" (fine terminals in all, at least the run's N)"),
    ),
    Key(
        "extend.runs",
        "–",
        "the lowest-cost seed of each cell, or every complete run",
        accepted="{}",
        check=OneOf(EXTEND_RUNS),
    ),
    Key(
        "extend.batch_territories",
        "territories",
        "territories per Dask task and per commit (the result does not depend on it)",
        accepted="{}",
        check=Range(1, 10**7, integer=True),
    ),
    Key(
        "extend.seed",
        "–",
        "the territories' random streams",
        default="{}: the run's own seed",
        accepted="{}, or null",
        check=replace(SWEPT_KEYS["seeds"], null=True),
    ),
    Key(
        "extend.zerod",
        "–",
        (
            "the reduction's 0D network of the whole tree (`trees/<run_id>.extended.0d.json`): every "
            "territory's subtree one lumped resistance, or every vessel "
            "([Results](results.md#the-whole-tree-reduced)); not part of the extended store's identity "
            "either"
        ),
        accepted="{}",
        check=OneOf(
            EXTEND_ZERODS,
            why=" (the whole tree's 0D network: each territory's subtree one lumped resistance, or every vessel)",
        ),
    ),
    Key(
        "checkpoint.every_seconds",
        "s",
        "time between a job's checkpoints",
        default="{} (`+sweep=smoke`: 5)",
        accepted="{} (a week)",
        check=Range(0, MAX_CHECKPOINT_SECONDS, lo_open=True, why=" (s; at most a week)"),
    ),
    Key("sweep.name", "–", "the sweep's name", accepted="a label"),
    Key(
        "sweep.n_terminals",
        "1",
        "the N axis",
        default="{}: [`n_terminals`]",
        accepted="list of " + _plural(SWEPT_KEYS["n_terminals"].doc),
    ),
    Key(
        "sweep.m_b",
        "W m⁻³",
        "the m_b axis",
        default="{}: [`physics.m_b`]",
        accepted="list of " + _plural(SWEPT_KEYS["m_b"].doc),
    ),
    Key(
        "sweep.seeds", "–", "the seeds", default="{}: [`seed`]", accepted="list of " + _plural(SWEPT_KEYS["seeds"].doc)
    ),
    Key(
        "sweep.steps",
        "moves",
        "a steps axis (run ids then carry `-S<steps>`)",
        default="{}: `anneal.steps` (or the schedule's budget)",
        accepted="list of " + _plural(SWEPT_KEYS["steps"].doc),
    ),
    Key("cluster.name", "–", "where the jobs run", accepted="`local`, `address`, `slurm`"),
    Key(
        "cluster.n_workers",
        "workers",
        "workers to start or request; not used with `address`",
        default="{}: local one per core, slurm one per unfinished run (never more than the unfinished runs)",
        accepted="integer ≥ 1, or null",
    ),
    Key(
        "cluster.address",
        "URL",
        "an existing scheduler",
        default="{} (`cluster=address`: required)",
        accepted="`tcp://host:port` or `tls://host:port`",
    ),
    Key(
        "cluster.dashboard_address",
        "host:port",
        "the Dask dashboard (needs bokeh; without it no port is asked for)",
        default="{} (`address`: null)",
        accepted="host:port, or null (no dashboard)",
    ),
    Key(
        "cluster.retries",
        "1",
        "resubmissions of a job whose worker died or whose machine failed it",
        accepted="integer ≥ 0",
    ),
    Key(
        "cluster.startup_timeout",
        "s",
        "wait for the first worker, then for the first job to begin",
        default="{}",
        accepted="finite > 0",
    ),
    Key(
        "cluster.allow_insecure",
        "–",
        "slurm without `cluster.tls.*` files: plain tcp instead of temporary TLS certificates",
        accepted="true, false",
    ),
    Key(
        "cluster.dry_run",
        "–",
        "print the planned runs (and the SLURM job script); run and write nothing",
        accepted="true, false",
    ),
    Key("cluster.tls.ca_file", "path", "certificate authority", accepted="a PEM file"),
    Key("cluster.tls.cert", "path", "certificate for client, scheduler and workers", accepted="a PEM file"),
    Key("cluster.tls.key", "path", "private key", default="{}: inside `cert`", accepted="a PEM file"),
    Key("cluster.tls.require_encryption", "–", "refuse unencrypted connections", accepted="true, false"),
    Key("cluster.slurm.queue", "–", "`-p`", accepted="a partition"),
    Key("cluster.slurm.account", "–", "`-A`", accepted="an account"),
    Key(
        "cluster.slurm.walltime",
        "time",
        "per SLURM job; workers retire before it",
        accepted=("sbatch's `--time` formats (`04:00:00`, `1-12:00:00`, ...), at least 10 minutes; `UNLIMITED`"),
    ),
    Key(
        "cluster.slurm.cores",
        "workers",
        "single-threaded worker processes per SLURM job (1: ended jobs are reliably replaced)",
        accepted="integer ≥ 1",
    ),
    Key("cluster.slurm.memory", "bytes", "per SLURM job", accepted="an amount such as `4GB` or `500MB`"),
    Key(
        "cluster.slurm.interface",
        "–",
        "the workers' and scheduler's interface",
        accepted="one of this machine's network interfaces, e.g. `ib0`",
    ),
    Key("cluster.slurm.local_directory", "path", "node-local scratch for Dask", accepted="a directory"),
    Key(
        "cluster.slurm.log_directory",
        "path",
        "where SLURM writes the worker jobs' logs",
        default="{}: `<output_dir>/.slurm_logs`",
        accepted="a directory",
    ),
    Key(
        "cluster.slurm.job_extra_directives",
        "–",
        'extra `#SBATCH` lines, e.g. `["--qos=normal"]`',
        accepted="list of strings",
    ),
    Key(
        "cluster.slurm.job_script_prologue",
        "–",
        'e.g. `["module load python", "source ~/venv/bin/activate"]`',
        accepted="list of strings",
    ),
)
KEY_OF = {key.name: key for key in KEYS}


def schema_defaults(cls: type | None = None, prefix: str = "") -> dict[str, Any]:
    """Every key of the schema's dataclasses (``RunConfig`` and its sections, ``sweep`` too,
    which is optional), dotted, with its default."""
    from .schema import RunConfig

    cls = cls or RunConfig
    hints = typing.get_type_hints(cls)
    instance, out = cls(), {}
    for field in dataclasses.fields(cls):
        kinds = [t for t in (typing.get_args(hints[field.name]) or (hints[field.name],)) if t is not type(None)]
        if len(kinds) == 1 and dataclasses.is_dataclass(kinds[0]):
            out.update(schema_defaults(kinds[0], f"{prefix}{field.name}."))
        else:
            out[f"{prefix}{field.name}"] = getattr(instance, field.name)
    return out
