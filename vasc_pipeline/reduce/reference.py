"""Reference morphometry: Kassab et al. 1993, porcine coronary arteries (Tables 1-3).

The table ships with the package as ``data/kassab1993_tables1-3_diameter_length.csv``,
verbatim, with its source comment on the first line (two independent transcriptions of
the paper, their agreement in the ``status`` column). In the CSV, diameters are in
micrometres and lengths in millimetres; :func:`kassab_dataset` converts both to metres.

Orders are Kassab's diameter-defined Strahler orders: 1 = smallest arterioles, 11 = the
trunk of the RCA and the LAD (the LCX has 10 orders). :func:`compare_with_kassab` sets a
model's per-order means (from :func:`vasc_pipeline.reduce.morphometry.morphometry`) beside them.
"""

from __future__ import annotations

import functools
from importlib import resources
from io import StringIO

import numpy as np
import pandas as pd
import xarray as xr

__all__ = [
    "KASSAB_CSV_NAME",
    "ARTERIES",
    "LEVELS",
    "ORDERS",
    "kassab_csv_path",
    "kassab_source",
    "kassab_table",
    "kassab_dataset",
    "compare_with_kassab",
]

KASSAB_CSV_NAME = "kassab1993_tables1-3_diameter_length.csv"
ARTERIES = ("RCA", "LAD", "LCX")
LEVELS = ("segment", "element")
ORDERS = tuple(range(1, 12))

# divisors to SI (division by an exact power of ten rounds better than * 1e-6)
_UM, _MM = 1e6, 1e3
# (variable, CSV column, divisor to SI, units, long_name)
_SI_COLUMNS = (
    ("D_mean", "D_mean_um", _UM, "m", "mean diameter"),
    ("D_sd", "D_sd_um", _UM, "m", "standard deviation of diameter"),
    ("D_n", "D_n", None, "1", "number of vessels measured for diameter"),
    ("L_mean", "L_mean_mm", _MM, "m", "mean length"),
    ("L_sd", "L_sd_mm", _MM, "m", "standard deviation of length"),
    ("L_n", "L_n", None, "1", "number of vessels measured for length"),
)


def kassab_csv_path():
    """Path (a ``Traversable``) of the shipped CSV file."""
    return resources.files("vasc_pipeline").joinpath("data", KASSAB_CSV_NAME)


@functools.lru_cache(maxsize=1)
def _read() -> tuple[str, pd.DataFrame]:
    text = kassab_csv_path().read_text(encoding="utf-8")
    first, _, _ = text.partition("\n")
    if not first.startswith("#"):
        raise ValueError(f"{KASSAB_CSV_NAME}: the first line must be the '# source: ...' comment")
    table = pd.read_csv(StringIO(text), skiprows=1, dtype={"status": str, "note": str}, keep_default_na=True)
    table["note"] = table["note"].fillna("")
    return first.lstrip("#").strip(), table


def kassab_source() -> str:
    """The CSV's source comment (citation, transcriptions and their status), without '#'."""
    return _read()[0]


def kassab_table(si: bool = False) -> pd.DataFrame:
    """Kassab 1993 Tables 1-3 as a long table, one row per (artery, level, order).

    Parameters
    ----------
    si : bool
        False (default): the CSV's columns as shipped, ``D_mean_um, D_sd_um`` in
        micrometres and ``L_mean_mm, L_sd_mm`` in millimetres. True: those four columns
        replaced by ``D_mean, D_sd, L_mean, L_sd`` in metres.

    Returns
    -------
    pandas.DataFrame
        Columns ``artery`` (str), ``level`` ("segment" | "element"), ``order`` (int64),
        diameters, ``D_n`` (int64), lengths, ``L_n`` (int64), ``status`` ("agree",
        "DISPUTED", "A_only", "B_only") and ``note`` (str, "" when empty). Missing SDs
        (single trunk elements) are NaN. ``attrs["source"]`` holds the source line.

    Examples
    --------
    >>> t = kassab_table(si=True)
    >>> float(t.query("artery == 'RCA' and level == 'element' and order == 11").D_mean.iloc[0])
    0.003218
    """
    source, table = _read()
    table = table.copy()
    if si:
        for name, column, scale, _, _ in _SI_COLUMNS:
            if scale is not None:
                table[name] = table.pop(column) / scale
        front = ["artery", "level", "order"]
        table = table[front + [n for n, *_ in _SI_COLUMNS] + ["status", "note"]]
    table.attrs["source"] = source
    return table


