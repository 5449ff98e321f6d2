"""The coronary substrate (vasc_pipeline.model.tissue.heart): mass, shape, inlets, bad input."""

from __future__ import annotations

import inspect
import json
import logging
from dataclasses import asdict

import numpy as np
import pytest
from helpers import make_problem
from scipy import ndimage

from vasc_pipeline import engine
from vasc_pipeline.config import (
    TISSUE_KEYS_OF_EVERY_TISSUE,
    ConfigError,
    TissueConfig,
    compose,
    to_run_config,
    validate,
)
from vasc_pipeline.config.identity import config_hash
from vasc_pipeline.model.tissue import TISSUES, TissueError, build_tissue, heart

TARGET_G = 218.0
DENSITY = 1.06e3


@pytest.fixture(scope="module")
def dims():
    return heart.heart_dimensions(n_terminals=300)


@pytest.fixture(scope="module")
def tissue1000():
    return heart.heart_tissue(1000)


def _mass_g(t, density=DENSITY):
    return t.n_tissue_voxels * t.voxel_size**3 * density * 1e3


def _voxel_centres_z(t):
    return t.origin[2] + t.voxel_size * np.arange(t.shape[0])


def test_reference_volume_is_converged_and_agrees_with_counting_voxels():
    # the fine-grid reference integral is converged ...
    v = heart._reference_volume()
    assert heart._reference_volume.__wrapped__(n=1200) == pytest.approx(v, rel=1e-4)
    # ... and agrees with an independent estimate: fine voxels counted in the scaled heart
    fine = heart.heart_dimensions(voxel_size=0.6e-3)
    assert fine["mass_g_voxelised"] == pytest.approx(TARGET_G, rel=5e-3)


def test_mass_within_2_percent_at_1000(tissue1000):
    assert _mass_g(tissue1000) == pytest.approx(TARGET_G, rel=0.02)


def test_mass_within_2_percent_at_500():
    assert _mass_g(heart.heart_tissue(500)) == pytest.approx(TARGET_G, rel=0.02)


def test_mass_and_density_params_scale_the_heart():
    t = heart.heart_tissue(1000, mass_g=109.0, density=1.0e3)
    assert _mass_g(t, 1.0e3) == pytest.approx(109.0, rel=0.02)


def test_dimensions_physiological(dims):
    assert 0.07 < dims["lv_long_axis"] < 0.12
    assert 0.007 < dims["lv_wall_equator"] < 0.016
    assert 0.002 < dims["rv_free_wall"] < 0.007
    assert dims["rv_offset"] > 0
    assert dims["apex_z"] < dims["base_z"] == 0.0
    assert dims["mass_g_voxelised"] == pytest.approx(TARGET_G, rel=0.03)


def test_via_build_tissue_ignores_other_keys(caplog):
    with caplog.at_level(logging.INFO, logger="vasc_pipeline.model.tissue.heart"):
        t = build_tissue(
            "heart", 300, mass_g=218.0, density=1.06e3, voxel_size=None, radius=0.02, side=0.1, q_required=None
        )
    assert t.name == "heart" and t.ndim == 3
    assert any("g myocardium" in r.getMessage() for r in caplog.records)


def test_inlets_outside_tissue_inside_grid(tissue1000):
    t = tissue1000
    assert t.inlet_names == ("LCA", "RCA")
    assert t.inlets.shape == (2, 3)
    assert not t.contains(t.inlets).any()
    lo, hi = t.bounds
    assert np.all(t.inlets > lo) and np.all(t.inlets < hi)
    # LCA on the left (-x), RCA on the right (+x, the RV side), both at the base
    assert t.inlets[0, 0] < t.inlets[1, 0]
    assert np.all(t.inlets[:, 2] >= 0.0)
    # room outside the tissue: a margin of empty voxels on every side of the heart
    m = t.mask
    for axis in range(3):
        occupied = np.flatnonzero(m.any(axis=tuple(a for a in range(3) if a != axis)))
        assert occupied[0] >= 5 and occupied[-1] <= m.shape[axis] - 6


