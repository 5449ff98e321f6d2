"""Trunk centre-lines and their distances (the paper's consistency claim as a number)."""

import numpy as np
import pytest

from vasc_pipeline.reduce.similarity import main_trunks, resample_polyline, trunk_distance, trunk_spread


def two_inlet_tree(shift=0.0):
    """Inlet 0 at the origin: 0 -> 1 -> 3 along x, node 1 with a side terminal 6, node 3 with
    three terminals 2, 4, 5; inlet 7 feeding terminal 8. ``shift`` lifts everything along z."""
    parent = np.array([-1, 0, 3, 1, 3, 3, 1, -1, 7])
    kind = np.array([0, 1, 2, 1, 2, 2, 2, 0, 2], dtype=np.int8)
    position = np.array(
        [[0, 0, 0], [1, 0, 0], [2, 1, 0], [2, 0, 0], [2, -1, 0], [3, 0, 0], [1, 1, 0], [0, 2, 0], [0, 3, 0]],
        dtype=float,
    )
    position[:, 2] += shift
    return parent, position, kind


def test_main_trunk_follows_the_child_with_most_terminals_until_the_fraction():
    parent, position, kind = two_inlet_tree()
    # node 3 has three children (a trifurcation is fine); with fraction 1/2 the trunk stops
    # at 3: each of its children carries 1 of the inlet's 4 terminals
    trunk_a, trunk_b = main_trunks(parent, position, kind, fraction=0.5)
    assert trunk_a.tolist() == [[0, 0, 0], [1, 0, 0], [2, 0, 0]]
    assert trunk_b.tolist() == [[0, 2, 0], [0, 3, 0]]
    # with a small fraction it continues into the tie between 2, 4, 5: the lowest index, 2
    assert main_trunks(parent, position, kind, fraction=0.1)[0][-1].tolist() == [2, 1, 0]


def test_trunk_distance_of_parallel_and_identical_lines():
    a = [[0, 0, 0], [1, 0, 0], [3, 0, 0]]
    assert trunk_distance(a, a) == pytest.approx(0, abs=1e-15)
    assert trunk_distance(a, [[0, 0, 0.25], [3, 0, 0.25]]) == pytest.approx(0.25)
    # a point against a line: half the mean distance each way
    assert trunk_distance([[0, 1, 0]], [[0, 0, 0], [2, 0, 0]]) == pytest.approx(
        0.5 * (1 + np.mean(np.hypot(np.linspace(0, 2, 64), 1)))
    )
    line = resample_polyline(a, 4)
    np.testing.assert_allclose(line[:, 0], [0, 1, 2, 3])


def test_trunk_spread_over_pairs_of_trees():
    trees = [main_trunks(*two_inlet_tree(shift), fraction=0.5) for shift in (0.0, 0.1, 0.3)]
    np.testing.assert_allclose(trunk_spread(trees), [0.1, 0.3, 0.2])


def test_tortuosity_is_arc_over_chord():
    from vasc_pipeline.reduce.similarity import tortuosity

    assert tortuosity([[0, 0, 0], [1, 0, 0], [3, 0, 0]]) == pytest.approx(1.0)
    assert tortuosity([[0, 0, 0], [1, 1, 0], [2, 0, 0]]) == pytest.approx(np.sqrt(2))
    assert np.isnan(tortuosity([[1, 1, 1], [1, 1, 1]]))  # no chord
