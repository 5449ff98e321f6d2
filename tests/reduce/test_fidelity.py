"""The fidelity measures of vasc_pipeline.reduce.fidelity on hand-built trees and datasets."""

import numpy as np
import pytest
import xarray as xr

from vasc_pipeline.reduce import anatomy, fidelity
from vasc_pipeline.reduce.reference import kassab_dataset

# Two inlets (LCA 0, RCA 1). The LCA's left main (0 -> 6) splits at 6 into a wide branch 7
# (terminals 2, 3) and a narrow one 8 (terminals 4, 5); the RCA feeds terminal 9 alone.
PARENT = np.array([-1, -1, 7, 7, 8, 8, 0, 6, 6, 1])
KIND = np.array([0, 0, 2, 2, 2, 2, 1, 1, 1, 2], dtype=np.int8)
RADIUS = np.array([0.0, 0.0, 1.0, 1.0, 0.8, 0.8, 3.0, 2.0, 1.5, 1.0]) * 1e-4
POSITION = np.array(
    [[0, 0, 0], [9, 0, 0], [-3, 4, 0], [-1, 4, 0], [2, 4, 0], [4, 4, 0], [0, 1, 0], [-2, 2, 0], [3, 2, 0], [9, 3, 0]],
    dtype=float,
)
TREE = {"parent": PARENT, "position": POSITION * 1e-3, "radius": RADIUS, "kind": KIND}


def test_inlet_shares_count_the_terminals_of_each_inlet():
    assert anatomy.inlet_shares(PARENT, KIND, ("LCA", "RCA")) == {"LCA": 0.8, "RCA": 0.2}


def test_a_subtree_gets_an_inlet_at_its_head_s_parent():
    sub = fidelity.subtree(TREE, 7)
    assert sub["parent"].tolist() == [-1, 3, 3, 0]  # inlet; terminals 2, 3; their bifurcation 7 (node order)
    assert sub["kind"].tolist() == [0, 2, 2, 1]
    np.testing.assert_array_equal(sub["position"][0], TREE["position"][6])
    np.testing.assert_array_equal(sub["radius"][1:], RADIUS[[2, 3, 7]])


def test_per_artery_trees_split_the_left_main_into_its_two_widest_branches():
    arteries = fidelity.per_artery_trees(TREE, ("LCA", "RCA"))
    assert sorted(arteries) == ["LAD", "LCX", "RCA"]
    np.testing.assert_array_equal(arteries["LAD"]["radius"][1:], RADIUS[[2, 3, 7]])  # the wider branch
    np.testing.assert_array_equal(arteries["LCX"]["radius"][1:], RADIUS[[4, 5, 8]])
    assert arteries["RCA"]["parent"].tolist() == [-1, 0]


def test_diameter_ratio_per_order_is_the_geometric_growth():
    assert fidelity.diameter_ratio_per_order([1, 2, 3, 4], [1.0, 2.0, 4.0, 8.0]) == pytest.approx(2.0)
    assert np.isnan(fidelity.diameter_ratio_per_order([3], [1.0]))
    lad = kassab_dataset().sel(artery="LAD", level="element").sel(order=slice(5, 11))
    assert fidelity.kassab_diameter_ratio() == fidelity.diameter_ratio_per_order(lad.order, lad.D_mean)  # orders 5-11
    assert fidelity.kassab_diameter_ratio() == pytest.approx(1.86, abs=0.005)


def test_terminal_aligned_puts_the_lowest_order_on_kassab_s_nearest_diameter():
    lad = kassab_dataset().sel(artery="LAD", level="element")
    target = int(lad.order.values[3])
    orders = np.arange(5, 12)
    counts = np.array([0, 10, 5, 3, 2, 1, 1])  # order 5 empty: the lowest present is 6
    diameters = np.full(orders.size, 1e-3)
    diameters[1] = float(lad.D_mean.sel(order=target))
    morph = xr.Dataset(
        {
            "element_count": (("scheme", "order"), counts[None, :]),
            "element_diameter_mean": (("scheme", "order"), diameters[None, :]),
        },
        coords={"scheme": ["diameter_defined"], "order": orders},
    )
    aligned, shift = fidelity.terminal_aligned(morph)
    assert shift == target - 6
    assert aligned.order.values.tolist() == (orders + shift).tolist()
