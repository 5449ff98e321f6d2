"""Figures across reduced sweeps, from the command line (one sweep's own figures come with its reduction).

    python -m vasc_pipeline.figures convergence OUT.png LABEL=OUTPUT_DIR [LABEL=OUTPUT_DIR ...]

``convergence``: :func:`~vasc_pipeline.figures.plot_convergence_studies` of the sweeps'
``summary.zarr`` (each reduced first, by the sweep itself or ``+stage=reduce``), e.g. the
paper's schedule against ``fast`` on the same problem. Exit status 2 on bad arguments.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import xarray as xr

from ..store.layout import SUMMARY_NAME


def _labelled_dir(text: str) -> tuple[str, Path]:
    label, sep, directory = text.partition("=")
    if not sep or not label or not directory:
        raise argparse.ArgumentTypeError(f"expected LABEL=OUTPUT_DIR, got {text!r}")
    summary = Path(directory) / SUMMARY_NAME
    if not summary.is_dir():
        raise argparse.ArgumentTypeError(
            f"{summary} does not exist: reduce the sweep first (python -m vasc_pipeline +stage=reduce "
            f"output_dir={directory})"
        )
    return label, summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m vasc_pipeline.figures", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="figure", required=True)
    conv = sub.add_parser("convergence", help="mean final cost ± SE against moves, several sweeps on one plot")
    conv.add_argument("out", type=Path, help="the PNG to write")
    conv.add_argument("sweeps", nargs="+", type=_labelled_dir, metavar="LABEL=OUTPUT_DIR")
    args = parser.parse_args(argv)

    from . import plot_convergence_studies

    summaries = {label: xr.open_datatree(path, engine="zarr") for label, path in args.sweeps}
    path = plot_convergence_studies(summaries, args.out)
    if path is None:
        print("vasc_pipeline.figures: no sweep has a steps axis with two or more values", file=sys.stderr)
        return 1
    print(f"vasc_pipeline.figures: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
