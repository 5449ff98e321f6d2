"""The whole trees' summary (``extended_summary.zarr``), table (``extended_comparison.csv``) and
printed table, from what :func:`vasc_pipeline.reduce.extended.reduce_whole_tree` found in each.

Groups of the DataTree, dim ``run_id`` (the run below which a whole tree was grown):

- ``/morphometry`` (run_id, reading, scheme, order): :func:`~vasc_pipeline.reduce.morphometry.morphometry`'s
  per-order statistics for both readings of the diameter-defined ordering (``range``,
  ``confluence``), orders shifted so that the trunk is 11 and aligned from the lowest order (1 or
  below) to 11;
- ``/comparison`` (run_id, reading, artery, order) and (run_id, reading, artery): against Kassab
  et al. 1993, element level (a heart's trees only);
- ``/pressure`` (run_id, reading, order): the pressures along each order's vessels
  (:data:`PRESSURE_META`), the published values in its attrs;
- ``/anatomy`` (run_id) and (run_id, inlet): :func:`~vasc_pipeline.reduce.anatomy.anatomy` of the
  whole tree (fine terminals' pressures, crown exponents), the vessels of the published
  diameters, the fine count;
- ``/territory`` (run_id, territory): :func:`~vasc_pipeline.reduce.extended.territory_table`.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import xarray as xr

from ..model.physics import Physics
from . import morphometry as _m
from .anatomy import ANATOMY_FIELDS, MMHG
from .ordering import READINGS
from .reference import ARTERIES, kassab_dataset
from .summary import _comparison_part

# Published pressures in coronary arterioles as a fraction of aortic pressure (module docstring:
# the source lines, and where the numbers are from).
PUBLISHED_PRESSURES = {
    "diameter_min": 100e-6,  # m
    "diameter_max": 170e-6,  # m
    "fraction_min": 0.60,
    "fraction_max": 0.80,
    "source": "Chilian, Eastham & Marcus 1986, Am J Physiol 251:H779-H788 (cat); Chilian, Layne, Klausner, "
    "Eastham & Marcus 1989, Am J Physiol 256:H383-H390 (dog): about 60-80 % of aortic pressure in coronary "
    "arterioles of about 100-170 um (as secondary sources summarise them, not checked against the papers' tables)",
}

TERRITORY_META = {
    "node": ("1", "the annealed terminal (node) at the territory's root"),
    "fine_terminals": ("1", "fine terminals of the territory"),
    "flow": ("m3 s-1", "flow into the territory's subtree, Q_t"),
    "pressure_root": ("Pa", "pressure at the annealed terminal, P_t"),
    "pressure_terminal_mean": ("Pa", "mean pressure of the territory's fine terminals"),
    "pressure_terminal_min": ("Pa", "lowest pressure of the territory's fine terminals"),
    "resistance_lumped": ("Pa s m-3", "lumped resistance (P_t - mean fine terminal pressure) / Q_t"),
    "resistance_network": ("Pa s m-3", "series-parallel resistance of the subtree, its terminals at one pressure"),
    "path_length_mean": ("m", "mean path length from the annealed terminal to a fine terminal"),
}

PRESSURE_META = {
    "pressure_mean": ("Pa", "mean pressure along the order's vessels (length-weighted)"),
    "pressure_min": ("Pa", "lowest pressure in the order's vessels (at a distal end)"),
    "pressure_max": ("Pa", "highest pressure in the order's vessels (at a proximal end)"),
    "pressure_mean_fraction": ("1", "mean pressure along the order's vessels over the inlet pressure"),
    "pressure_min_fraction": ("1", "lowest pressure in the order's vessels over the inlet pressure"),
    "diameter_min": ("m", "smallest segment diameter of the order"),
    "diameter_max": ("m", "largest segment diameter of the order"),
    "vessel_length": ("m", "total length of the order's vessels"),
}


def counts_as_ints(ds: xr.Dataset) -> xr.Dataset:
    for name, var in ds.data_vars.items():  # an outer join turns absent counts into NaN: back to 0
        if name.endswith("_count"):
            ds[name] = var.fillna(0).astype(np.int64)
    return ds


__all__ = ["Reduced", "build_extended_summary", "comparison_frame", "format_extended"]


@dataclass
class Reduced:
    """What the summary keeps of one whole tree (its arrays are let go after its exports)."""

    run_id: str
    organ: str
    physics: Physics
    morphometry: xr.Dataset
    pressure: xr.Dataset
    anatomy: dict[str, float]
    territory: pd.DataFrame


ANATOMY_EXTRA = (
    ("band_pressure_mean_fraction", "1", "mean pressure along the vessels of 100-170 um over the inlet pressure"),
    ("band_pressure_min_fraction", "1", "lowest pressure in the vessels of 100-170 um over the inlet pressure"),
    ("band_pressure_mean", "Pa", "mean pressure along the vessels of 100-170 um (length-weighted)"),
    ("band_vessel_length", "m", "total length of the vessels of 100-170 um"),
    ("lumped_over_network_median", "1", "median over territories of the lumped over the series-parallel resistance"),
)


def build_extended_summary(reduced: list[Reduced], output_dir: Path, zerod: str) -> xr.DataTree:
    run_ids = [r.run_id for r in reduced]
    lo = min([1] + [int(r.morphometry.order.min()) for r in reduced])
    orders = np.arange(lo, _m.TOP_ORDER + 1, dtype=np.int64)
    run_dim = xr.DataArray(np.array(run_ids, dtype=object), dims="run_id", name="run_id")
    morph = counts_as_ints(xr.concat([r.morphometry.reindex(order=orders) for r in reduced], dim=run_dim, join="outer"))
    pressure = xr.concat([r.pressure.reindex(order=orders) for r in reduced], dim=run_dim, join="outer")
    pressure.attrs.update(
        title="Pressures along the whole tree's vessels by diameter-defined order (Poiseuille, from the inlet's)",
        published=PUBLISHED_PRESSURES["source"],
        published_diameter_min=PUBLISHED_PRESSURES["diameter_min"],
        published_diameter_max=PUBLISHED_PRESSURES["diameter_max"],
        published_fraction_min=PUBLISHED_PRESSURES["fraction_min"],
        published_fraction_max=PUBLISHED_PRESSURES["fraction_max"],
    )
    groups = {"/morphometry": morph, "/pressure": pressure, "/anatomy": _anatomy_group(reduced, run_dim)}
    groups["/territory"] = _territory_group(reduced, run_dim)
    heart = [r for r in reduced if r.organ == "heart"]
    if heart:
        reference = kassab_dataset()
        per_run = []
        for r in heart:
            per_reading = [
                _comparison_part(r.morphometry.sel(reading=reading).reindex(order=orders), reference, orders)[0]
                for reading in READINGS
            ]
            per_run.append(xr.concat(per_reading, dim=xr.DataArray(list(READINGS), dims="reading", name="reading")))
        groups["/comparison"] = xr.concat(
            per_run, dim=xr.DataArray(np.array([r.run_id for r in heart], dtype=object), dims="run_id", name="run_id")
        ).assign_coords(artery=list(ARTERIES))
    for ds in groups.values():
        if "reading" in ds.dims:
            ds["reading"] = ds["reading"].astype(object)
            ds["reading"].attrs.update(long_name="reading of the diameter-defined ordering (range, confluence)")
        if "scheme" in ds.dims:
            ds["scheme"] = ds["scheme"].astype(object)
        if "artery" in ds.dims:
            ds["artery"] = ds["artery"].astype(object)
        ds["run_id"].attrs.update(long_name="the run below which the whole tree was grown")
    root = xr.Dataset(
        attrs={
            "title": "vasc_pipeline: the whole trees of extended/, reduced",
            "Conventions": "CF-1.10",
            "history": f"{_dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')}: "
            "vasc_pipeline.reduce.extended",
            "output_dir": str(Path(output_dir).resolve()),
            "zerod": zerod,
            "ordering": "diameter-defined Strahler (Jiang, Kassab & Fung 1994), both readings; orders shifted so "
            f"that the highest is {_m.TOP_ORDER}",
        }
    )
    return xr.DataTree.from_dict({"/": root, **groups})


def _anatomy_group(reduced: list[Reduced], run_dim) -> xr.Dataset:
    prefix = "inlet_share_"
    inlets = sorted({k[len(prefix) :] for r in reduced for k in r.anatomy if k.startswith(prefix)})
    data = {}
    for name, units, long_name in (*ANATOMY_FIELDS, *ANATOMY_EXTRA):
        values = [float(r.anatomy.get(name, math.nan)) for r in reduced]
        data[name] = ("run_id", np.array(values), {"units": units, "long_name": long_name})
    shares = np.array([[r.anatomy.get(prefix + i, math.nan) for i in inlets] for r in reduced], dtype=float)
    data["inlet_share"] = (("run_id", "inlet"), shares, {"units": "1", "long_name": "share of the fine terminals"})
    for name, units, long_name, get in (
        ("n_fine_terminals", "1", "fine terminals of the whole tree", lambda r: r.physics.n_terminals),
        ("n_territories", "1", "territories (annealed terminals)", lambda r: len(r.territory)),
        (
            "pressure_inlet",
            "Pa",
            "inlet pressure of the model (its aortic pressure)",
            lambda r: r.physics.pressure_inlet,
        ),
    ):
        data[name] = ("run_id", np.array([get(r) for r in reduced]), {"units": units, "long_name": long_name})
    coords = {"run_id": run_dim, "inlet": ("inlet", np.array(inlets, dtype=object), {"long_name": "inlet (ostium)"})}
    return xr.Dataset(data, coords=coords, attrs={"title": "Anatomy of the whole trees (fine terminals' pressures)"})


def _territory_group(reduced: list[Reduced], run_dim) -> xr.Dataset:
    size = max(len(r.territory) for r in reduced)
    data = {}
    for name, (units, long_name) in TERRITORY_META.items():
        integer = name in ("node", "fine_terminals")
        values = np.full((len(reduced), size), -1 if integer else np.nan, dtype=np.int64 if integer else float)
        for i, r in enumerate(reduced):
            values[i, : len(r.territory)] = r.territory[name].to_numpy()
        data[name] = (("run_id", "territory"), values, {"units": units, "long_name": long_name})
    coords = {"run_id": run_dim, "territory": ("territory", np.arange(size), {"long_name": "territory", "units": "1"})}
    return xr.Dataset(data, coords=coords, attrs={"title": "Territories: each annealed terminal's subtree"})


def comparison_frame(summary: xr.DataTree) -> pd.DataFrame:
    """``extended_comparison.csv``: one row per (run, reading, order) with a vessel (and, for a
    heart, per artery with Kassab's values beside), the pressures of the order's vessels."""
    morph = summary["morphometry"].to_dataset().sel(scheme="diameter_defined")
    names = ["element_diameter_mean", "element_length_mean", "element_count", "segment_count"]
    frame = morph[names].to_dataframe().reset_index()
    press = summary["pressure"].to_dataset()
    frame = frame.merge(press[list(PRESSURE_META)].to_dataframe().reset_index(), on=["run_id", "reading", "order"])
    frame = frame.drop(columns=[c for c in ("scheme",) if c in frame.columns])
    if "comparison" in summary.children:
        comp = summary["comparison"].to_dataset()
        kassab = comp[
            ["kassab_diameter", "kassab_length", "kassab_count", "diameter_log10_ratio", "length_log10_ratio"]
        ]
        frame = frame.merge(kassab.to_dataframe().reset_index(), on=["run_id", "reading", "order"], how="left")
        keep = (frame.element_count > 0) | (frame.kassab_count.fillna(0) > 0)
    else:
        keep = frame.element_count > 0
    frame = frame[keep].rename(
        columns={n: f"{n}_{PRESSURE_META[n][0]}" for n in PRESSURE_META if PRESSURE_META[n][0] != "1"}
    )
    frame = frame.rename(columns={"element_diameter_mean": "model_diameter_m", "element_length_mean": "model_length_m"})
    frame = frame.rename(columns={"kassab_diameter": "kassab_diameter_m", "kassab_length": "kassab_length_m"})
    front = [c for c in ("run_id", "reading", "artery", "order") if c in frame.columns]
    return frame[front + [c for c in frame.columns if c not in front]].reset_index(drop=True)


def format_extended(summary: xr.DataTree) -> str:
    """The whole trees in a table: per order (range reading) diameter and length against Kassab's
    (a heart's), the pressures along the order's vessels; then the published comparison."""
    morph = summary["morphometry"].to_dataset()
    press = summary["pressure"].to_dataset()
    anat = summary["anatomy"].to_dataset()
    comp = summary["comparison"].to_dataset() if "comparison" in summary.children else None
    band = PUBLISHED_PRESSURES
    lines = [
        "The whole trees (extended/): mean element diameter D [um] and length L [mm] per diameter-defined order "
        f"(range reading, highest = {_m.TOP_ORDER}), and the pressure along the order's vessels (Poiseuille) in mmHg "
        "and as a share of the inlet pressure."
    ]
    for run_id in morph.run_id.values:
        m = morph.sel(run_id=run_id, reading="range", scheme="diameter_defined")
        p = press.sel(run_id=run_id, reading="range")
        a = anat.sel(run_id=run_id)
        lines.append("")
        lines.append(f"{run_id}: {int(a.n_fine_terminals)} fine terminals in {int(a.n_territories)} territories")
        kassab = "" if comp is None else " " + " ".join(f"{'D ' + x:>7}" for x in ARTERIES)
        lkassab = "" if comp is None else " " + " ".join(f"{'L ' + x:>7}" for x in ARTERIES)
        lines.append(
            f"{'order':>5} {'D model':>7}{kassab} {'L model':>7}{lkassab} {'n':>7} {'P mean':>7} {'P min':>7} "
            f"{'mean %':>6}"
        )
        for o in m.order.values[::-1]:
            n = int(m.element_count.sel(order=o))
            if n == 0:
                continue
            row = f"{int(o):>5} {_num(float(m.element_diameter_mean.sel(order=o)), 1e6)}"
            if comp is not None:
                c = comp.sel(run_id=run_id, reading="range", order=o)
                row += " " + " ".join(_num(float(c.kassab_diameter.sel(artery=x)), 1e6) for x in ARTERIES)
            row += f" {_num(float(m.element_length_mean.sel(order=o)), 1e3)}"
            if comp is not None:
                row += " " + " ".join(_num(float(c.kassab_length.sel(artery=x)), 1e3) for x in ARTERIES)
            row += (
                f" {n:>7} {_num(float(p.pressure_mean.sel(order=o)), 1 / MMHG)} "
                f"{_num(float(p.pressure_min.sel(order=o)), 1 / MMHG)} "
                f"{100 * float(p.pressure_mean_fraction.sel(order=o)):>6.1f}"
            )
            lines.append(row)
        if comp is not None:
            for reading in READINGS:
                c = comp.sel(run_id=run_id, reading=reading)
                mad = " ".join(f"{x} {float(c.mean_abs_log10_ratio_diameter.sel(artery=x)):.3f}" for x in ARTERIES)
                mal = " ".join(f"{x} {float(c.mean_abs_log10_ratio_length.sel(artery=x)):.3f}" for x in ARTERIES)
                n = int(c.n_orders_compared.isel(artery=0))
                lines.append(f"{reading} reading, mean |log10 model/Kassab| over {n} orders: D {mad} | L {mal}")
        lines.append(
            f"vessels of {band['diameter_min'] * 1e6:.0f}-{band['diameter_max'] * 1e6:.0f} um: mean "
            f"{100 * float(a.band_pressure_mean_fraction):.1f} %, lowest "
            f"{100 * float(a.band_pressure_min_fraction):.1f} % "
            f"of the inlet pressure; published {100 * band['fraction_min']:.0f}-{100 * band['fraction_max']:.0f} % of "
            "aortic pressure (Chilian et al. 1986, 1989: cat, dog)"
        )
        lines.append(
            f"fine terminals: pressure min {float(a.terminal_pressure_min) / MMHG:.0f}, median "
            f"{float(a.terminal_pressure_median) / MMHG:.0f} mmHg ({int(a.terminals_below_zero)} below 0); crowns "
            f"D_s ~ L_c^{float(a.diameter_crown_length_exponent):.2f} (3/7), "
            f"V_c ~ D_s^{float(a.crown_volume_diameter_exponent):.2f} (3); lumped over series-parallel territory "
            f"resistance, median {float(a.lumped_over_network_median):.3f}"
        )
    return "\n".join(lines)


def _num(value: float, scale: float, width: int = 7) -> str:
    return f"{value * scale:{width}.4g}" if np.isfinite(value) else " " * (width - 1) + "-"
