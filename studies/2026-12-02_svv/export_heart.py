"""Export our heart (the voxel tissue of ``build_tissue("heart", N)``) for svVascularize.

Run in OUR environment (system python, from the repository root):

    python studies/2026-12-02_svv/export_heart.py --n 1000 6000 --out /tmp/svv_study
    python studies/2026-12-02_svv/export_heart.py --quick     # N = 40 into a temporary directory

Writes ``heart_N<N>.npz`` per N: ``mask`` (uint8, z, y, x: the myocardium), ``cavity``
(uint8, z, y, x: the ventricular cavities of the exclusion domain), ``voxel_size`` (m),
``origin`` ([x, y, z] of voxel [0, 0, 0]'s centre, m), ``inlets`` (K x 3, m) and
``inlet_names``. The surface itself is made in the svv venv (``grow_svv.py``), which has
scikit-image / VTK; our env has neither.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np


def export(n: int, out: Path) -> Path:
    """``heart_N<n>.npz`` in ``out``: the heart's voxel tissue at N = ``n``."""
    from vasc_pipeline.model.tissue import build_tissue

    t = build_tissue("heart", n)
    path = out / f"heart_N{n}.npz"
    np.savez_compressed(
        path,
        mask=np.asarray(t.mask, dtype=np.uint8),
        cavity=np.asarray(t.cavity, dtype=np.uint8),
        voxel_size=float(t.voxel_size),
        origin=np.asarray(t.origin, dtype=np.float64),
        inlets=np.asarray(t.inlets, dtype=np.float64),
        inlet_names=np.array(list(t.inlet_names)),
    )
    print(path, t.mask.shape, float(t.voxel_size), list(t.inlet_names))
    return path


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[1000, 6000])
    ap.add_argument("--out", type=Path, default=Path("/tmp/svv_study"))
    ap.add_argument("--quick", action="store_true", help="N = 40 into a temporary directory, read back")
    args = ap.parse_args(argv)
    if args.quick:
        with tempfile.TemporaryDirectory() as tmp:
            d = np.load(export(40, Path(tmp)))
            assert d["mask"].any() and d["inlets"].shape == (2, 3), "the heart's myocardium and its two ostia"
        return
    args.out.mkdir(parents=True, exist_ok=True)
    for n in args.n:
        export(n, args.out)


if __name__ == "__main__":
    main()
