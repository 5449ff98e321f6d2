"""The ``surface`` tissue: closed surface meshes (STL, OBJ, PLY, VTP) as the organ, with cavities.

Every surface here is written by the test (trimesh's icospheres, the model heart by marching
cubes) and read back through the config, as a user's segmentation would be.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from helpers import assert_running_equals_full, make_problem

from vasc_pipeline import config, engine, job, store, sweep, tissue
from vasc_pipeline.config import ConfigError
from vasc_pipeline.model.tissue import surfaces

trimesh = pytest.importorskip("trimesh")

R_OUTER, R_INNER = 0.02, 0.008  # m: a ball of tissue around a spherical cavity off its centre
CAVITY_CENTRE = (0.004, 0.0, 0.0)
INLET = [0.0, 0.0, 0.021]  # just above the north pole


def ball_surfaces(directory, suffix: str = ".stl") -> tuple[str, str]:
    """(outer, cavity) icospheres written as ``suffix``."""
    outer = trimesh.creation.icosphere(subdivisions=4, radius=R_OUTER)
    inner = trimesh.creation.icosphere(subdivisions=3, radius=R_INNER)
    inner.apply_translation(CAVITY_CENTRE)
    paths = []
    for name, mesh in (("organ", outer), ("cavity", inner)):
        paths.append(str(surfaces.write_surface(directory / f"{name}{suffix}", mesh.vertices, mesh.faces)))
    return paths[0], paths[1]


def surface_overrides(organ, cavity=None, *extra: str) -> list[str]:
    return [
        "tissue=surface",
        f"tissue.path={organ}",
        *([f"tissue.cavity_paths=[{cavity}]"] if cavity else []),
        f"tissue.inlets=[[{INLET[0]!r},{INLET[1]!r},{INLET[2]!r}]]",
        "n_terminals=24",
        "anneal.steps=4000",
        "anneal.trace_every=2000",
        *extra,
    ]


def test_every_format_gives_the_same_voxels_inside_the_surfaces(tmp_path):
    grids = {}
    for suffix in (".stl", ".obj", ".ply", ".vtp"):
        organ, cavity = ball_surfaces(tmp_path, suffix)
        t = tissue.build_tissue("surface", 24, path=organ, cavity_paths=[cavity], inlets=[INLET])
        grids[suffix] = t
    first = grids[".stl"]
    for t in grids.values():
        np.testing.assert_array_equal(t.mask, first.mask)
        np.testing.assert_array_equal(t.exclusion, first.exclusion)
        np.testing.assert_allclose(t.origin, first.origin, rtol=0, atol=1e-9)  # STL holds float32 coordinates
    # every voxel centre tested against the spheres themselves (the icospheres' facets lie within
    # 0.3 % of the radius: only centres that close to a sphere may differ)
    k, j, i = np.indices(first.shape)
    p = first.origin + first.voxel_size * np.stack([i, j, k], axis=-1)
    r_out = np.linalg.norm(p, axis=-1)
    r_in = np.linalg.norm(p - CAVITY_CENTRE, axis=-1)
    sure = (np.abs(r_out - R_OUTER) > 0.004 * R_OUTER) & (np.abs(r_in - R_INNER) > 0.004 * R_INNER)
    expected = (r_out < R_OUTER) & (r_in > R_INNER)
    np.testing.assert_array_equal(first.mask.astype(bool)[sure], expected[sure])
    np.testing.assert_array_equal(first.cavity[sure], (r_in < R_INNER)[sure])
    assert first.name == "surface" and first.inlets.tolist() == [INLET]
    # the default voxel: R_supply / 4 of the volume between the surfaces
    volume = 4 / 3 * math.pi * (R_OUTER**3 - R_INNER**3)
    assert first.voxel_size == pytest.approx(tissue.default_voxel_size(24, volume, 3), rel=0.01)
    assert first.measure == pytest.approx(volume, rel=0.02)


def test_mesh_unit_scales_the_coordinates(tmp_path):
    outer = trimesh.creation.icosphere(subdivisions=3, radius=R_OUTER * 1e3)  # in mm
    path = surfaces.write_surface(tmp_path / "mm.stl", outer.vertices, outer.faces)
    message = r"tissue\.path: .* is 40 m across with tissue\.mesh_unit=m, .*set tissue\.mesh_unit"
    with pytest.raises(tissue.TissueError, match=message):
        tissue.build_tissue("surface", 24, path=str(path), inlets=[INLET])
    t = tissue.build_tissue("surface", 24, path=str(path), mesh_unit="mm", inlets=[INLET])
    assert t.measure == pytest.approx(4 / 3 * math.pi * R_OUTER**3, rel=0.03)


@pytest.fixture(scope="module")
def heart_surfaces(tmp_path_factory):
    return surfaces.write_heart_surfaces(tmp_path_factory.mktemp("heart") / "heart.stl")


def test_the_heart_written_as_surfaces_reads_back_as_the_heart(heart_surfaces):
    organ, cavities, inlets_path = heart_surfaces
    for path in (organ, *cavities):
        assert trimesh.load(str(path)).is_watertight
    heart = tissue.build_tissue("heart", 200)
    back = tissue.build_tissue(
        "surface", 200, path=str(organ), cavity_paths=[str(c) for c in cavities], inlets_path=str(inlets_path)
    )
    assert back.measure == pytest.approx(heart.measure, rel=0.01)  # myocardium
    assert back.cavity.sum() * back.voxel_size**3 == pytest.approx(heart.cavity.sum() * heart.voxel_size**3, rel=0.01)
    assert back.inlet_names == ("LCA", "RCA")
    np.testing.assert_allclose(back.inlets, heart.inlets, rtol=0, atol=1e-15)
    assert back.shape == heart.shape
    # on the heart's own grid the two voxelisations differ only where a voxel centre lies within the
    # marching cubes' error of a surface
    same = tissue.build_tissue(
        "surface",
        200,
        path=str(organ),
        cavity_paths=[str(c) for c in cavities],
        inlets_path=str(inlets_path),
        voxel_size=heart.voxel_size,
    )
    differ = np.count_nonzero(same.mask != heart.mask) if same.shape == heart.shape else None
    assert differ is not None and differ < 0.02 * heart.n_tissue_voxels


def test_a_run_on_surfaces_end_to_end_with_its_inputs_in_its_identity(tmp_path):
    organ, cavity = ball_surfaces(tmp_path)
    cfg = config.compose(surface_overrides(organ, cavity, f"output_dir={tmp_path / 'out'}"))
    problem = engine.build_problem(cfg)
    assert problem.tissue.cavity.any() and problem.tissue.n_tissue_voxels > 0
    state = engine.initial_state(problem, seed=0)
    engine.run_block(problem, state, 4000)
    assert_running_equals_full(problem, state)
    (j,) = sweep.expand(cfg)
    inputs = j.config["inputs"]
    assert set(inputs) == {"tissue.path", "tissue.cavity_paths[0]"}
    assert job.run_job(j)["status"] == "complete"
    run = store.RunStore.open(j.store, mode="r")
    assert run.group["tissue"]["mask"].shape == problem.tissue.shape
    from vasc_pipeline.pipeline.reduction import reduce_and_draw

    result = reduce_and_draw(tmp_path / "out", stream=None)
    assert (tmp_path / "out" / "trees" / f"{j.run_id}.vtp").is_file()
    assert list((tmp_path / "out" / "figures").glob("*.png"))
    assert result is not None
    # the cavity's file changed in place: the stored run is a different run, refused by the file's key
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.9 * R_INNER)
    surfaces.write_surface(cavity, mesh.vertices, mesh.faces)
    (changed,) = sweep.expand(cfg)
    diff = store.config_differences(j.config, changed.config)
    assert len(diff) == 1 and diff[0].startswith(f"tissue.cavity_paths[0]: the content of {cavity!r} differs")


def test_one_inlet_on_a_surface_is_another_organ_than_the_heart():
    assert config.organ_of("surface", None, 1) == "other"
    assert config.organ_of("surface", None, 2) == "heart"


def _open_box(path):
    box = trimesh.creation.box(extents=[0.02, 0.02, 0.02])
    return surfaces.write_surface(path, box.vertices, box.faces[:-2])


@pytest.mark.parametrize(
    "make, keys, message",
    [
        (lambda d: None, {"path": "{d}/absent.stl"}, r"tissue\.path: surface file '.*absent\.stl' does not exist"),
        (
            lambda d: (d / "organ.txt").write_text("solid\n"),
            {"path": "{d}/organ.txt"},
            r"tissue\.path: '.*organ\.txt' is not a surface this reads; accepted: closed triangle surfaces as STL",
        ),
        (
            lambda d: (d / "organ.stl").write_text("this is no STL at all\n"),
            {"path": "{d}/organ.stl"},
            r"tissue\.path: '.*organ\.stl' holds no triangle",
        ),
        (
            lambda d: (d / "organ.vtp").write_text("<VTKFile broken"),
            {"path": "{d}/organ.vtp"},
            r"tissue\.path: '.*organ\.vtp' is not a readable VTK XML PolyData surface",
        ),
        (
            lambda d: _open_box(d / "open.ply"),
            {"path": "{d}/open.ply"},
            r"tissue\.path: the surface '.*open\.ply' is not closed \(\d+ of its edges border one triangle",
        ),
        (
            lambda d: ball_surfaces(d),
            {"path": "{d}/organ.stl", "cavity_paths": ["{d}/absent.obj"]},
            r"tissue\.cavity_paths\[0\]: surface file '.*absent\.obj' does not exist",
        ),
        (
            lambda d: (ball_surfaces(d), _moved_cavity(d)),
            {"path": "{d}/organ.stl", "cavity_paths": ["{d}/cavity.stl", "{d}/moved.stl"]},
            r"tissue\.cavity_paths\[1\]: the cavity '.*moved\.stl' reaches outside the organ's surface",
        ),
        (
            lambda d: _slab(d / "organ.stl"),
            {"path": "{d}/organ.stl", "voxel_size": 0.004},
            r"tissue\.path: no voxel centre lies inside the surface '.*organ\.stl' .* set a smaller tissue\.voxel_size",
        ),
        (
            lambda d: ball_surfaces(d),
            {"path": "{d}/organ.stl", "inlets": None},
            r"tissue\.inlets .* or tissue\.inlets_path is required for tissue=surface",
        ),
    ],
    ids=[
        "missing",
        "format",
        "damaged-stl",
        "damaged-vtp",
        "open",
        "missing-cavity",
        "cavity-outside",
        "empty",
        "inlets",
    ],
)
def test_bad_surfaces_are_refused_naming_the_key_and_the_file(tmp_path, make, keys, message):
    make(tmp_path)
    params = {"inlets": [INLET]}
    for key, value in keys.items():
        params[key] = [v.format(d=tmp_path) for v in value] if isinstance(value, list) else value
        if isinstance(value, str):
            params[key] = value.format(d=tmp_path)
    with pytest.raises(tissue.TissueError, match=message):
        tissue.build_tissue("surface", 24, **params)


def _slab(path):
    """A slab 1 mm thin, between the voxel centres of a 4 mm grid."""
    slab = trimesh.creation.box(extents=[0.02, 0.02, 0.001])
    return surfaces.write_surface(path, slab.vertices, slab.faces)


def _moved_cavity(directory):
    inner = trimesh.creation.icosphere(subdivisions=3, radius=R_INNER)
    inner.apply_translation([R_OUTER, 0.0, 0.0])  # half of it outside the organ
    return surfaces.write_surface(directory / "moved.stl", inner.vertices, inner.faces)


def test_bad_surface_keys_are_refused_before_any_job(tmp_path):
    organ, cavity = ball_surfaces(tmp_path)
    with pytest.raises(ConfigError, match=r"tissue\.mesh_unit must be one of m, cm, mm, um, got 'inch'"):
        config.compose(surface_overrides(organ, None, "tissue.mesh_unit=inch"))
    with pytest.raises(ConfigError, match=r"tissue\.cavity_paths must be a non-empty list"):
        config.compose(surface_overrides(organ, None, "tissue.cavity_paths=[]"))
    with pytest.raises(ConfigError, match=r"tissue\.cavity_paths is read by tissue=surface only"):
        config.compose(["tissue=sphere", f"tissue.cavity_paths=[{cavity}]"])
    # a surface's voxel coarser than its supply sphere, as for every tissue
    with pytest.raises(tissue.TissueError, match=r"coarser than the supply sphere"):
        make_problem(*surface_overrides(organ, cavity, "tissue.voxel_size=0.008"))


def test_the_heart_surfaces_command_writes_what_tissue_surface_reads(tmp_path):
    from vasc_pipeline.model.tissue.__main__ import main

    assert main([str(tmp_path / "h.vtp")]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["h.inlets.json", "h.lv.vtp", "h.rv.vtp", "h.vtp"]
    assert set(json.loads((tmp_path / "h.inlets.json").read_text())) == {"LCA", "RCA"}
    organ = surfaces.read_surface(tmp_path / "h.vtp")
    assert organ.is_watertight and abs(organ.volume) == pytest.approx(3.87e-4, rel=0.01)  # myocardium + cavities
