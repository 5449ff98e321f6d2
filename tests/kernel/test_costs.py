"""The kernel's geometric primitives against their plain NumPy twins and by hand."""

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import FAST_2026_12, make_problem

from vasc_pipeline import costs, engine, kernel, tissue


@pytest.fixture(scope="module")
def sphere_problem():
    return make_problem("tissue=sphere", "n_terminals=100", "anneal.steps=1000")


def random_points(problem, n, seed, spread=1.2):
    rs = np.random.default_rng(seed)
    r = problem.tissue.inlets[0][2]
    return rs.uniform(-spread * r, spread * r, (n, 3))


def test_voxel_pieces_sum_to_segment_length_and_match_fine_sampling():
    rs = np.random.default_rng(0)
    shape = (30, 30, 30)
    for _ in range(50):
        u0, u1 = rs.uniform(2, 27, 3), rs.uniform(2, 27, 3)
        idx, pieces = costs.voxel_pieces(u0, u1, shape)
        length = np.linalg.norm(u1 - u0)
        assert pieces.sum() == pytest.approx(length, rel=1e-12)
        # Fine sampling: the fraction of sample points in each voxel.
        t = (np.arange(200_000) + 0.5) / 200_000
        vox = np.floor(u0 + t[:, None] * (u1 - u0) + 0.5).astype(int)[:, ::-1]
        keys, counts = np.unique(vox, axis=0, return_counts=True)
        sampled = {tuple(k): c / t.size * length for k, c in zip(keys, counts)}
        exact = {}
        for k, p in zip(map(tuple, idx), pieces):
            exact[k] = exact.get(k, 0.0) + p
        for k, p in exact.items():
            assert sampled.get(k, 0.0) == pytest.approx(p, abs=2e-4 * length + 1e-9)


def test_voxel_pieces_axis_aligned_by_hand():
    idx, pieces = costs.voxel_pieces(np.array([0.0, 1.0, 1.0]), np.array([3.0, 1.0, 1.0]), (3, 3, 5))
    assert idx.tolist() == [[1, 1, 0], [1, 1, 1], [1, 1, 2], [1, 1, 3]]
    np.testing.assert_allclose(pieces, [0.5, 1.0, 1.0, 0.5], rtol=1e-12)


def test_kernel_traversal_equals_numpy_twin(sphere_problem):
    model, t = sphere_problem.model, sphere_problem.tissue
    pts = random_points(sphere_problem, 400, 1)
    for p0, p1 in zip(pts[::2], pts[1::2]):
        expected = costs.exclusion_sum(p0, p1, t)
        got = kernel.segment_exclusion(model, p0, p1)
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-300)
    # Axis-parallel and degenerate segments exercise the d == 0 branches.
    c = t.origin + 0.5 * t.voxel_size * np.array(t.shape[::-1])
    for d in (np.array([0.01, 0, 0]), np.array([0, 0.01, 0]), np.array([0, 0, 0.01]), np.zeros(3)):
        assert kernel.segment_exclusion(model, c - d, c + d) == pytest.approx(
            costs.exclusion_sum(c - d, c + d, t), rel=1e-12, abs=1e-300
        )