def test_lv_cavity_not_tissue(tissue1000, dims):
    t = tissue1000
    centre = np.array([0.0, 0.0, dims["lv_center_z"]])
    assert not t.contains(centre[None])[0]
    # the LV wall is tissue on both sides of the cavity (lateral wall and septum)
    r = 0.5 * (dims["lv_outer_radius"] + dims["lv_inner_radius"])
    assert t.contains(np.array([[-r, 0.0, centre[2]], [r, 0.0, centre[2]], [0.0, r, centre[2]]])).all()


def test_rv_cavity_not_tissue(tissue1000, dims):
    t = tissue1000
    z = dims["rv_center_z"]
    x_septum = dims["lv_outer_radius"]  # LV outer surface at the equator (rv_center_z = lv_center_z)
    x_rv_inner = dims["rv_center_x"] + dims["rv_inner_semi_axes"][0]
    x_rv_outer = dims["rv_center_x"] + dims["rv_outer_semi_axes"][0]
    cavity = np.array([[0.5 * (x_septum + x_rv_inner), 0.0, z]])
    free_wall = np.array([[0.5 * (x_rv_inner + x_rv_outer), 0.0, z]])
    assert x_septum < x_rv_inner
    assert not t.contains(cavity)[0]
    assert t.contains(free_wall)[0]
    assert not t.contains(np.array([[x_rv_outer + 2 * t.voxel_size, 0.0, z]]))[0]


def test_tissue_connected(tissue1000):
    _, n = ndimage.label(tissue1000.mask)
    assert n == 1


def test_apex_below_base_and_truncation(tissue1000, dims):
    t = tissue1000
    zc = _voxel_centres_z(t)
    layers = np.flatnonzero(t.mask.any(axis=(1, 2)))
    z_low, z_high = zc[layers[0]], zc[layers[-1]]
    assert z_low < z_high
    assert z_low == pytest.approx(dims["apex_z"], abs=t.voxel_size)
    # truncated at the base plane z = 0: no tissue above it, but tissue right below it
    assert z_high <= 1e-12
    assert z_high > -t.voxel_size
    assert zc[-1] > 0.0 and not t.mask[zc > 1e-12].any()
    # the base cross-section is open: the LV cavity reaches the base plane
    assert t.mask[layers[-1]].sum() > 0
    assert not t.contains(np.array([[0.0, 0.0, z_high]]))[0]


def test_distance_transform_deep_enough(tissue1000):
    assert tissue1000.distance.max() > 2.0


def test_explicit_voxel_size():
    t = heart.heart_tissue(1000, voxel_size=2e-3)
    assert t.voxel_size == 2e-3
    assert _mass_g(t) == pytest.approx(TARGET_G, rel=0.05)


@pytest.mark.parametrize(
    "field, value",
    [
        ("mass_g", 0.0),
        ("mass_g", -5.0),
        ("mass_g", float("nan")),
        ("mass_g", "heavy"),
        ("density", 0.0),
        ("density", -1.0),
        ("density", float("inf")),
        ("voxel_size", -1e-3),
        ("voxel_size", 0.0),
    ],
)
def test_bad_parameters_name_the_field(field, value):
    with pytest.raises(TissueError, match=field):
        heart.heart_tissue(100, **{field: value})
    if field != "voxel_size":
        with pytest.raises(TissueError, match=field):
            heart.heart_dimensions(**{field: value})


# -- exclusion domain: myocardium plus the ventricular cavities (the exclusion term C_o) --------


