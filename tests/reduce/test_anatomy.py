"""The anatomy of a tree (vasc_pipeline.reduce.anatomy) against hand computations and plain twins."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vasc_pipeline.model.physics import Physics
from vasc_pipeline.model.topology import KIND_BIFURCATION, KIND_INLET, KIND_TERMINAL
from vasc_pipeline.reduce import anatomy as an

Q0, MU, R_IN, GAMMA = 4e-6, 3.6e-3, 2e-3, 2.1


def physics(n_terminals: int, n_inlets: int = 1) -> Physics:
    return Physics(n_terminals, n_inlets, GAMMA, R_IN, Q0, 641.3, MU, 1e-3)


def y_tree():
    """Inlet 0 at the origin, terminals 1 and 2, bifurcation 3 at x = 10 mm."""
    parent = np.array([-1, 3, 3, 0])
    position = np.array([[0, 0, 0], [0.02, 0.005, 0], [0.02, -0.01, 0], [0.01, 0, 0]], dtype=float)
    kind = np.array([KIND_INLET, KIND_TERMINAL, KIND_TERMINAL, KIND_BIFURCATION], dtype=np.int8)
    p = physics(2)
    n = np.array([0, 1, 1, 2])
    radius = np.where(n > 0, p.terminal_radius * n ** (1 / GAMMA), 0.0)
    return parent, position, radius, kind, p


def poiseuille_drop(length, radius, flow):
    return 8 * MU * length / (math.pi * radius**4) * flow


def test_terminal_pressures_are_the_poiseuille_drops_along_the_path():
    parent, position, radius, kind, p = y_tree()
    at_bifurcation = p.pressure_inlet - poiseuille_drop(0.01, radius[3], Q0)
    expected = [
        at_bifurcation - poiseuille_drop(np.linalg.norm(position[i] - position[3]), radius[i], Q0 / 2) for i in (1, 2)
    ]
    np.testing.assert_allclose(an.terminal_pressures(parent, position, p), expected, rtol=1e-12)
    a = an.anatomy(parent, position, radius, kind, p, ("root",))
    assert a["terminal_pressure_min"] == pytest.approx(min(expected), rel=1e-12)
    assert a["pressure_drop_mean"] == pytest.approx(p.pressure_inlet - np.mean(expected), rel=1e-12)
    assert a["inlet_share_root"] == 1.0 and a["terminals_below_zero"] == 0
    assert math.isnan(a["bifurcations_off_organ_share"])  # no organ given


def test_distance_outside_a_voxel_cube():
    h = 1e-3
    domain = np.zeros((10, 10, 10), dtype=bool)
    domain[2:5, 2:5, 2:5] = True  # voxels 2-4 on every axis
    origin = np.zeros(3)
    points = np.array([[3e-3, 3e-3, 3e-3], [8e-3, 3e-3, 3e-3], [3e-3, 3e-3, 15e-3]])
    np.testing.assert_allclose(an.distance_outside(points, domain, h, origin), [0.0, 4e-3, 11e-3])


def test_bifurcations_off_the_organ_are_counted_beyond_two_millimetres():
    parent, position, radius, kind, p = y_tree()
    h = 1e-3
    domain = np.zeros((5, 5, 40), dtype=bool)  # (z, y, x): a slab x in [0, 5] mm
    domain[:, :, :6] = True
    origin = np.array([0.0, -2e-3, -2e-3])
    a = an.anatomy(parent, position, radius, kind, p, ("root",), organ=domain, voxel_size=h, origin=origin)
    assert a["bifurcations_off_organ_share"] == 1.0  # the bifurcation at x = 10 mm lies 5 mm off
    assert a["bifurcations_off_organ_median_distance"] == pytest.approx(5e-3)
    domain[:, :, :9] = True  # the slab now reaches x = 8 mm: 2 mm off is still on the organ
    a = an.anatomy(parent, position, radius, kind, p, ("root",), organ=domain, voxel_size=h, origin=origin)
    assert a["bifurcations_off_organ_share"] == 0.0 and math.isnan(a["bifurcations_off_organ_median_distance"])


def random_tree(n_terminals: int, rng: np.random.Generator):
    """A random binary tree (one inlet), radii from the terminal counts, random positions."""
    parent = np.full(2 * n_terminals, -1)
    kind = np.full(2 * n_terminals, KIND_TERMINAL, dtype=np.int8)
    kind[0] = KIND_INLET
    roots = list(range(1, n_terminals + 1))  # terminals, joined pairwise into bifurcations
    nxt = n_terminals + 1
    while len(roots) > 1:
        i, j = sorted(rng.choice(len(roots), 2, replace=False))
        b, nxt = nxt, nxt + 1
        kind[b] = KIND_BIFURCATION
        parent[roots[i]] = parent[roots[j]] = b
        roots = [r for k, r in enumerate(roots) if k not in (i, j)] + [b]
    parent[roots[0]] = 0
    position = rng.uniform(0, 0.05, size=(parent.size, 3))
    n = np.zeros(parent.size, dtype=int)
    for t in range(1, n_terminals + 1):
        x = t
        while x > 0:
            n[x] += 1
            x = parent[x]
    radius = np.where(n > 0, 1e-4 * n ** (1 / GAMMA), 0.0)
    return parent, position, radius, kind, n


def test_crown_exponents_equal_a_plain_fit_over_explicit_subtrees():
    parent, position, radius, kind, n = random_tree(60, np.random.default_rng(3))
    length = np.r_[0.0, np.linalg.norm(position[1:] - position[parent[1:]], axis=1)]
    below = {v: {v} for v in range(parent.size)}
    for v in range(parent.size):  # every node into the crowns of all its ancestors' segments
        x = parent[v]
        while x > 0:
            below[x].add(v)
            x = parent[x]
    stems = [v for v in range(1, parent.size) if n[v] >= 2]
    crown_length = np.array([sum(length[u] for u in below[v]) for v in stems])
    crown_volume = np.array([sum(math.pi * radius[u] ** 2 * length[u] for u in below[v]) for v in stems])
    d = 2 * radius[stems]
    got = an.crown_exponents(parent, position, radius, kind)
    assert got["diameter_crown_length_exponent"] == pytest.approx(np.polyfit(np.log(crown_length), np.log(d), 1)[0])
    assert got["crown_volume_diameter_exponent"] == pytest.approx(np.polyfit(np.log(d), np.log(crown_volume), 1)[0])


def test_crown_exponents_of_a_tree_too_small_to_fit_are_nan():
    parent, position, radius, kind, _ = y_tree()
    assert all(math.isnan(v) for v in an.crown_exponents(parent, position, radius, kind).values())
