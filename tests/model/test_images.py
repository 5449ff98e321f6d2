"""Segmentations in: NIfTI and NRRD label maps as tissue=mask (spacing, origin and orientation
from the header, labels by role, inlets from a file), the shipped heart written as a label map
and read back into the same tissue, and the refusals (anisotropic, oblique, contradicting keys)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from helpers import ENV, REPO, make_problem

from vasc_pipeline.config import ConfigError
from vasc_pipeline.model.tissue import TissueError, build_tissue
from vasc_pipeline.model.tissue import images as img

nibabel = pytest.importorskip("nibabel", reason="nibabel (pip install -e '.[test]') reads NIfTI")
nrrd = pytest.importorskip("nrrd", reason="pynrrd (pip install -e '.[test]') reads NRRD")

H = 2e-3  # m
ORIGIN = np.array([-0.01, 0.02, 0.005])  # m, [x, y, z] of voxel [0, 0, 0]'s centre


def labels_zyx() -> np.ndarray:
    """A small asymmetric label map (z, y, x): 1 = tissue shell, 2 = a cavity inside it."""
    z, y, x = np.mgrid[0:9, 0:11, 0:13]
    r = np.sqrt((x - 6.0) ** 2 + ((y - 5.0) * 1.2) ** 2 + ((z - 4.0) * 1.4) ** 2)
    out = np.where(r <= 5.0, 1, 0).astype(np.uint8)
    out[r <= 2.5] = 2
    out[0, 0, 0] = 0
    out[8, 10, 12] = 0
    return out


def mask_tissue(path, **labels):
    return build_tissue("mask", 20, path=str(path), inlets=[[0.0, 0.03, 0.02]], labels=labels or None)


def test_a_nifti_label_map_gives_its_spacing_origin_and_labels(tmp_path):
    path = img.write_label_map(tmp_path / "m.nii.gz", labels_zyx(), H, ORIGIN)
    data, h, origin = img.read_label_map(path)
    np.testing.assert_array_equal(data, labels_zyx())
    assert h == pytest.approx(H, rel=1e-6)  # float32 in the header
    np.testing.assert_allclose(origin, ORIGIN, rtol=0, atol=1e-8)
    t = mask_tissue(path, supply=[1], exclusion=[2])
    np.testing.assert_array_equal(t.mask, labels_zyx() == 1)
    np.testing.assert_array_equal(t.cavity, labels_zyx() == 2)
    assert t.voxel_size == pytest.approx(H) and np.allclose(t.origin, ORIGIN)


def test_flipped_and_permuted_axes_give_the_same_tissue(tmp_path):
    """The same image stored with x flipped and the axes in (y, x, z) order: reoriented on reading."""
    xyz = labels_zyx().transpose(2, 1, 0)  # indexed (x, y, z)
    n = xyz.shape
    stored = np.flip(xyz, axis=0).transpose(1, 0, 2)  # index (j, i, k) = (y, x flipped, z)
    affine = np.zeros((4, 4))
    affine[3, 3] = 1.0
    affine[1, 0] = H * 1e3  # index axis 0 runs along +y
    affine[0, 1] = -H * 1e3  # index axis 1 runs along -x
    affine[2, 2] = H * 1e3
    affine[:3, 3] = (ORIGIN + [(n[0] - 1) * H, 0.0, 0.0]) * 1e3  # voxel [0, 0, 0] is the largest x
    image = nibabel.Nifti1Image(stored, affine)
    image.header.set_xyzt_units("mm")
    nibabel.save(image, tmp_path / "turned.nii")
    data, h, origin = img.read_label_map(tmp_path / "turned.nii")
    np.testing.assert_array_equal(data, labels_zyx())
    np.testing.assert_allclose(origin, ORIGIN, atol=1e-8)


def test_an_nrrd_in_lps_gives_the_same_tissue_as_the_nifti(tmp_path):
    xyz = labels_zyx().transpose(2, 1, 0)
    lps_origin = ORIGIN * [-1.0, -1.0, 1.0] * 1e3  # mm; LPS = RAS with x and y negated
    header = {
        "space": "left-posterior-superior",
        "space directions": np.diag([-H * 1e3, -H * 1e3, H * 1e3]),  # +i along RAS +x is LPS -x
        "space origin": lps_origin,
    }
    nrrd.write(str(tmp_path / "m.nrrd"), xyz, header)
    data, h, origin = img.read_label_map(tmp_path / "m.nrrd")
    np.testing.assert_array_equal(data, labels_zyx())
    assert h == pytest.approx(H, rel=1e-12)
    np.testing.assert_allclose(origin, ORIGIN, atol=1e-12)


def test_anisotropic_and_oblique_images_are_refused_with_their_geometry(tmp_path):
    xyz = labels_zyx().transpose(2, 1, 0)
    nibabel.save(nibabel.Nifti1Image(xyz, np.diag([2.0, 2.0, 3.0, 1.0])), tmp_path / "aniso.nii")
    with pytest.raises(TissueError, match=r"tissue\.path: .*anisotropic voxels, 2 x 2 x 3 mm"):
        img.read_label_map(tmp_path / "aniso.nii")
    c, s = np.cos(0.3), np.sin(0.3)
    rotated = np.eye(4)
    rotated[:2, :2] = [[2 * c, -2 * s], [2 * s, 2 * c]]
    rotated[2, 2] = 2.0
    nibabel.save(nibabel.Nifti1Image(xyz, rotated), tmp_path / "oblique.nii")
    with pytest.raises(TissueError, match=r"oblique grid .* 17 degrees"):
        img.read_label_map(tmp_path / "oblique.nii")


def test_the_shipped_heart_round_trips_through_a_label_map(tmp_path):
    code = subprocess.run(
        [sys.executable, "-m", "vasc_pipeline.model.tissue", str(tmp_path / "heart.nii.gz"), "200"],
        env=ENV, cwd=REPO, capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert code.returncode == 0, code.stderr
    assert "Warning" not in code.stderr, code.stderr  # runpy's "found in sys.modules" above all
    assert code.stdout.split() == [str(tmp_path / "heart.nii.gz"), str(tmp_path / "heart.inlets.json")]
    inlets = tmp_path / "heart.inlets.json"
    assert set(json.loads(inlets.read_text())) == {"LCA", "RCA"}
    heart = build_tissue("heart", 200)
    back = build_tissue(
        "mask",
        200,
        path=str(tmp_path / "heart.nii.gz"),
        labels={"supply": [1], "exclusion": [2], "open": [3]},
        inlets_path=str(inlets),
    )
    np.testing.assert_array_equal(back.mask, heart.mask)
    np.testing.assert_array_equal(back.exclusion, heart.exclusion)
    np.testing.assert_array_equal(back.distance, heart.distance)  # the open base as well
    # NIfTI keeps its geometry in float32 (mm): the same grid to 1e-7 of a voxel
    assert back.voxel_size == pytest.approx(heart.voxel_size, rel=1e-6)
    np.testing.assert_allclose(back.origin, heart.origin, rtol=0, atol=1e-8)
    np.testing.assert_allclose(back.inlets, heart.inlets, rtol=0, atol=1e-15)
    assert back.inlet_names == heart.inlet_names


def test_a_run_on_a_label_map_through_the_config(tmp_path):
    path = img.write_label_map(tmp_path / "m.nii.gz", labels_zyx(), H, ORIGIN)
    (tmp_path / "inlets.csv").write_text("name,x,y,z\nroot,0.002,0.03,0.021\n")  # just above the shell
    problem = make_problem(
        "tissue=mask",
        f"tissue.path={path}",
        "tissue.labels.supply=[1]",
        "tissue.labels.exclusion=[2]",
        f"tissue.inlets_path={tmp_path / 'inlets.csv'}",
        "n_terminals=12",
        "anneal=fast_v1",
        "anneal.steps=2000",
    )
    assert problem.tissue.inlet_names == ("root",) and problem.tissue.cavity.sum() == (labels_zyx() == 2).sum()


def test_bad_labels_and_contradicting_keys_name_the_field(tmp_path):
    path = img.write_label_map(tmp_path / "m.nii.gz", labels_zyx(), H, ORIGIN)
    base = ("tissue=mask", f"tissue.path={path}", "tissue.inlets=[[0.0,0.03,0.02]]", "n_terminals=12")
    with pytest.raises(ConfigError, match=r"tissue\.labels: label 2 is both supply and exclusion"):
        make_problem(*base, "tissue.labels.supply=[1,2]", "tissue.labels.exclusion=[2]")
    with pytest.raises(ConfigError, match=r"tissue\.labels\.open must be a non-empty list"):
        make_problem(*base, "tissue.labels.open=[]")
    with pytest.raises(TissueError, match=r"tissue\.labels\.supply: no voxel .* holds the labels \[7\]"):
        make_problem(*base, "tissue.labels.supply=[7]")
    with pytest.raises(TissueError, match=r"tissue\.voxel_size=0\.001 contradicts the header"):
        make_problem(*base, "tissue.voxel_size=0.001")
    with pytest.raises(ConfigError, match=r"tissue\.labels is read by tissue=mask only"):
        make_problem("tissue=sphere", "tissue.labels.supply=[1]")


# -- inputs that read badly or passed silently ---------------------------------------------


def test_a_file_of_no_format_read_lists_the_formats(tmp_path):
    script = tmp_path / "make.py"
    script.write_text("print('not a mask')\n")
    folder = tmp_path / "scans"
    folder.mkdir()
    for path in (script, folder):
        with pytest.raises(TissueError) as err:
            make_problem("tissue=mask", f"tissue.path={path}", "tissue.voxel_size=1e-3", "tissue.inlets=[[0,0,0]]")
        text = str(err.value)
        assert text.startswith(f"tissue.path: {str(path)!r} is ") and "No group found" not in text, text
        for accepted in (".npy", "Zarr", ".nii.gz", ".nrrd"):
            assert accepted in text, text


def test_a_damaged_label_map_says_so(tmp_path):
    good = img.write_label_map(tmp_path / "m.nii.gz", labels_zyx(), H, ORIGIN)
    nrrd.write(str(tmp_path / "m.nrrd"), labels_zyx().transpose(2, 1, 0), {"space directions": np.eye(3) * 2.0})
    raw = (tmp_path / "m.nrrd").read_bytes()
    cases = {
        "cut.nrrd": raw[: raw.index(b"sizes")] + b"sizes 13\n",  # a header line without its colon
        "half.nrrd": raw[: len(raw) // 2],
        "cut.nii.gz": good.read_bytes()[:100],
    }
    for name, content in cases.items():
        (tmp_path / name).write_bytes(content)
        kind = "NRRD" if name.endswith(".nrrd") else "NIfTI"
        with pytest.raises(TissueError) as err:
            make_problem("tissue=mask", f"tissue.path={tmp_path / name}", "tissue.inlets=[[0,0,0]]")
        text = str(err.value)
        assert f"tissue.path: {str(tmp_path / name)!r} is not a readable {kind} label map" in text, text
        assert "damaged" in text and "truncated" in text, text


def test_an_inlet_from_a_file_outside_the_grid_names_the_file_in_mm(tmp_path):
    path = img.write_label_map(tmp_path / "m.nii.gz", labels_zyx(), H, ORIGIN)
    inlets = tmp_path / "ostia.json"
    inlets.write_text(json.dumps({"LCA": [-0.03, 0.03, 0.013]}))  # x far left of the grid
    with pytest.raises(TissueError) as err:
        make_problem("tissue=mask", f"tissue.path={path}", f"tissue.inlets_path={inlets}", "n_terminals=12")
    text = str(err.value)
    where = f"tissue.inlets_path ({str(inlets)!r}): inlet 0 (LCA) at [-30, 30, 13] mm lies outside"
    assert text.startswith(where), text
    assert "0.030000000000000002" not in text and "box, x [-11, 15], y [19, 41], z [4, 22] mm" in text, text


@pytest.mark.parametrize("role", ["exclusion", "open"])
def test_labels_absent_from_the_map_are_refused_in_every_role(tmp_path, role):
    path = img.write_label_map(tmp_path / "m.nii.gz", labels_zyx(), H, ORIGIN)
    base = ("tissue=mask", f"tissue.path={path}", "tissue.inlets=[[0.0,0.03,0.02]]", "n_terminals=12")
    absent = rf"tissue\.labels\.{role}: no voxel of .* holds the labels \[7\] \(its labels: \[0, 1, 2\]\)"
    with pytest.raises(TissueError, match=absent):
        make_problem(*base, "tissue.labels.supply=[1]", f"tissue.labels.{role}=[7]")
    with pytest.raises(TissueError, match=rf"tissue\.labels\.{role}: no voxel .* holds the labels \[7\]"):
        make_problem(*base, "tissue.labels.supply=[1]", f"tissue.labels.{role}=[2,7]")  # one of them absent


def test_a_label_map_whose_header_gives_metre_voxels_is_refused_naming_the_file(tmp_path):
    """A 1000 mm voxel (a header in the wrong unit): a 26 m organ, which would run to exit 0."""
    path = img.write_label_map(tmp_path / "m.nii.gz", labels_zyx(), 1.0, ORIGIN * 500)
    with pytest.raises(TissueError) as err:
        make_problem("tissue=mask", f"tissue.path={path}", "tissue.inlets=[[0.0,15.0,10.0]]", "n_terminals=12")
    text = str(err.value)
    assert text.startswith(f"the header of tissue.path ({str(path)!r}) gives voxels of 1000 mm, outside "), text
    assert "[0.001, 10] mm" in text and "unit" in text, text


def test_an_inlet_inside_an_excluded_cavity_is_refused(tmp_path):
    """An ostium lies in the tissue or the open space next to it (the heart's lie above the base,
    outside the myocardium); inside a cavity its root segment could not leave without crossing it."""
    path = img.write_label_map(tmp_path / "m.nii.gz", labels_zyx(), H, ORIGIN)
    centre = (ORIGIN + H * np.array([6, 5, 4])).tolist()  # label 2, the cavity
    shell = (ORIGIN + H * np.array([6, 5, 7])).tolist()  # label 1, the tissue
    above = (ORIGIN + H * np.array([6, 5, 8])).tolist()  # label 0, outside
    base = ("tissue=mask", f"tissue.path={path}", "n_terminals=12")
    inlets = f"tissue.inlets=[{above},{centre}]".replace(" ", "")
    with pytest.raises(TissueError) as err:
        make_problem(*base, "tissue.labels.supply=[1]", "tissue.labels.exclusion=[2]", inlets)
    text = str(err.value)
    assert text.startswith("tissue.inlets: inlet 1 (inlet1) at [2, 30, 13] mm lies inside a cavity of the"), text
    # the same cavity given as a mask of its own (tissue.exclusion_path)
    labels = labels_zyx()
    np.save(tmp_path / "tissue.npy", (labels == 1).astype(np.uint8))
    np.save(tmp_path / "cavity.npy", (labels == 2).astype(np.uint8))
    own = ("tissue=mask", f"tissue.path={tmp_path / 'tissue.npy'}", f"tissue.voxel_size={H!r}", "n_terminals=12")
    own += (f"tissue.origin={ORIGIN.tolist()}".replace(" ", ""), f"tissue.exclusion_path={tmp_path / 'cavity.npy'}")
    with pytest.raises(TissueError, match=r"tissue\.inlets: inlet 0 .* lies inside a cavity"):
        make_problem(*own, f"tissue.inlets=[{centre}]".replace(" ", ""))
    for fine in (shell, above):  # in the tissue or outside it: accepted
        make_problem(*own, f"tissue.inlets=[{fine}]".replace(" ", ""))
    # without an exclusion role the label is plain tissue (every nonzero label): accepted
    make_problem(*base, f"tissue.inlets=[{centre}]".replace(" ", ""))