def test_exclusion_domain_is_the_myocardium_plus_the_cavities(tissue1000, dims):
    t = tissue1000
    assert np.all(t.exclusion >= t.mask)  # the tissue is excluded too
    cavity_ml = t.cavity.sum() * t.voxel_size**3 * 1e6
    # LV 106 ml + RV 75 ml at the default scale (module docstring), up to voxelisation
    assert cavity_ml == pytest.approx(181.0, rel=0.03)
    k, j, i = t.voxel_index(np.array([0.0, 0.0, dims["lv_center_z"]]))
    assert t.mask[k, j, i] == 0 and t.cavity[k, j, i] and t.exclusion[k, j, i] == 1  # not tissue, but excluded
    _, n = ndimage.label(t.exclusion)
    assert n == 1
    assert not t.exclusion[_voxel_centres_z(t) > 1e-12].any()  # closed at the base plane, nothing above
    np.testing.assert_array_equal(t.distance[t.exclusion == 0], 0.0)


def test_cavities_are_deep_up_to_the_base_plane(tissue1000, dims):
    """The base plane closes the cavities but is no surface: the top layer is deep, not 1 voxel."""
    t = tissue1000
    top = int(np.flatnonzero(t.exclusion.any(axis=(1, 2))).max())
    _, j, i = t.voxel_index(np.array([0.0, 0.0, 0.0]))  # on the LV axis, in the base layer
    k = top
    assert t.cavity[k, j, i]
    # about the distance to the LV epicardium at the base (its outer radius there)
    r_base = dims["lv_outer_radius"] * np.sqrt(1 - (dims["lv_center_z"] / dims["lv_outer_half_length"]) ** 2)
    assert t.distance[k, j, i] > 0.5 * r_base / t.voxel_size
    # the septum lies between the cavities: deeper than any wall of the old (myocardium-only) map
    old = heart.heart_tissue(1000, exclude_cavities=False)
    assert t.distance.max() > 3 * old.distance.max()


def test_exclude_cavities_false_is_the_myocardium_only_model(tissue1000):
    old = heart.heart_tissue(1000, exclude_cavities=False)
    np.testing.assert_array_equal(old.mask, tissue1000.mask)
    np.testing.assert_array_equal(old.exclusion, old.mask)
    assert not old.cavity.any()
    expected = ndimage.distance_transform_edt(np.pad(old.mask, 1))[1:-1, 1:-1, 1:-1]
    np.testing.assert_allclose(old.distance, expected, rtol=1e-6)


def test_large_vessels_stay_out_of_the_cavities_after_a_fixed_seed_anneal():
    """N = 200, seed 0, the default schedule: the cavity share is ~0 (the fidelity work's
    target is < 0.5 %); with the myocardium-only map the same run puts ~30 % in the cavities."""
    from vasc_pipeline import config, engine
    from vasc_pipeline.model.costs import cavity_share

    result = engine.run(config.compose(["n_terminals=200"]), seed=0)
    share = result.statistics["cavity_share"]
    assert 0.0 <= share < 0.005
    old = engine.run(config.compose(["n_terminals=200", "tissue.exclude_cavities=false"]), seed=0)
    assert old.statistics == {}  # no cavity in its tissue: nothing to report
    assert cavity_share(old.tree.parent, old.tree.position, old.radius, result.problem.tissue) > 0.1


