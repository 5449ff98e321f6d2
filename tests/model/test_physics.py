import math

import numpy as np
import pytest

from vasc_pipeline import costs, physics
from vasc_pipeline.model.tree import Tree


def coronary(**kw):
    base = dict(
        n_terminals=1000,
        n_inlets=2,
        gamma=2.1,
        inlet_radius=2.1e-3,
        total_flow=4.16e-6,
        m_b=641.3,
        viscosity=3.6e-3,
        supply_radius=3e-3,
    )
    base.update(kw)
    return physics.Physics(**base)


def test_murray_radii_and_inlet_split():
    p = coronary()
    # r_t = r_in N^(-1/gamma), r = r_t n^(1/gamma): the whole tree has the inlet radius.
    assert p.radius(1000) == pytest.approx(2.1e-3, rel=1e-12)
    assert p.terminal_radius == pytest.approx(2.1e-3 * 1000 ** (-1 / 2.1), rel=1e-12)
    # Any split of terminals between the two inlets keeps sum r_k^gamma = r_in^gamma.
    for n_left in (1, 300, 999):
        r1, r2 = p.radius(n_left), p.radius(1000 - n_left)
        assert r1**2.1 + r2**2.1 == pytest.approx(2.1e-3**2.1, rel=1e-12)
    # Murray at every bifurcation: parent^gamma = sum of children^gamma.
    assert p.radius(7) ** 2.1 == pytest.approx(p.radius(3) ** 2.1 + p.radius(4) ** 2.1, rel=1e-12)


def test_flow_and_cost_tables_by_hand():
    p = coronary(n_terminals=10, n_inlets=1)
    t = physics.cost_tables(p)
    n = 4
    r = 2.1e-3 * (n / 10) ** (1 / 2.1)
    q = n * 4.16e-6 / 10
    assert t.flow[n] == pytest.approx(q)
    assert t.volume[n] == pytest.approx(641.3 * math.pi * r**2)
    assert t.resistance[n] == pytest.approx(8 * 3.6e-3 / (math.pi * r**4))
    assert t.power[n] == pytest.approx(q**2 * 8 * 3.6e-3 / (math.pi * r**4))
    assert t.exclusion[n] == pytest.approx(math.pi * r**2)  # r > r_cutoff = 0.01 mm
    assert np.all(t.array[:, 0] == 0)
    tiny = physics.cost_tables(coronary(n_terminals=10, n_inlets=1, r_cutoff=1.0))
    assert np.all(tiny.exclusion == 0)


def test_supply_radius_fills_tissue():
    v = 2.0566e-4
    r3 = physics.supply_radius(1000, v, 3)
    assert 1000 * 4 / 3 * math.pi * r3**3 == pytest.approx(v)
    # The paper's q_required = 2e-2 s^-1 with Q0 = 4.16e-6: (4/3) pi R^3 = Q_N / q.
    r_q = physics.supply_radius(1000, v, 3, q_required=2e-2, total_flow=4.16e-6)
    assert 4 / 3 * math.pi * r_q**3 == pytest.approx(4.16e-6 / 1000 / 2e-2)
    r2 = physics.supply_radius(64, 0.01, 2)
    assert 64 * math.pi * r2**2 == pytest.approx(0.01)


def test_volume_and_poiseuille_power_of_a_two_terminal_tree_by_hand():
    # Inlet at the origin, one bifurcation at (1, 0, 0) cm, terminals at (2, +-1, 0) cm.
    p = coronary(n_terminals=2, n_inlets=1, A_o=0.0, A_s=0.0)
    parent = np.array([-1, 3, 3, 0])
    children = np.array([[3, -1], [-1, -1], [-1, -1], [1, 2]])
    pos = np.array([[0, 0, 0], [0.02, 0.01, 0], [0.02, -0.01, 0], [0.01, 0, 0]], dtype=float)
    tree = Tree(parent, children, pos, np.array([2, 1, 1, 2]), 1)
    result = costs.full_costs(tree, None, p, costs.ActiveTerms((False, False, False)))
    r_root, r_leaf = 2.1e-3, 2.1e-3 * 2 ** (-1 / 2.1)
    leaf_len = math.sqrt(0.01**2 + 0.01**2)
    volume = math.pi * r_root**2 * 0.01 + 2 * math.pi * r_leaf**2 * leaf_len
    assert result["volume"] == pytest.approx(641.3 * volume, rel=1e-12)
    q0 = 4.16e-6
    power = q0**2 * 8 * 3.6e-3 * 0.01 / (math.pi * r_root**4) + 2 * (q0 / 2) ** 2 * 8 * 3.6e-3 * leaf_len / (
        math.pi * r_leaf**4
    )
    assert result["power"] == pytest.approx(power, rel=1e-12)
    assert result["total"] == pytest.approx(result["volume"] + result["power"], rel=1e-15)


@pytest.mark.parametrize("tissue", ["sphere", "box", "heart"])
def test_default_voxel_size_follows_the_supply_radius_also_with_q_required(tissue):
    """One formula for R_supply: the default voxel is R_supply / 4 whether or not q_required is given
    (without it, up to the voxelisation error of the volume: the voxel comes before the voxels)."""
    from helpers import make_problem

    for extra, rel in (([], 2e-2), (["tissue.q_required=0.05"], 1e-12)):
        problem = make_problem(f"tissue={tissue}", "n_terminals=200", "anneal.steps=10", *extra)
        assert problem.tissue.voxel_size == pytest.approx(problem.physics.supply_radius / 4.0, rel=rel)
    assert problem.physics.supply_radius == pytest.approx(
        (3.0 * 4.16e-6 / 200 / 0.05 / (4.0 * math.pi)) ** (1.0 / 3.0), rel=1e-12
    )


