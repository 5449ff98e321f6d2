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