def kassab_dataset() -> xr.Dataset:
    """Kassab 1993 Tables 1-3 as a labelled dataset in SI units.

    Returns
    -------
    xarray.Dataset
        Dims ``artery`` (RCA, LAD, LCX), ``level`` (segment, element), ``order`` (1..11).
        ``D_mean, D_sd, L_mean, L_sd`` float64 in metres (NaN where the paper gives no
        value: LCX order 11, SDs of single trunk elements); ``D_n, L_n`` int64 counts (0
        where absent); ``status`` and ``note`` strings ("" where absent). Every variable
        carries ``units`` and ``long_name``; ``attrs["source"]`` holds the source line.

    Examples
    --------
    >>> ds = kassab_dataset()
    >>> float(ds.D_mean.sel(artery="LAD", level="segment", order=1))  # 9.2 um
    9.2e-06
    """
    source, table = _read()
    shape = (len(ARTERIES), len(LEVELS), len(ORDERS))
    a = table["artery"].map({k: i for i, k in enumerate(ARTERIES)})
    lv = table["level"].map({k: i for i, k in enumerate(LEVELS)})
    o = table["order"].to_numpy() - ORDERS[0]
    if a.isna().any() or lv.isna().any() or (o < 0).any() or (o >= len(ORDERS)).any():
        raise ValueError(f"{KASSAB_CSV_NAME}: unexpected artery, level or order value")
    a, lv = a.to_numpy(dtype=np.int64), lv.to_numpy(dtype=np.int64)
    dims = ("artery", "level", "order")
    data_vars = {}
    for name, column, scale, units, long_name in _SI_COLUMNS:
        if scale is None:
            values = np.zeros(shape, dtype=np.int64)
            values[a, lv, o] = table[column].to_numpy(dtype=np.int64)
        else:
            values = np.full(shape, np.nan)
            values[a, lv, o] = table[column].to_numpy(dtype=float) / scale
        data_vars[name] = (dims, values, {"units": units, "long_name": f"Kassab 1993 {long_name}"})
    for name, long_name in (("status", "agreement of the two transcriptions"), ("note", "transcription note")):
        values = np.full(shape, "", dtype=object)
        values[a, lv, o] = table[name].to_numpy(dtype=object)
        data_vars[name] = (dims, values.astype(str), {"long_name": long_name})
    coords = {
        "artery": ("artery", list(ARTERIES), {"long_name": "coronary artery"}),
        "level": ("level", list(LEVELS), {"long_name": "vessel unit (segment or element)"}),
        "order": (
            "order",
            np.array(ORDERS, dtype=np.int64),
            {"long_name": "diameter-defined Strahler order", "units": "1"},
        ),
    }
    return xr.Dataset(
        data_vars,
        coords=coords,
        attrs={"title": "Kassab et al. 1993, porcine coronary arteries, Tables 1-3", "source": source},
    )


