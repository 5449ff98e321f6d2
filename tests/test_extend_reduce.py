"""The reduction of the whole tree (vasc_pipeline.reduce.extended): pass-through nodes (the annealed
terminals, kind 3) read as no branch point everywhere, the lumped 0D network against the full
tree's Poiseuille solution, every fine terminal's pressure reported, and the outputs.

Hand-built trees first; then one small extension (a CCO heart of 40 terminals, 10 fine ones
below each) made once in this module.
"""

from __future__ import annotations

import numpy as np
import pytest

from vasc_pipeline.model.costs import node_pressures, tree_pressures
from vasc_pipeline.model.physics import Physics
from vasc_pipeline.model.topology import KIND_TERRITORY_ROOT, check_tree_arrays, terminals_downstream
from vasc_pipeline.model.tree import tree_from_arrays
from vasc_pipeline.reduce.anatomy import crown_exponents, terminal_pressures
from vasc_pipeline.reduce.morphometry import morphometry, segment_lengths, strahler_orders

GAMMA = 2.1


# --------------------------------------------------------------------------------------------
# Hand-built trees


def random_tree(n_terminals: int, seed: int):
    """A random binary tree in the anneal's layout (inlet 0, terminals 1..N, bifurcations after),
    positions uniform in a 10 mm cube, Murray radii from the terminals downstream."""
    rs = np.random.default_rng(seed)
    n = n_terminals
    parent = np.full(2 * n, -1, dtype=np.int64)
    roots = list(range(1, n + 1))
    nxt = n + 1
    while len(roots) > 1:
        a = roots.pop(rs.integers(len(roots)))
        b = roots.pop(rs.integers(len(roots)))
        parent[a] = parent[b] = nxt
        roots.append(nxt)
        nxt += 1
    parent[roots[0]] = 0
    kind = np.full(2 * n, 1, dtype=np.int8)
    kind[0], kind[1 : n + 1] = 0, 2
    position = rs.uniform(0, 1e-2, (2 * n, 3))
    count = terminals_downstream(parent, kind)
    radius = np.where(parent >= 0, 1e-4 * count ** (1 / GAMMA), 0.0)
    return parent, position, radius, kind


def with_pass_through(parent, position, radius, kind, nodes, bend=0.0, seed=0):
    """The tree with a pass-through node (kind 3) inserted on the segment ending at each of
    ``nodes``, at its midpoint moved ``bend`` (m) off the chord: the whole tree's layout."""
    rs = np.random.default_rng(seed)
    nodes = np.asarray(nodes)
    new = np.arange(parent.size, parent.size + nodes.size)
    mid = 0.5 * (position[nodes] + position[parent[nodes]]) + bend * rs.normal(size=(nodes.size, 3))
    parent2 = np.concatenate([parent, parent[nodes]])
    parent2[nodes] = new
    return (
        parent2,
        np.concatenate([position, mid]),
        np.concatenate([radius, radius[nodes]]),
        np.concatenate([kind, np.full(nodes.size, KIND_TERRITORY_ROOT, np.int8)]),
    )


def test_a_pass_through_node_is_no_branch_point_for_the_orders_and_the_morphometry():
    tree = random_tree(60, seed=1)
    parent, position, radius, kind = tree
    segments = np.flatnonzero(parent >= 0)
    through = with_pass_through(*tree, segments[::3])  # on straight segments, at the midpoint
    check_tree_arrays(*through[:1], through[3], radius=through[2], position=through[1])
    n = parent.size
    np.testing.assert_array_equal(strahler_orders(through[0], through[3])[:n], strahler_orders(parent, kind))
    for reading in ("range", "confluence"):
        plain = morphometry(parent, position, radius, kind, reading=reading)
        ds = morphometry(*through, reading=reading)
        assert ds.attrs["n_pass_through"] == segments[::3].size and ds.attrs["n_segments"] == plain.attrs["n_segments"]
        for name, var in plain.drop_dims("node").data_vars.items():
            np.testing.assert_allclose(ds[name].values, var.values, rtol=1e-12, err_msg=f"{reading} {name}")
        order = ds.segment_order.values
        np.testing.assert_array_equal(order[:, :n], plain.segment_order.values)
        np.testing.assert_array_equal(order[:, n:], order[:, segments[::3]])  # the order of the vessel it lies on


def test_a_bent_vessel_through_a_pass_through_node_is_as_long_as_its_two_pieces():
    tree = random_tree(30, seed=2)
    through = with_pass_through(*tree, np.flatnonzero(tree[3] == 2), bend=2e-3)
    ds = morphometry(*through, top=None)
    total = segment_lengths(through[0], through[1]).sum()  # every piece once: no vessel is cut short
    assert ds.attrs["n_segments"] == np.count_nonzero(tree[0] >= 0)
    for level in ("element", "segment"):
        summed = (ds[f"{level}_length_mean"] * ds[f"{level}_count"]).fillna(0).sum("order")
        np.testing.assert_allclose(summed.values, total, rtol=1e-12, err_msg=level)


def test_pass_through_nodes_leave_pressures_and_crown_exponents_as_they_were():
    parent, position, radius, kind = random_tree(50, seed=3)
    p = Physics(50, 1, GAMMA, 2e-3, 4e-6, 641.3, 3.6e-3, 1e-3)
    plain = node_pressures(tree_from_arrays(parent, position, 1), p)
    np.testing.assert_array_equal(tree_pressures(parent, position, p), plain)  # the same sums, bit for bit
    through = with_pass_through(parent, position, radius, kind, np.flatnonzero(kind == 2))
    pressure = tree_pressures(through[0], through[1], p)
    np.testing.assert_allclose(pressure[: parent.size], plain, rtol=1e-12)
    np.testing.assert_allclose(terminal_pressures(through[0], through[1], p), plain[kind == 2], rtol=1e-12)
    a, b = crown_exponents(parent, position, radius, kind), crown_exponents(*through)
    for name in a:
        assert b[name] == pytest.approx(a[name], rel=1e-9), name


@pytest.mark.parametrize(
    "change, message",
    [("two children", "pass-through node 1"), ("chained", "hangs from pass-through node")],
)
def test_pass_through_nodes_that_are_not_are_refused(change, message):
    tree = random_tree(8, seed=4)
    parent, position, radius, kind = with_pass_through(*tree, [1, 2])
    if change == "two children":
        parent[3] = parent[1]  # terminal 3 now hangs from the pass-through node above 1 too
    else:  # a pass-through node on the segment of another one
        parent, position, radius, kind = with_pass_through(parent, position, radius, kind, [parent[1]])
    with pytest.raises(ValueError, match=message):
        check_tree_arrays(parent, kind, radius=radius, position=position)
