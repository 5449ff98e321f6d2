"""The paper's coronary substrate: a two-ventricle heart of 218 g, tissue ``heart``.

Keelan, Chung & Hague model the myocardium as "an ellipsoidal human heart muscle of mass
218 g": the left ventricle (LV) a thick-walled ellipsoid, the right ventricle (RV) a
super-ellipsoid of exponent 2.5, truncated at the base so that the mass is physiological.
They do not give the dimensions; this module fixes them as follows.

Coordinates (metres): the long axis of the LV is the z axis, the apex points to -z and the
base is the plane z = 0 (no tissue above it). x points from the LV towards the RV (the
heart's right), y is antero-posterior (-y anterior). The heart is mirror-symmetric in y
except for the aortic root, which sits slightly anterior.

Reference dimensions before scaling (adult human / large pig heart, in cm):

=================================  ==========================================
LV outer ellipsoid                 semi-axes 3.0 (x, y) and 6.0 (z), centre at z = -2.0
LV cavity (inner ellipsoid)        semi-axes 2.0 (x, y) and 5.2 (z), same centre
  => LV long axis (base to apex)   8.0; base truncated 2.0 above the equator
  => LV wall                       1.0 at the equator (septum too), 0.8 at the apex
RV outer super-ellipsoid, p = 2.5  |dx/2.8|^p + |y/3.3|^p + |dz/4.5|^p <= 1,
                                   centre offset 2.0 to +x from the LV axis, z = -2.0
RV cavity                          the same with semi-axes 2.4, 2.9, 4.1
  => RV free wall                  0.4 thick; RV reaches 6.5 below the base (LV: 8.0)
aortic root (centre of the valve)  x = 1.6, y = -0.4 (over the LV outflow, beside the
                                   septum), radius 1.3
coronary ostia                     0.5 above the base plane on the root's wall:
                                   LCA at x = 1.6 - 1.3 (left), RCA at x = 1.6 + 1.3 (right);
                                   ``ostium_height`` [m, unscaled] replaces the 0.5
=================================  ==========================================

Two options reshape this reference before it is scaled to the mass (both unset by default):
``elongation`` multiplies every long-axis (z) dimension of both ventricles (half-lengths,
centres, the RV's z semi-axes; walls and radii in x and y keep theirs), and ``base_cut``
places the base plane at that fraction of the LV's outer half-length above the LV's
equator (reference 2.0 / 6.0 = 1/3; 0 cuts at the equator, 0.7 leaves a nearly closed
ellipsoid). The aortic root and the ostia keep their place relative to the base plane.

The RV free wall is the set inside the RV's outer super-ellipsoid, outside its cavity and
outside the LV's outer ellipsoid (so the interventricular septum is LV wall); the RV cavity
is the set inside the RV's inner super-ellipsoid and outside the LV's outer ellipsoid. With
these numbers the LV wall holds 100.1 cm^3 and the RV free wall 30.3 cm^3 (cavities 67
and 48 ml). Every length (ostia included) is then multiplied by one factor
s = (V_target / V_reference)^(1/3), V_target = mass / density (2.0566e-4 m^3 for 218 g at
1.06e3 kg m^-3), V_reference the volume of the unscaled myocardium, integrated once on a
fine (x, z) grid with the y extent of every column computed analytically (relative error
~1e-5) and cached. For 218 g at 1.06e3 kg m^-3, V_reference = 130.38 cm^3 and s = 1.164:
LV long axis 9.31 cm, LV outer diameter 6.98 cm, LV wall 11.6 mm (apex 9.3 mm), RV free
wall 4.7 mm, RV offset 2.33 cm, LV wall 167 g, RV free wall 51 g, LV cavity 106 ml, RV
cavity 75 ml, aortic root diameter 3.0 cm, ostia 5.8 mm above the base.

Supply counts the myocardium; the exclusion domain (large vessels, C_o) is the myocardium
plus both cavities, closed at the base plane: "vessels may not penetrate the ventricles".
The base is a cut through the heart, not a surface, so the distance map looks through the
space above the base (see :func:`_open_base`): the base layer is as deep as the heart is
wide there, and large vessels reach it from the epicardium.

The voxel grid covers the heart and the ostia plus a margin of 12% of the heart's largest
extent on every side, so that large vessels can run on the epicardium and bifurcations have
room outside the tissue. The voxelised mass differs from the target by the voxelisation
error only (well under 1% at the default voxel size R_supply / 4 for N >= 500); it is
logged by :func:`heart_tissue`.
"""