def compare_with_kassab(
    ds: xr.Dataset,
    artery: str,
    *,
    scheme: str = "diameter_defined",
    level: str = "element",
    reference: xr.Dataset | None = None,
) -> pd.DataFrame:
    """Model against Kassab 1993: mean diameter and length per order.

    Parameters
    ----------
    ds : xarray.Dataset
        From :func:`vasc_pipeline.reduce.morphometry.morphometry` (orders shifted to 11), with or
        without the ``scheme`` dim.
    artery : {"RCA", "LAD", "LCX"}
    scheme : {"diameter_defined", "strahler"}
        Used when ``ds`` has a ``scheme`` dim.
    level : {"element", "segment"}
    reference : xarray.Dataset, optional
        Default :func:`kassab_dataset`.

    Returns
    -------
    pandas.DataFrame
        Index ``order`` (union of model and Kassab orders). Columns ``model_diameter``,
        ``kassab_diameter``, ``diameter_log10_ratio`` (log10 model/Kassab), the same for
        ``length`` (metres), ``model_count``, ``kassab_count``. ``attrs`` hold
        ``mean_abs_log10_ratio_diameter``, ``mean_abs_log10_ratio_length`` (over the
        orders present in both, NaN if none), their mean ``mean_abs_log10_ratio``,
        ``n_orders_compared``, ``artery``, ``scheme`` and ``level``.
    """
    if reference is None:
        reference = kassab_dataset()
    ds = _checked_selection(ds, reference, artery, scheme, level)
    table = _joined_orders(ds, reference.sel(artery=artery, level=level), level)
    both = (table.model_count > 0) & (table.kassab_count > 0)
    mad = float(table.diameter_log10_ratio[both].abs().mean()) if both.any() else float("nan")
    mal = float(table.length_log10_ratio[both].abs().mean()) if both.any() else float("nan")
    table.attrs.update(
        mean_abs_log10_ratio_diameter=mad,
        mean_abs_log10_ratio_length=mal,
        mean_abs_log10_ratio=(mad + mal) / 2,
        n_orders_compared=int(both.sum()),
        artery=artery,
        scheme=scheme,
        level=level,
    )
    return table


# The comparison table's columns, in order
_COMPARISON_COLUMNS = [
    "model_diameter",
    "kassab_diameter",
    "diameter_log10_ratio",
    "model_length",
    "kassab_length",
    "length_log10_ratio",
    "model_count",
    "kassab_count",
]


def _checked_selection(ds: xr.Dataset, reference: xr.Dataset, artery: str, scheme: str, level: str) -> xr.Dataset:
    """``ds`` at ``scheme`` (when it has the dim), after checking the artery, the level and the scheme."""
    if artery not in reference.artery.values:
        raise ValueError(f"artery: {artery!r} is not one of {list(reference.artery.values)}")
    if level not in ("element", "segment"):
        raise ValueError(f"level: {level!r} is not 'element' or 'segment'")
    if "scheme" in ds.dims:
        if scheme not in ds.scheme.values:
            raise ValueError(f"scheme: {scheme!r} is not one of {list(ds.scheme.values)}")
        ds = ds.sel(scheme=scheme)
    return ds


def _joined_orders(ds: xr.Dataset, ref: xr.Dataset, level: str) -> pd.DataFrame:
    """Model and Kassab per order (the union of the orders either has), with the log10 ratios."""
    model = pd.DataFrame(
        {
            "model_diameter": ds[f"{level}_diameter_mean"].to_series(),
            "model_length": ds[f"{level}_length_mean"].to_series(),
            "model_count": ds[f"{level}_count"].to_series(),
        }
    )
    model = model[model.model_count > 0]
    kassab = pd.DataFrame(
        {
            "kassab_diameter": ref.D_mean.to_series(),
            "kassab_length": ref.L_mean.to_series(),
            "kassab_count": ref.D_n.to_series(),
        }
    )
    kassab = kassab[kassab.kassab_count > 0]
    table = model.join(kassab, how="outer").sort_index()
    table.index = table.index.astype(np.int64)
    table.index.name = "order"
    table["model_count"] = table.model_count.fillna(0).astype(np.int64)
    table["kassab_count"] = table.kassab_count.fillna(0).astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        table["diameter_log10_ratio"] = np.log10(table.model_diameter / table.kassab_diameter)
        table["length_log10_ratio"] = np.log10(table.model_length / table.kassab_length)
    return table[_COMPARISON_COLUMNS]