def test_ostium_height_places_both_ostia_above_the_base_in_metres(dims):
    assert dims["ostium_height"] == pytest.approx(0.005 * dims["scale"])  # the reference's 5 mm, scaled
    t = heart.heart_tissue(300, ostium_height=0.015)
    reference = np.array(dims["inlets"])
    np.testing.assert_allclose(t.inlets[:, 2], 0.015)
    np.testing.assert_allclose(t.inlets[:, :2], reference[:, :2])  # on the aortic root's wall, as before
    assert not t.contains(t.inlets).any()
    assert np.all(t.inlets < t.bounds[1])  # the grid grows to hold them
    default = heart.heart_tissue(300)
    # the same voxelised myocardium: the grid only gains layers on top
    np.testing.assert_allclose(t.origin, default.origin, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(t.mask[: default.shape[0]], default.mask)
    assert t.shape[0] > default.shape[0] and not t.mask[default.shape[0] :].any()


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["tissue=sphere", "tissue.ostium_height=0.01"], r"tissue.ostium_height is read by tissue=heart only; "),
        (["tissue=box", "tissue.base_cut=0.2"], r"tissue.base_cut .* tissue=box ignores it: .* default \(null\)"),
        (["tissue=plane2d", "tissue.elongation=1.2"], "tissue.elongation is read by tissue=heart only"),
        (["tissue=sphere", "tissue.mass_g=109"], r"tissue.mass_g .* leave it at its default \(218.0\)"),
        (
            [
                "tissue=mask",
                "tissue.path=m.npy",
                "tissue.voxel_size=1e-3",
                "tissue.inlets=[[0,0,0]]",
                "tissue.exclude_cavities=false",
            ],
            r"tissue.exclude_cavities .* tissue=mask ignores it: .*\(true\)",
        ),
        (["tissue.radius=0.03"], r"tissue.radius is read by tissue=sphere only"),
        (["tissue=sphere", "tissue.size=[0.02,0.02,0.02]"], r"tissue.size is read by tissue=box only"),
        (["tissue=box", "tissue.side=0.2"], r"tissue.side is read by tissue=plane2d only"),
    ],
)
def test_keys_the_tissue_does_not_read_are_refused_naming_the_field(overrides, message):
    with pytest.raises(ConfigError, match=message):
        validate(to_run_config(compose(overrides, check=False)))


def test_every_tissue_key_applies_to_every_tissue_or_is_read_by_a_tissue_builder():
    read = set().union(*(inspect.signature(build).parameters for build in TISSUES.values()))
    for key in TissueConfig.__dataclass_fields__:
        assert key in TISSUE_KEYS_OF_EVERY_TISSUE or key in read, key


@pytest.mark.parametrize(
    "overrides",
    [
        ["tissue.mass_g=109", "tissue.exclude_cavities=false", "tissue.q_required=0.02", "tissue.voxel_size=1e-3"],
        ["tissue=sphere", "tissue.radius=0.03", "tissue.bifurcation_reach=0", "tissue.mass_g=218"],
        ["tissue=box", "tissue.size=[0.02,0.02,0.01]", "tissue.inlet_assignment=nearest"],
        ["tissue=plane2d", "tissue.side=0.2", "tissue.voxel_size=1e-3"],
    ],
)
def test_keys_the_tissue_reads_and_defaults_are_accepted(overrides):
    validate(to_run_config(compose(overrides, check=False)))


@pytest.mark.parametrize("key, value", [("ostium_height", 0.01), ("base_cut", 0.2), ("elongation", 1.3)])
def test_runs_stored_before_the_heart_options_keep_their_identity(key, value):
    base = to_run_config(compose([]))
    explicit = to_run_config(compose([f"tissue.{key}=null"]))
    assert getattr(explicit.tissue, key) is None
    assert config_hash(asdict(base)) == config_hash(asdict(explicit))
    stored_before = asdict(base)
    del stored_before["tissue"][key]
    assert config_hash(stored_before) == config_hash(asdict(base))
    assert config_hash(asdict(to_run_config(compose([f"tissue.{key}={value}"])))) != config_hash(asdict(base))


@pytest.mark.parametrize("shape", [dict(base_cut=0.0), dict(base_cut=0.6), dict(elongation=0.7), dict(elongation=1.5)])
def test_shape_options_reshape_the_heart_at_its_mass(dims, shape):
    d = heart.heart_dimensions(n_terminals=300, **shape)
    assert d["mass_g_reference"] == pytest.approx(TARGET_G, rel=1e-4)  # rescaled to the mass
    assert d["mass_g_voxelised"] == pytest.approx(TARGET_G, rel=0.03)
    base_cut = shape.get("base_cut", 1.0 / 3.0)
    elongation = shape.get("elongation", 1.0)
    assert d["base_cut"] == pytest.approx(base_cut) and d["elongation"] == elongation
    assert -d["lv_center_z"] / d["lv_outer_half_length"] == pytest.approx(base_cut)
    assert d["rv_center_z"] == d["lv_center_z"]
    # length over width of the LV's outer ellipsoid: elongation times the reference's 6 / 3
    assert d["lv_outer_half_length"] / d["lv_outer_radius"] == pytest.approx(2.0 * elongation)
    assert d["lv_long_axis"] == pytest.approx((1.0 + base_cut) * d["lv_outer_half_length"])
    # the ostia keep their scaled 5 mm above the base plane, the walls their x-y thickness
    assert d["ostium_height"] == pytest.approx(0.005 * d["scale"])
    assert d["lv_wall_equator"] / d["scale"] == pytest.approx(dims["lv_wall_equator"] / dims["scale"])
    t = heart.heart_tissue(300, **shape)
    assert _mass_g(t) == pytest.approx(TARGET_G, rel=0.03)
    assert np.all(t.inlets[:, 2] == pytest.approx(d["ostium_height"]))