from __future__ import annotations

import functools
import logging
import math
import numbers

import numpy as np

from .grid import Tissue, TissueError, default_voxel_size, voxelize

__all__ = ["heart_tissue", "heart_dimensions", "RV_EXPONENT", "DEFAULT_MASS_G", "DEFAULT_DENSITY"]

log = logging.getLogger(__name__)

DEFAULT_MASS_G = 218.0  # g (paper)
DEFAULT_DENSITY = 1.06e3  # kg m^-3 (paper, Vinnakota 2004)
RV_EXPONENT = 2.5  # super-ellipsoid exponent of the RV (paper)
MARGIN_FRACTION = 0.12  # grid margin around the heart, fraction of its largest extent
# Accepted ranges of the shape options. base_cut < 0.75 keeps the RV cut by the base plane
# (its top is 4.5 / 6 of the LV's half-length above the equator); elongation 0.5 makes the LV
# a sphere, 2 twice the reference's length-to-width ratio.
BASE_CUT_RANGE = (0.0, 0.7)
ELONGATION_RANGE = (0.5, 2.0)
OSTIUM_HEIGHT_RANGE = (0.0, 0.05)  # m: half the heart's length; higher, the aortic root is not on this heart

# Unscaled reference geometry [m] (see the module docstring).
_CM = 1e-2
_BASE = dict(
    lv_center_z=-2.0 * _CM,
    lv_outer_radius=3.0 * _CM,
    lv_outer_half_length=6.0 * _CM,
    lv_inner_radius=2.0 * _CM,
    lv_inner_half_length=5.2 * _CM,
    rv_center_x=2.0 * _CM,
    rv_center_z=-2.0 * _CM,
    rv_outer_semi_axes=(2.8 * _CM, 3.3 * _CM, 4.5 * _CM),
    rv_inner_semi_axes=(2.4 * _CM, 2.9 * _CM, 4.1 * _CM),
    aortic_root_center=(1.6 * _CM, -0.4 * _CM),
    aortic_root_radius=1.3 * _CM,
    ostium_height=0.5 * _CM,
)
_LENGTH_KEYS = (
    "lv_center_z",
    "lv_outer_radius",
    "lv_outer_half_length",
    "lv_inner_radius",
    "lv_inner_half_length",
    "rv_center_x",
    "rv_center_z",
    "aortic_root_radius",
    "ostium_height",
)
_TUPLE_KEYS = ("rv_outer_semi_axes", "rv_inner_semi_axes", "aortic_root_center")


