"""The key table's ``tissue.*`` entries (:mod:`vasc_pipeline.config.keys`)."""

from __future__ import annotations

from .keyspec import (
    BOOLEAN,
    EVERY,
    Key,
    OneOf,
    Range,
    format_value,
    mesh_units,
    tissue_names,
)
from .schema import (
    HEART_EXCLUSION_VOXEL_SIZE,
    INLET_ASSIGNMENTS,
    ORGANS,
)

__all__ = ["TISSUE_KEYS"]

TISSUE_KEYS: tuple[Key, ...] = (
    Key(
        "tissue.name",
        "–",
        "the tissue",
        accepted="{} (the group `tissue=...` sets it)",
        check=OneOf(tissue_names, unknown="tissue"),
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
        "tissue.bifurcations_in_cavities",
        "–",
        (
            "false: no bifurcation inside a cavity (the exclusion domain outside the tissue: a "
            "ventricle's blood pool) ([Where bifurcations may lie](model.md#where-bifurcations-may-lie))"
        ),
        accepted="{}; not with `method=cco`",
        check=BOOLEAN,
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
        check=OneOf(mesh_units),
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
)