def test_viscosity_laws_against_pries_by_hand():
    """Both Pries fits at discharge hematocrit 0.45, divided by their large-vessel value 3.2,
    written out here once more from the papers' formulas."""
    d = np.array([5.0, 10.0, 20.0, 50.0, 100.0, 400.0])  # µm
    in_vitro = 220 * np.exp(-1.3 * d) + 3.2 - 2.44 * np.exp(-0.06 * d**0.645)
    w = (d / (d - 1.1)) ** 2
    in_vivo = (1 + (6 * np.exp(-0.085 * d) + 3.2 - 2.44 * np.exp(-0.06 * d**0.645) - 1) * w) * w
    diameter = d * 1e-6
    np.testing.assert_allclose(physics.relative_viscosity(diameter, "pries_in_vitro"), in_vitro / 3.2, rtol=1e-12)
    np.testing.assert_allclose(physics.relative_viscosity(diameter, "pries_in_vivo"), in_vivo / 3.2, rtol=1e-12)
    assert np.all(physics.relative_viscosity(diameter, "constant") == 1.0)
    # Fåhræus–Lindqvist: thinner blood from 400 down to 10 µm; in vivo the endothelial surface
    # layer makes capillaries more viscous than large vessels again.
    vitro = physics.relative_viscosity(diameter, "pries_in_vitro")
    assert np.all(np.diff(vitro[1:]) > 0) and vitro[1] == pytest.approx(0.415, abs=1e-3)
    assert physics.relative_viscosity(5e-6, "pries_in_vivo") > 3.0
    # The in-vivo fit relative to plasma: 5.87 at 10 µm, 2.53 at 100 µm.
    in_vivo_to_plasma = 3.2 * physics.relative_viscosity(np.array([10e-6, 100e-6]), "pries_in_vivo")
    np.testing.assert_allclose(in_vivo_to_plasma, [5.87, 2.53], atol=0.01)
    # Large vessels keep physics.viscosity (in vivo up to the (D / (D - 1.1))^2 factor, 1.0006 at 4 mm).
    for law in ("pries_in_vitro", "pries_in_vivo"):
        assert physics.relative_viscosity(4e-3, law) == pytest.approx(1.0, abs=2e-3)
    with pytest.raises(ValueError, match="physics.viscosity_law"):
        physics.relative_viscosity(diameter, "blood")


def test_viscosity_law_scales_resistance_and_power_only():
    constant = physics.cost_tables(coronary())
    for law in ("pries_in_vitro", "pries_in_vivo"):
        p = coronary(viscosity_law=law)
        varying = physics.cost_tables(p)
        n = np.arange(1, 1001)
        factor = physics.relative_viscosity(2 * p.radius(n), law)
        np.testing.assert_allclose(varying.resistance[1:], constant.resistance[1:] * factor, rtol=1e-12)
        np.testing.assert_allclose(varying.power[1:], constant.power[1:] * factor, rtol=1e-12)
        for row in (physics.TABLE_VOLUME, physics.TABLE_EXCLUSION, physics.TABLE_FLOW):
            np.testing.assert_array_equal(varying.array[row], constant.array[row])
        assert np.all(varying.array[:, 0] == 0)
        # The terminal segments (D ~ 156 µm at N = 1000, gamma 2.1) lose a sixth of their resistance.
        assert 0.6 < factor[0] < 0.9


def test_physics_attrs_keep_the_law_and_old_stores_read_as_constant():
    p = coronary(viscosity_law="pries_in_vivo")
    assert physics.Physics(**p.as_attrs()) == p
    old = {k: v for k, v in coronary().as_attrs().items() if k not in ("viscosity_law", "r_cutoff_ramp")}
    assert physics.Physics(**old) == coronary()
    assert (physics.Physics(**old).viscosity_law, physics.Physics(**old).r_cutoff_ramp) == ("constant", 0.0)


def test_exclusion_ramp_weights_the_exclusion_table():
    r = np.array([0.0, 1e-4, 2e-4, 2.5e-4, 3e-4, 4e-4, 5e-4])
    np.testing.assert_array_equal(physics.exclusion_weight(r, 2e-4, 0.0), [0, 0, 0, 1, 1, 1, 1])
    np.testing.assert_allclose(physics.exclusion_weight(r, 2e-4, 2e-4), [0, 0, 0, 0.25, 0.5, 1, 1])
    step = physics.cost_tables(coronary(r_cutoff=2e-4))
    p = coronary(r_cutoff=2e-4, r_cutoff_ramp=2e-4)
    ramp = physics.cost_tables(p)
    radius = p.radius(np.arange(1001))
    weight = np.clip((radius - 2e-4) / 2e-4, 0, 1)
    np.testing.assert_allclose(ramp.exclusion, np.pi * radius**2 * weight, rtol=1e-12)
    assert np.all(ramp.exclusion <= step.exclusion) and np.any((ramp.exclusion > 0) & (ramp.exclusion < step.exclusion))
    np.testing.assert_array_equal(ramp.exclusion[radius >= 4e-4], step.exclusion[radius >= 4e-4])