def _check_positive(field: str, value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value <= 0:
        raise TissueError(f"tissue.{field} must be a positive finite number ({what}), got {value!r}")
    return float(value)


def _shaped(base_cut: float | None = None, elongation: float | None = None) -> dict:
    """The unscaled reference geometry [m], reshaped by ``elongation`` and ``base_cut``."""
    d = dict(_BASE)
    if elongation is not None:
        for k in ("lv_center_z", "lv_outer_half_length", "lv_inner_half_length", "rv_center_z"):
            d[k] = _BASE[k] * elongation
        for k in ("rv_outer_semi_axes", "rv_inner_semi_axes"):
            ax, ay, az = _BASE[k]
            d[k] = (ax, ay, az * elongation)
    if base_cut is not None:  # the RV's centre stays level with the LV's, as in the reference
        d["lv_center_z"] = d["rv_center_z"] = -base_cut * d["lv_outer_half_length"]
    return d


def _scaled(scale: float, shape: tuple = (None, None)) -> dict:
    """The geometry of :func:`_shaped` (``shape`` = (base_cut, elongation)) times ``scale``."""
    ref = _shaped(*shape)
    dims = {k: float(ref[k] * scale) for k in _LENGTH_KEYS}
    dims.update({k: tuple(float(v * scale) for v in ref[k]) for k in _TUPLE_KEYS})
    return dims


def _half_extent_y(x, z, d: dict):
    """Half-widths in |y| of the four surfaces over the column (x, z); 0 where missed.

    Returns (Y_lv_outer, Y_lv_inner, Y_rv_outer, Y_rv_inner). Works on broadcastable arrays.
    """
    zc = z - d["lv_center_z"]
    out = []
    for a, c in ((d["lv_outer_radius"], d["lv_outer_half_length"]), (d["lv_inner_radius"], d["lv_inner_half_length"])):
        arg = 1.0 - (zc / c) ** 2 - (x / a) ** 2
        out.append(a * np.sqrt(np.maximum(arg, 0.0)))
    p = RV_EXPONENT
    dx = np.abs(x - d["rv_center_x"])
    dz = np.abs(z - d["rv_center_z"])
    for ax, ay, az in (d["rv_outer_semi_axes"], d["rv_inner_semi_axes"]):
        arg = 1.0 - (dx / ax) ** p - (dz / az) ** p
        out.append(ay * np.maximum(arg, 0.0) ** (1.0 / p))
    return out


def _extent(d: dict) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box [x, y, z] of the myocardium (lower, upper) [m]."""
    ax, ay, az = d["rv_outer_semi_axes"]
    lo = np.array([-d["lv_outer_radius"], -max(d["lv_outer_radius"], ay), d["lv_center_z"] - d["lv_outer_half_length"]])
    hi = np.array([max(d["lv_outer_radius"], d["rv_center_x"] + ax), max(d["lv_outer_radius"], ay), 0.0])
    return lo, hi


@functools.lru_cache(maxsize=8)
def _reference_volume(shape: tuple = (None, None), n: int = 2400) -> float:
    """Volume [m^3] of the unscaled myocardium: midpoint rule over (x, z), exact in y.

    Per column (x, z) below the base plane the tissue in y >= 0 is the LV wall
    [Y_lv_inner, Y_lv_outer] plus the RV free wall [max(Y_rv_inner, Y_lv_outer), Y_rv_outer].
    """
    d = _scaled(1.0, shape)
    lo, hi = _extent(d)
    hx = (hi[0] - lo[0]) / n
    hz = (hi[2] - lo[2]) / n
    x = lo[0] + hx * (np.arange(n) + 0.5)
    total = 0.0
    for zs in np.array_split(lo[2] + hz * (np.arange(n) + 0.5), 8):
        yo, yi, ro, ri = _half_extent_y(x[None, :], zs[:, None], d)
        length = (yo - yi) + np.maximum(ro - np.maximum(ri, yo), 0.0)
        total += float(length.sum())
    return 2.0 * total * hx * hz


def _scale_for(mass_g: float, density: float, shape: tuple = (None, None)) -> float:
    target = mass_g * 1e-3 / density
    return (target / _reference_volume(shape)) ** (1.0 / 3.0)


def _inside(d: dict, solid: bool = False):
    """inside(x, y, z) for :func:`voxelize`, evaluated slice by slice on the grid axes.

    The myocardium, or with ``solid`` the heart with its ventricular cavities (inside
    the LV's or the RV's outer surface, below the base plane, which closes the cavities).

    voxelize passes full meshgrid arrays; only their axes are used here (x varies along
    the last axis, y along the middle one, z along the first), so temporaries stay the
    size of one z slice, in float32 where the precision allows.
    """
    p = RV_EXPONENT

    def inside(x, y, z):
        xs = np.asarray(x[0, 0, :], dtype=np.float64)
        ys = np.asarray(y[0, :, 0], dtype=np.float64)
        zs = np.asarray(z[:, 0, 0], dtype=np.float64)
        out = np.zeros((zs.size, ys.size, xs.size), dtype=bool)  # also right for sparse grids
        # |y|^p / ay^p and y^2 / a^2 terms per row, x terms per column: (ny, 1) + (1, nx)
        y2 = (ys**2)[:, None]
        x2 = (xs**2)[None, :]
        adx = np.abs(xs - d["rv_center_x"])[None, :]
        ay_abs = np.abs(ys)[:, None]
        a_o, c_o = d["lv_outer_radius"], d["lv_outer_half_length"]
        a_i, c_i = d["lv_inner_radius"], d["lv_inner_half_length"]
        lv_o_xy = ((x2 + y2) / a_o**2).astype(np.float32)
        lv_i_xy = ((x2 + y2) / a_i**2).astype(np.float32)
        (oxa, oya, oza), (ixa, iya, iza) = d["rv_outer_semi_axes"], d["rv_inner_semi_axes"]
        rv_o_xy = ((adx / oxa) ** p + (ay_abs / oya) ** p).astype(np.float32)
        rv_i_xy = ((adx / ixa) ** p + (ay_abs / iya) ** p).astype(np.float32)
        for k, zk in enumerate(zs):
            if zk > 0.0:  # truncated at the base plane z = 0
                continue
            dz_lv = (zk - d["lv_center_z"]) ** 2
            dz_rv = abs(zk - d["rv_center_z"])
            lv_outer = lv_o_xy <= np.float32(1.0 - dz_lv / c_o**2)
            rv_outer = rv_o_xy <= np.float32(1.0 - (dz_rv / oza) ** p)
            if solid:
                out[k] = lv_outer | rv_outer
            else:
                lv_inner = lv_i_xy <= np.float32(1.0 - dz_lv / c_i**2)
                rv_inner = rv_i_xy <= np.float32(1.0 - (dz_rv / iza) ** p)
                out[k] = (lv_outer & ~lv_inner) | (rv_outer & ~rv_inner & ~lv_outer)
        return out

    return inside


def _inlets(d: dict) -> np.ndarray:
    cx, cy = d["aortic_root_center"]
    r = d["aortic_root_radius"]
    h = d["ostium_height"]
    return np.array([[cx - r, cy, h], [cx + r, cy, h]])


@functools.lru_cache(maxsize=32)
def _dimensions(mass_g: float, density: float, shape: tuple = (None, None)) -> dict:
    s = float(_scale_for(mass_g, density, shape))
    d = _scaled(s, shape)
    lo, hi = _extent(d)
    d.update(
        scale=s,
        rv_exponent=RV_EXPONENT,
        base_z=0.0,
        apex_z=d["lv_center_z"] - d["lv_outer_half_length"],
        lv_long_axis=d["lv_outer_half_length"] - d["lv_center_z"],
        lv_wall_equator=d["lv_outer_radius"] - d["lv_inner_radius"],
        lv_wall_apex=d["lv_outer_half_length"] - d["lv_inner_half_length"],
        rv_free_wall=d["rv_outer_semi_axes"][0] - d["rv_inner_semi_axes"][0],
        rv_offset=d["rv_center_x"],
        bbox_lo=tuple(lo.tolist()),
        bbox_hi=tuple(hi.tolist()),
        inlets=tuple(map(tuple, _inlets(d).tolist())),
        inlet_names=("LCA", "RCA"),
        volume=float(_reference_volume(shape) * s**3),
        mass_g_target=mass_g,
        density=density,
        mass_g_reference=float(_reference_volume(shape) * s**3 * density * 1e3),
        base_cut=-d["lv_center_z"] / d["lv_outer_half_length"],
        elongation=1.0 if shape[1] is None else float(shape[1]),
    )
    return d


def _open_base(solid: np.ndarray) -> np.ndarray:
    """The space above the heart's base plane, over its footprint (bool (z, y, x)).

    The truncation at the base is a cut, not a surface: were the plane closing the
    cavities a surface, large vessels could run just under it, across a cavity, at almost
    no exclusion cost (measured at N = 200: 0.3-1.4 % of the large vessels' length when
    only the cavity openings were looked through). The distance map looks through this
    space instead, so the base layer is as deep as the heart is wide there, and large
    vessels reach the base from the side (the epicardium), as in the atrioventricular groove.
    """
    top = int(np.flatnonzero(solid.any(axis=(1, 2))).max())  # z index of the base layer
    openings = np.zeros(solid.shape, dtype=bool)
    openings[top + 1 :] = solid[top] == 1
    return openings


def _build(
    n_terminals: int,
    voxel_size: float | None,
    mass_g: float,
    density: float,
    exclude_cavities: bool = True,
    q_required: float | None = None,
    total_flow: float | None = None,
    ostium_height: float | None = None,
    shape: tuple = (None, None),
) -> tuple[Tissue, dict]:
    d = dict(_dimensions(mass_g, density, shape))
    volume = d["volume"]
    h = voxel_size if voxel_size is not None else default_voxel_size(n_terminals, volume, 3, q_required, total_flow)
    lo, hi = np.array(d["bbox_lo"]), np.array(d["bbox_hi"])
    inl = np.array(d["inlets"])
    lo_all = np.minimum(lo, inl.min(axis=0))
    hi_all = np.maximum(hi, inl.max(axis=0))
    if ostium_height is not None:  # in metres as given, not scaled with the heart
        d["ostium_height"] = float(ostium_height)
        d["inlets"] = tuple(map(tuple, _inlets(d).tolist()))
        inl = np.array(d["inlets"])
        # Ostia above the default box add whole voxel layers on top: the grid's origin, so
        # the voxelised heart, stays that of the default ostia.
        hi_all[2] += h * math.ceil(max(float(inl[:, 2].max() - hi_all[2]), 0.0) / h)
    margin = MARGIN_FRACTION * float(np.max(hi - lo))
    mask, origin = voxelize(_inside(d), lo_all, hi_all, h, margin=margin)
    solid = openings = None
    if exclude_cavities:
        solid = voxelize(_inside(d, solid=True), lo_all, hi_all, h, margin=margin)[0]
        openings = _open_base(solid)
    tissue = Tissue(
        "heart", mask, h, origin, inl, inlet_names=d["inlet_names"], exclusion=solid, open_boundary=openings
    )
    return tissue, d


def _check_options(ostium_height, base_cut, elongation) -> tuple:
    """(ostium_height, (base_cut, elongation)) as floats or None, each in its range (TissueError naming it)."""
    checked = []
    for field, value, (low, high), what in (
        ("ostium_height", ostium_height, OSTIUM_HEIGHT_RANGE, "a height above the heart's base plane in metres"),
        ("base_cut", base_cut, BASE_CUT_RANGE, "the base plane's height above the LV's equator, in LV half-lengths"),
        ("elongation", elongation, ELONGATION_RANGE, "the factor on the ventricles' long-axis dimensions"),
    ):
        if value is not None:
            ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and low <= value <= high
            if not ok:
                raise TissueError(f"tissue.{field} must be {what}, in [{low}, {high}], or null, got {value!r}")
            value = float(value)
        checked.append(value)
    return checked[0], tuple(checked[1:])


def _validate(n_terminals, voxel_size, mass_g, density, ostium_height, base_cut, elongation) -> tuple:
    """(voxel_size, mass_g, density, ostium_height, shape) checked, each error naming its field."""
    mass_g = _check_positive("mass_g", mass_g, "myocardial mass in grams, > 0")
    density = _check_positive("density", density, "myocardial density in kg m^-3, > 0")
    if voxel_size is not None:
        voxel_size = _check_positive("voxel_size", voxel_size, "voxel edge in metres, > 0")
    if isinstance(n_terminals, bool) or not isinstance(n_terminals, numbers.Integral) or n_terminals < 1:
        raise TissueError(f"n_terminals must be a positive integer, got {n_terminals!r}")
    return (voxel_size, mass_g, density, *_check_options(ostium_height, base_cut, elongation))


def heart_dimensions(
    mass_g: float = DEFAULT_MASS_G,
    density: float = DEFAULT_DENSITY,
    *,
    n_terminals: int = 1000,
    voxel_size: float | None = None,
    ostium_height: float | None = None,
    base_cut: float | None = None,
    elongation: float | None = None,
) -> dict:
    """The scaled heart geometry [m] and its masses [g].

    Keys: the scaled lengths of the module docstring (``lv_outer_radius``,
    ``lv_outer_half_length``, ``lv_inner_radius``, ``lv_inner_half_length``, ``lv_center_z``,
    ``rv_center_x`` (= ``rv_offset``), ``rv_center_z``, ``rv_outer_semi_axes``,
    ``rv_inner_semi_axes``, ``aortic_root_center``, ``aortic_root_radius``,
    ``ostium_height``), derived ones (``lv_long_axis``, ``lv_wall_equator``,
    ``lv_wall_apex``, ``rv_free_wall``, ``base_z`` = 0, ``apex_z``, ``bbox_lo``/``bbox_hi``,
    ``base_cut`` and ``elongation`` as used),
    ``inlets`` and ``inlet_names``, ``scale`` (factor applied to the reference dimensions),
    ``volume`` [m^3] and ``mass_g_reference`` (fine-grid mass, equal to ``mass_g``), and
    ``voxel_size``, ``n_tissue_voxels`` and ``mass_g_voxelised`` (``mass_g`` in short): the
    achieved mass of the voxel map at ``voxel_size`` (default: R_supply / 4 for
    ``n_terminals``).
    """
    voxel_size, mass_g, density, ostium_height, shape = _validate(
        n_terminals, voxel_size, mass_g, density, ostium_height, base_cut, elongation
    )
    tissue, d = _build(
        n_terminals, voxel_size, mass_g, density, exclude_cavities=False, ostium_height=ostium_height, shape=shape
    )
    achieved = tissue.measure * density * 1e3
    d.update(
        voxel_size=float(tissue.voxel_size),
        n_tissue_voxels=tissue.n_tissue_voxels,
        grid_shape=tissue.shape,
        mass_g_voxelised=float(achieved),
        mass_g=float(achieved),
    )
    return d


def heart_tissue(
    n_terminals: int,
    voxel_size: float | None = None,
    mass_g: float = DEFAULT_MASS_G,
    density: float = DEFAULT_DENSITY,
    exclude_cavities: bool = True,
    q_required: float | None = None,
    total_flow: float | None = None,
    ostium_height: float | None = None,
    base_cut: float | None = None,
    elongation: float | None = None,
    *,
    report: bool = True,
    **_,
) -> Tissue:
    """The coronary substrate (LV + RV myocardium) with the LCA and RCA ostia as inlets.

    ``voxel_size`` [m] defaults to R_supply / 4 for ``n_terminals`` (with ``q_required``
    [s^-1] and ``total_flow`` [m^3 s^-1] when a required flow density is given); ``mass_g`` and
    ``density`` [kg m^-3] fix the myocardial volume the geometry is scaled to. The
    exclusion domain is the myocardium plus the ventricular cavities closed at the base
    plane ("vessels may not penetrate the ventricles"), or with ``exclude_cavities=False``
    the myocardium only (cavities then cost nothing to cross; the model before 2026-11).
    ``ostium_height`` [m, in [0, 0.05]] places both ostia that far above the base plane on
    the aortic root's wall (default: the reference heart's 5 mm, scaled: 5.8 mm at 218 g).
    ``base_cut`` (in [0, 0.7]; default 1/3) and ``elongation`` (in [0.5, 2]; default 1)
    reshape the reference heart before it is scaled to ``mass_g`` (module docstring).
    Keys meant for other tissues are ignored. Logs the achieved (voxelised) mass at INFO, or
    with ``report=False`` (the exclusion grid's twin, :func:`vasc_pipeline.model.tissue.build_tissue`)
    at DEBUG.
    """
    voxel_size, mass_g, density, ostium_height, shape = _validate(
        n_terminals, voxel_size, mass_g, density, ostium_height, base_cut, elongation
    )
    tissue, d = _build(
        n_terminals, voxel_size, mass_g, density, bool(exclude_cavities), q_required, total_flow, ostium_height, shape
    )
    achieved = tissue.measure * density * 1e3
    log.log(
        logging.INFO if report else logging.DEBUG,
        "heart tissue: %.2f g myocardium as voxelised (target %.2f g, %+.2f%%), %d voxels of %.3g mm, "
        "grid %s, LV long axis %.1f mm",
        achieved,
        mass_g,
        100.0 * (achieved / mass_g - 1.0),
        tissue.n_tissue_voxels,
        tissue.voxel_size * 1e3,
        "x".join(map(str, tissue.shape)),
        d["lv_long_axis"] * 1e3,
    )
    return tissue