def test_unset_shape_is_the_reference_heart(tissue1000):
    t = heart.heart_tissue(1000, base_cut=None, elongation=None)
    assert np.array_equal(t.mask, tissue1000.mask) and np.array_equal(t.distance, tissue1000.distance)


@pytest.mark.parametrize(
    "key, value, message",
    [
        ("base_cut", -0.1, r"tissue.base_cut must be .* in \[0.0, 0.7\], or null, got -0.1"),
        ("base_cut", 0.8, "tissue.base_cut must be"),
        ("elongation", 0.3, r"tissue.elongation must be .* in \[0.5, 2.0\]"),
        ("elongation", "long", "tissue.elongation must be"),
        ("ostium_height", -0.001, r"tissue.ostium_height must be a height .* in \[0.0, 0.05\]"),
        ("ostium_height", 0.2, "tissue.ostium_height must be"),
    ],
)
def test_bad_heart_options_are_refused_before_any_job(tmp_path, key, value, message):
    with pytest.raises(TissueError, match=message):
        heart.heart_tissue(300, **{key: value})
    if isinstance(value, float):  # and by the command's planning, before anything is written
        from vasc_pipeline.pipeline.planning import plan

        with pytest.raises(TissueError, match=message):
            plan(compose([f"tissue.{key}={value}", f"output_dir={tmp_path / 'out'}", "n_terminals=300"]))
        assert not (tmp_path / "out").exists()


def test_a_sweep_reports_the_heart_mass_once(caplog, tmp_path):
    """Planning builds the heart (and its exclusion grid's twin at tissue.exclusion_voxel_size), the
    kernels' warm-up builds it again: the achieved mass is reported once, for the supply grid."""
    from vasc_pipeline.pipeline import orchestrate, planning

    cfg = compose(["n_terminals=16", "anneal.steps=600", "anneal.trace_every=300", f"output_dir={tmp_path}"])
    with caplog.at_level(logging.INFO, logger="vasc_pipeline.model.tissue.heart"):
        p = planning.plan(cfg)
        orchestrate.compile_kernels(p.jobs)
    reports = [r.getMessage() for r in caplog.records if r.levelno >= logging.INFO and "myocardium" in r.getMessage()]
    supply_mm = build_tissue("heart", 16).voxel_size * 1e3
    assert len(reports) == 1 and f"voxels of {supply_mm:.3g} mm" in reports[0], reports


def test_ostia_on_the_base_plane_open_onto_the_cavity_and_are_accepted():
    """At ostium_height=0 the LCA lies on the base plane over the LV's cavity: in a cavity voxel of
    the top layer, whose face opens onto the space above the base. Not inside the cavity."""
    t = heart.heart_tissue(200, ostium_height=0.0)
    assert t.contains(t.inlets, t.cavity)[0]
    np.testing.assert_array_equal(t.inlets[:, 2], 0.0)


# -- own inlets (ostia) on every tissue ---------------------------------------------------------


def inlets_override(points) -> str:
    """``tissue.inlets=[[x,y,z],...]`` with every float exact (repr round-trips)."""
    return "tissue.inlets=[" + ",".join("[" + ",".join(repr(float(v)) for v in p) + "]" for p in points) + "]"


