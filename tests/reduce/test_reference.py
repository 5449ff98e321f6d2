"""The shipped Kassab 1993 table: verbatim copy, values, units, labels."""

import csv
import io
import math
from pathlib import Path

import numpy as np
import pytest

from vasc_pipeline.reduce.reference import (
    ARTERIES,
    KASSAB_CSV_NAME,
    LEVELS,
    kassab_csv_path,
    kassab_dataset,
    kassab_source,
    kassab_table,
)

SHARED = Path("/work/shared/reference") / KASSAB_CSV_NAME


def _rows():
    """The shipped CSV parsed with the standard library only (independent of pandas)."""
    text = kassab_csv_path().read_text(encoding="utf-8")
    lines = text.splitlines()
    assert lines[0].startswith("# source: Kassab GS, Rider CA, Tang NJ, Fung YC (1993)")
    return list(csv.DictReader(io.StringIO("\n".join(lines[1:]))))


def _num(s):
    return math.nan if s == "" else float(s)


@pytest.mark.skipif(not SHARED.exists(), reason="shared reference directory not available")
def test_shipped_csv_is_a_verbatim_copy():
    assert kassab_csv_path().read_bytes() == SHARED.read_bytes()


def test_source_line_is_kept():
    src = kassab_source()
    assert src.startswith("source: Kassab GS")
    assert "Am J Physiol 265:H350" in src
    assert kassab_dataset().attrs["source"] == src
    assert kassab_table().attrs["source"] == src


def test_dataset_values_equal_the_csv():
    ds = kassab_dataset()
    rows = _rows()
    assert len(rows) == 22 + 22 + 20
    for r in rows:
        cell = ds.sel(artery=r["artery"], level=r["level"], order=int(r["order"]))
        for var, col, scale in (
            ("D_mean", "D_mean_um", 1e-6),
            ("D_sd", "D_sd_um", 1e-6),
            ("L_mean", "L_mean_mm", 1e-3),
            ("L_sd", "L_sd_mm", 1e-3),
        ):
            expected = _num(r[col]) * scale
            got = float(cell[var])
            if math.isnan(expected):
                assert math.isnan(got), (r, var)
            else:
                assert got == pytest.approx(expected, rel=1e-12), (r, var)
        assert int(cell.D_n) == int(r["D_n"])
        assert int(cell.L_n) == int(r["L_n"])
        assert str(cell.status.values) == r["status"]
        assert str(cell.note.values) == r["note"]


def test_dataset_layout_units_and_missing_cells():
    ds = kassab_dataset()
    assert list(ds.artery.values) == list(ARTERIES) == ["RCA", "LAD", "LCX"]
    assert list(ds.level.values) == list(LEVELS) == ["segment", "element"]
    assert ds.order.values.tolist() == list(range(1, 12))
    assert dict(ds.sizes) == {"artery": 3, "level": 2, "order": 11}
    for v in ("D_mean", "D_sd", "L_mean", "L_sd"):
        assert ds[v].attrs["units"] == "m" and ds[v].dtype == np.float64
        assert ds[v].attrs["long_name"]
    for v in ("D_n", "L_n"):
        assert ds[v].attrs["units"] == "1" and ds[v].dtype == np.int64
    assert "long_name" in ds.status.attrs
    # LCX has 10 orders: order 11 is absent at both levels
    lcx11 = ds.sel(artery="LCX", order=11)
    assert np.isnan(lcx11.D_mean).all() and np.isnan(lcx11.L_mean).all()
    assert (lcx11.D_n == 0).all() and (lcx11.status == "").all()
    # single trunk elements have no SD
    assert np.isnan(ds.D_sd.sel(artery="RCA", level="element", order=11))
    assert int(ds.D_n.sel(artery="RCA", level="element", order=11)) == 1


def test_spot_values_in_si_units():
    ds = kassab_dataset()
    rca11 = ds.sel(artery="RCA", level="element", order=11)
    assert float(rca11.D_mean) == pytest.approx(3218e-6)
    assert float(rca11.L_mean) == pytest.approx(84.1e-3)
    assert str(rca11.status.values) == "B_only"
    assert float(ds.D_mean.sel(artery="LAD", level="segment", order=1)) == pytest.approx(9.2e-6)
    assert float(ds.L_mean.sel(artery="LCX", level="element", order=10)) == pytest.approx(49.6e-3)
    assert int((ds.status == "DISPUTED").sum()) == 5


def test_table_raw_and_si():
    raw = kassab_table()
    assert list(raw.columns[:6]) == ["artery", "level", "order", "D_mean_um", "D_sd_um", "D_n"]
    assert len(raw) == 64
    si = kassab_table(si=True)
    assert {"D_mean", "D_sd", "L_mean", "L_sd"} <= set(si.columns)
    assert not {"D_mean_um", "L_mean_mm"} & set(si.columns)
    np.testing.assert_allclose(si.D_mean.to_numpy(), raw.D_mean_um.to_numpy() * 1e-6, rtol=1e-12)
    np.testing.assert_allclose(si.L_mean.to_numpy(), raw.L_mean_mm.to_numpy() * 1e-3, rtol=1e-12)
    # copies: mutating a returned table does not change the cache
    raw.loc[0, "D_mean_um"] = -1.0
    assert kassab_table().loc[0, "D_mean_um"] == 9.6