def test_capped_traversal_stops_at_the_first_voxel_past_the_cap(sphere_problem):
    """Below the cap the full sum, bit for bit; past it the prefix of the walk that first
    exceeds the cap (so never more than the full sum: a move rejected on it is rejected)."""
    model, t = sphere_problem.model, sphere_problem.tissue
    pts = random_points(sphere_problem, 600, 7)
    n_stopped = 0
    for p0, p1 in zip(pts[::2], pts[1::2]):
        full = kernel.segment_exclusion(model, p0, p1)
        assert kernel.segment_exclusion_capped(model, p0, p1, np.inf) == full
        assert kernel.segment_exclusion_capped(model, p0, p1, full) == full
        u0, u1 = ((p - t.origin) / t.voxel_size for p in (p0, p1))
        idx, pieces = costs.voxel_pieces(u0, u1, t.shape)
        terms = (t.distance[idx[:, 0], idx[:, 1], idx[:, 2]].astype(np.float64) * pieces) ** 6
        prefix = np.cumsum(terms[terms > 0])
        steps = np.flatnonzero(np.diff(prefix) > 1e-6 * prefix[1:])  # caps between clearly distinct prefixes
        for k in steps[:: max(1, steps.size // 4)]:
            cap = 0.5 * (prefix[k] + prefix[k + 1])
            got = kernel.segment_exclusion_capped(model, p0, p1, cap)
            assert cap < got <= full
            assert got == pytest.approx(prefix[k + 1], rel=1e-12)
            n_stopped += 1
    assert n_stopped > 100


def test_segment_outside_tissue_costs_nothing(sphere_problem):
    model, t = sphere_problem.model, sphere_problem.tissue
    lo, hi = t.bounds
    # Along an edge of the grid box: inside the grid, outside the tissue ball.
    p0 = lo + 1e-4
    p1 = np.array([hi[0] - 1e-4, lo[1] + 1e-4, lo[2] + 1e-4])
    assert kernel.segment_exclusion(model, p0, p1) == 0.0
    assert costs.exclusion_sum(p0, p1, t) == 0.0
    # Entirely outside the grid.
    assert kernel.segment_exclusion(model, hi + 1.0, hi + 2.0) == 0.0
    # Through the centre it costs something, and the exclusion grows with depth.
    assert kernel.segment_exclusion(model, np.array([-0.01, 0, 0]), np.array([0.01, 0, 0])) > 0


def test_leap_map_marks_exactly_the_blocks_without_domain_voxels():
    rs = np.random.default_rng(3)
    distance = np.zeros((21, 40, 35), dtype=np.float32)
    for z, y, x in rs.integers(0, (21, 40, 35), (6, 3)):
        distance[z, y, x] = rs.uniform(0.5, 3.0)
    leap = kernel.leap_map(distance)
    b = kernel.LEAP_BLOCK
    for z, y, x in np.ndindex(distance.shape):
        if distance[z, y, x] > 0:
            assert leap[z, y, x] == distance[z, y, x]
        else:
            corner = np.array([z, y, x]) // b * b
            block = distance[tuple(slice(c, c + b) for c in corner)]
            assert leap[z, y, x] == (0.0 if (block > 0).any() else -1.0)
    assert leap.dtype == np.float32 and leap.shape == distance.shape
    assert (leap < 0).any() and (leap == 0).any()
    assert (kernel.leap_map(np.zeros((5, 5, 5))) == -1.0).all()
    assert (kernel.leap_map(np.ones((5, 5, 5))) == 1.0).all()


def test_depth_fields_give_back_the_map_bit_for_bit():
    rs = np.random.default_rng(5)
    depth = kernel.leap_map(np.where(rs.random((20, 30, 40)) < 0.3, np.sqrt(rs.integers(1, 400, (20, 30, 40))), 0.0))
    fields = kernel.depth_fields(depth, np.zeros(3), 1.0)
    assert fields["depth_index"].dtype == np.uint16 and fields["depth_index"].shape == depth.shape
    assert fields["depth_values"].dtype == np.float32
    assert np.array_equal(fields["depth_values"][fields["depth_index"]].view(np.uint32), depth.view(np.uint32))
    # More distinct values than a uint16 can index: the index widens, the values stay exact.
    wide = rs.permutation(np.arange(70_000, dtype=np.float32)).reshape(7, 100, 100) / 7
    fields = kernel.depth_fields(wide, np.zeros(3), 1.0)
    assert fields["depth_index"].dtype == np.uint32
    assert np.array_equal(fields["depth_values"][fields["depth_index"]], wide)


def _two_balls(shape, centres, radii2):
    from scipy import ndimage

    z, y, x = np.indices(shape)
    domain = np.zeros(shape, dtype=bool)
    for (cx, cy, cz), r2 in zip(centres, radii2):
        domain |= (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2 < r2
    return ndimage.distance_transform_edt(domain).astype(np.float32)


@pytest.mark.parametrize(
    "distance",
    [
        _two_balls((40, 70, 90), [(20, 30, 20), (70, 50, 15)], [100, 50]),
        _two_balls((1, 70, 90), [(20, 30, 0), (47, 31, 0)], [100, 3]),  # one z layer, a ball against block faces
    ],
    ids=["3d", "2d"],
)
def test_traversal_leaping_empty_blocks_gives_the_walks_sum_to_the_bit(sphere_problem, distance):
    """Leaps over empty blocks must land where the voxel-by-voxel walk would, crossings and ties
    included: the sums over the leap map and over the plain map must be the same float. Voxel
    size 1 and origin 0 make plane coordinates exact, so ties between axes really occur."""
    plain = sphere_problem.model._replace(**kernel.depth_fields(distance, np.zeros(3), 1.0))
    assert (kernel.leap_map(distance) < 0).mean() > 0.5
    leap = plain._replace(**kernel.depth_fields(kernel.leap_map(distance), np.zeros(3), 1.0))
    rs = np.random.default_rng(4)
    b = kernel.LEAP_BLOCK
    size = np.array(distance.shape[::-1], dtype=float)
    lo, hi = -3.0, size + 2.0
    m = 3000
    starts = rs.uniform(lo, hi, (m, 3))
    on_faces = np.round(starts * 2) / 2  # endpoints on voxel faces and centres
    corners = rs.integers(0, size // b + 2, (m, 3)) * b - 0.5  # block corners (exact plane crossings)
    signs = rs.choice([-1.0, 1.0], (m, 3))
    lengths = rs.integers(1, 70, (m, 1)).astype(float)
    axis = np.eye(3)[rs.integers(0, 3, m)]  # along x, y or z
    flat = distance.shape[0] == 1
    if flat:
        starts[:, 2] = on_faces[:, 2] = corners[:, 2] = 0.0
        signs[:, 2] = 0.0
        axis[:, 2] = 0.0
    cases = [
        (starts, rs.uniform(lo, hi, (m, 3)) * ([1, 1, 0] if flat else 1)),
        (starts, starts + rs.normal(0, 8, (m, 3)) * ([1, 1, 0] if flat else 1)),
        (on_faces, on_faces + lengths * axis),
        (corners, corners + lengths * signs),  # diagonals through block corners
        (on_faces, on_faces + lengths * signs),
    ]
    n_nonzero = 0
    for p0s, p1s in cases:
        for p0, p1 in zip(p0s, p1s):
            for a, c in ((p0, p1), (p1, p0)):
                got = kernel.segment_exclusion(leap, a, c)
                assert got == kernel.segment_exclusion(plain, a, c)
                n_nonzero += got > 0
    assert n_nonzero > 1000  # the segments reach the domain, not only empty space
    # A diagonal entering the grid exactly at a block's corner, in the clipped first voxel
    # (where the clip's division and the walk's reciprocal can put the leap behind t).
    corner_map = np.zeros((1, 48, 48), dtype=np.float32)
    corner_map[0, 31, 47] = 2.0
    p0, p1 = np.array([86.5, 70.5, 0.0]), np.array([10.5, -5.5, 0.0])
    corner_leap = leap._replace(**kernel.depth_fields(kernel.leap_map(corner_map), np.zeros(3), 1.0))
    corner_plain = plain._replace(**kernel.depth_fields(corner_map, np.zeros(3), 1.0))
    assert kernel.segment_exclusion(corner_leap, p0, p1) == kernel.segment_exclusion(corner_plain, p0, p1)
    # A non-finite endpoint costs nothing, as in the walk (and does not leap forever).
    assert kernel.segment_exclusion(leap, np.array([np.nan, 5.0, 0.0]), np.array([10.0, 5.0, 0.0])) == 0.0
    assert kernel.segment_exclusion(leap, np.array([-np.inf, 5.0, 0.0]), np.array([10.0, 5.0, 0.0])) == 0.0
    # And the leap map's sums are the NumPy twin's (which knows nothing of leaps).
    grid = SimpleNamespace(distance=distance, origin=np.zeros(3), voxel_size=1.0, shape=distance.shape)
    for p0, p1 in zip(cases[0][0][:200], cases[0][1][:200]):
        expected = costs.exclusion_sum(p0, p1, grid)
        assert kernel.segment_exclusion(leap, p0, p1) == pytest.approx(expected, rel=1e-12, abs=1e-300)


def test_prefetching_ahead_changes_no_traversal_sum(sphere_problem):
    """The prefetch is a hint: with any lead (none, the default, one far past the map's end)
    every sum is the same float, for segments inside, across and outside the grid."""
    model = sphere_problem.model
    assert model.prefetch_lead == kernel.PREFETCH_LEAD > 0
    pts = random_points(sphere_problem, 600, 3, spread=2.0)
    leads = [model._replace(prefetch_lead=lead) for lead in (0.0, 1.0, 1e9)]
    n_nonzero = 0
    for p0, p1 in zip(pts[::2], pts[1::2]):
        got = kernel.segment_exclusion(model, p0, p1)
        assert all(kernel.segment_exclusion(m, p0, p1) == got for m in leads)
        n_nonzero += got > 0
    assert n_nonzero > 50


def test_prefetching_changes_no_run():
    """Both prefetches (the depth map ahead of a traversal, the count map's rows under a moving
    terminal's spheres) are hints: a short heart run on FAST_2026_12, coarse map and supply shells
    included, ends in the same arrays with them and without."""
    problem = make_problem("tissue=heart", "n_terminals=150", *FAST_2026_12, "anneal.steps=200000")
    assert problem.model.prefetch_supply and problem.coarse_model is not None
    final = []
    for fields in ({}, {"prefetch_lead": 0.0, "prefetch_supply": False}):
        p = dataclasses.replace(
            problem, model=problem.model._replace(**fields), coarse_model=problem.coarse_model._replace(**fields)
        )
        state = engine.initial_state(p, seed=2)
        engine.run_block(p, state, p.total_steps)
        final.append(engine.state_arrays(state))
    assert final[0]["counters"][kernel.COUNTER_TERMINAL_ACCEPTED] > 1000
    for name, value in final[0].items():
        np.testing.assert_array_equal(value, final[1][name], err_msg=name)


def test_supply_spheres_match_brute_force_voxel_for_voxel(sphere_problem):
    problem = sphere_problem
    state = engine.initial_state(problem, seed=5)
    k, n = problem.physics.n_inlets, problem.physics.n_terminals
    terminals = state.position[k : k + n]
    expected = costs.supply_counts(terminals, problem.tissue, problem.physics.supply_radius)
    got = np.where(state.supply < 0, 0, state.supply)
    np.testing.assert_array_equal(got, expected)
    assert np.all((state.supply < 0) == (problem.tissue.mask == 0))
    assert state.costs[kernel.SUPPLY] == costs.supply_cost(expected, problem.tissue.mask)


def test_supply_sphere_on_voxel_boundaries_and_centres():
    """Centres placed exactly on voxel centres and faces: ties at the radius decide identically."""
    problem = make_problem("tissue=box", "n_terminals=50", "anneal.steps=10", "tissue.voxel_size=0.001")
    t, model = problem.tissue, problem.model
    supply = np.where(t.mask == 1, 0, -1).astype(np.int32)
    centre = t.origin + t.voxel_size * np.array([20, 20, 10])
    for offset in ([0, 0, 0], [0.5, 0, 0], [0.5, 0.5, 0.5], [0.25, 0.5, 0]):
        p = centre + t.voxel_size * np.array(offset)
        supply[...] = np.where(t.mask == 1, 0, -1)
        kernel.supply_sphere(model, supply, p, 1)
        expected = costs.supply_counts(p[None], t, problem.physics.supply_radius)
        np.testing.assert_array_equal(np.where(supply < 0, 0, supply), expected)
        moved = p + t.voxel_size * np.array([0.5, 0.0, -0.5])
        delta = kernel.supply_move_delta(model, supply, p, moved)
        before = costs.supply_cost(np.where(supply < 0, 0, supply), t.mask)
        kernel.supply_move(model, supply, p, moved)
        after = np.where(supply < 0, 0, supply)
        np.testing.assert_array_equal(after, costs.supply_counts(moved[None], t, problem.physics.supply_radius))
        assert delta == costs.supply_cost(after, t.mask) - before


def test_kernel_pressures_match_numpy():
    problem = make_problem("tissue=box", "n_terminals=40", "anneal.steps=10", "physics.A_p=1e-6")
    state = engine.initial_state(problem, seed=2)
    tree = engine.tree_of(problem, state)
    p_ref = costs.node_pressures(tree, problem.physics)
    kernel.pressure_cost(problem.model, state)
    np.testing.assert_allclose(state.scratch_pressure[1:], p_ref[1:], rtol=1e-12)
    k, n = 1, 40
    c_p = np.sum((p_ref[k : k + n] - problem.physics.pressure_terminal) ** 2)
    assert state.costs[kernel.PRESSURE] == pytest.approx(c_p, rel=1e-12)
    # Terminals see lower pressure than the inlet, deeper ones lower still.
    assert np.all(p_ref[k : k + n] < problem.physics.pressure_inlet)


def _hollow_block(n=20, wall=6):
    """A block of tissue around a cubic cavity that is part of the exclusion domain."""
    mask = np.zeros((n, n, n), dtype=np.uint8)
    mask[2:-2, 2:-2, 2:-2] = 1
    cavity = np.zeros_like(mask)
    cavity[wall:-wall, wall:-wall, wall:-wall] = 1
    mask[cavity == 1] = 0
    return tissue.Tissue("block", mask, 1e-3, [0.0, 0.0, 0.0], [[0.0, 0.0, 0.0]], exclusion=cavity)


def test_cavity_share_is_the_large_vessels_length_inside_cavities():
    t = _hollow_block()
    assert t.cavity.sum() == 8**3 and np.all(t.exclusion >= t.mask)
    # the distance map sees the cavity as inside: deepest at the block's centre, not at the wall's
    assert t.distance[10, 10, 10] == t.distance.max() == 8.0
    h = t.voxel_size
    # node 0 inlet; node 1: a large vessel along x through the cavity (x = 1 .. 18 voxels, 8 inside);
    # node 2: a large vessel outside it; node 3: a small vessel through the cavity (not counted),
    # hanging from node 4, a small vessel outside it
    position = (
        np.array([[1.0, 10.0, 10.0], [18.0, 10.0, 10.0], [1.0, 1.0, 1.0], [10.0, 3.0, 10.0], [10.0, 17.0, 17.0]]) * h
    )
    parent = np.array([-1, 0, 0, 4, 2])
    radius = np.array([0.0, 1e-3, 1e-3, 1e-4, 1e-4])
    share = costs.cavity_share(parent, position, radius, t)
    assert share == pytest.approx(8.0 / (17.0 + 9.0 * math.sqrt(2.0)), rel=1e-12)
    # node 3 large too: x = 10, y 3 .. 17, z 10 .. 17 crosses the cavity (y, z in [5.5, 13.5]) for
    # y in [5.5, 13.5] while z = 10 + (y - 3) / 2 <= 13.5, i.e. y <= 10: a t-range of (10 - 5.5) / 14
    radius[3] = 1e-3
    length3 = math.hypot(14.0, 7.0)
    assert costs.cavity_share(parent, position, radius, t) == pytest.approx(
        (8.0 + 4.5 / 14.0 * length3) / (17.0 + 9.0 * math.sqrt(2.0) + length3), rel=1e-12
    )
    no_cavity = tissue.Tissue("block", t.mask, h, t.origin, t.inlets)
    assert math.isnan(costs.cavity_share(parent, position, radius, no_cavity))


def test_mask_tissue_takes_a_second_mask_for_its_exclusion_domain(tmp_path):
    t = _hollow_block()
    np.save(tmp_path / "tissue.npy", t.mask)
    np.save(tmp_path / "cavity.npy", t.cavity.astype(np.uint8) * 7)  # any nonzero value
    common = dict(voxel_size=1e-3, origin=[0.0, 0.0, 0.0], inlets=[[0.0, 0.0, 0.0]])
    loaded = tissue.build_tissue(
        "mask", 10, path=str(tmp_path / "tissue.npy"), exclusion_path=str(tmp_path / "cavity.npy"), **common
    )
    np.testing.assert_array_equal(loaded.exclusion, t.exclusion)
    np.testing.assert_array_equal(loaded.distance, t.distance)
    plain = tissue.build_tissue("mask", 10, path=str(tmp_path / "tissue.npy"), **common)
    np.testing.assert_array_equal(plain.exclusion, plain.mask)
    np.save(tmp_path / "wrong.npy", np.ones((4, 4, 4), dtype=np.uint8))
    with pytest.raises(tissue.TissueError, match=r"tissue\.exclusion_path: .*shape \(4, 4, 4\)"):
        tissue.build_tissue(
            "mask", 10, path=str(tmp_path / "tissue.npy"), exclusion_path=str(tmp_path / "wrong.npy"), **common
        )
    with pytest.raises(tissue.TissueError, match=r"tissue\.exclusion_path: mask file .* does not exist"):
        tissue.build_tissue(
            "mask", 10, path=str(tmp_path / "tissue.npy"), exclusion_path=str(tmp_path / "no.npy"), **common
        )


def test_vascular_exclusion_cost_is_the_total_without_supply_and_pressure(sphere_problem):
    physics = sphere_problem.physics
    terms = {"volume": 0.25, "power": 1.5, "exclusion": 3e-7, "pressure": 2e4, "supply": 900.0}
    w_o = physics.weights[0]
    assert w_o > 0
    expected = costs.total_cost({**terms, "supply": 0.0, "pressure": 0.0}, physics)
    assert costs.vascular_exclusion_cost(terms, w_o) == pytest.approx(expected, rel=1e-15)
    assert costs.vascular_exclusion_cost(terms, w_o) == pytest.approx(1.75 + w_o * 3e-7, rel=1e-15)