@pytest.mark.parametrize(
    "name, points",
    [
        ("heart", [[0.03, 0.0, 0.004]]),  # one ostium, beside the base
        ("sphere", [[0.0, 0.021, 0.0], [0.0, -0.021, 0.0]]),  # two, either side of the ball
        ("box", [[0.0, 0.0, 0.0]]),  # a corner of the block
        ("plane2d", [[0.1, 0.1, 0.0]]),  # the far corner
    ],
)
def test_own_inlets_replace_the_tissues_and_keep_its_grid(tmp_path, name, points):
    n = "n_terminals=64" if name == "plane2d" else "n_terminals=16"
    default = make_problem(f"tissue={name}", n).tissue
    own = make_problem(f"tissue={name}", n, inlets_override(points)).tissue
    np.testing.assert_array_equal(own.inlets, points)
    assert own.inlet_names == tuple(f"inlet{k}" for k in range(len(points)))
    np.testing.assert_array_equal(own.mask, default.mask)  # the tissue and its grid are the tissue's own
    np.testing.assert_array_equal(own.origin, default.origin)
    np.testing.assert_array_equal(own.distance, default.distance)
    named = tmp_path / "ostia.json"
    named.write_text(json.dumps({f"ostium{k}": p for k, p in enumerate(points)}))
    from_file = make_problem(f"tissue={name}", n, f"tissue.inlets_path={named}").tissue
    np.testing.assert_array_equal(from_file.inlets, points)
    assert from_file.inlet_names == tuple(f"ostium{k}" for k in range(len(points)))


@pytest.mark.parametrize(
    "overrides, message",
    [
        (
            ["tissue.inlets=[[0.5,0,0]]"],
            r"^tissue\.inlets: inlet 0 \(inlet0\) at \[500, 0, 0\] mm lies outside the voxel grid",
        ),
        (["tissue=sphere", "tissue.inlets=[[0,0,0.05]]"], r"^tissue\.inlets: inlet 0 .* lies outside the voxel grid"),
        (["tissue=plane2d", "tissue.inlets=[[0.05,0.05,0.001]]"], r"lies outside .* \(the plane of a 2-D tissue\)"),
        (["tissue.inlets=[]"], r"tissue\.inlets must hold at least one \[x, y, z\] position"),
        (["tissue.ostium_height=0.01", "tissue.inlets=[[0,0,0.01]]"], r"ostia, which tissue\.inlets replaces: set one"),
        (["tissue=box", "tissue.inlets=[[0,0]]"], r"tissue\.inlets\[0\] must be an \[x, y, z\] position"),
        (
            ["tissue.inlets=[[0.0,0.0,-0.03]]"],
            r"^tissue\.inlets: inlet 0 \(inlet0\) at \[0, 0, -30\] mm lies inside a cavity",
        ),
    ],
)
def test_own_inlets_out_of_the_box_or_in_a_cavity_are_refused(overrides, message):
    with pytest.raises((TissueError, ConfigError), match=message):
        make_problem("n_terminals=16", *overrides)


def test_own_inlets_at_the_hearts_ostia_give_todays_tree_bit_for_bit():
    """tissue.inlets set to the heart's own ostia (the floats its builder computes) is today's run,
    and tissue.inlets unset leaves the config's identity as it was."""
    run = ("n_terminals=24", "anneal.steps=3000", "anneal.trace_every=1000")
    ostia = build_tissue("heart", 24).inlets
    today = engine.run(compose(list(run)), seed=3)
    own = engine.run(compose([*run, inlets_override(ostia)]), seed=3)
    np.testing.assert_array_equal(own.tree.parent, today.tree.parent)
    np.testing.assert_array_equal(own.tree.position, today.tree.position)
    assert own.costs == today.costs
    unset = config_hash(asdict(compose(list(run))))
    assert unset == config_hash(asdict(compose([*run, "tissue.inlets=null", "tissue.inlets_path=null"])))
    assert unset != config_hash(asdict(compose([*run, inlets_override(ostia)])))  # given, they are part of it
