"""Score svVascularize's trees, and our CCO's, under our cost and against Kassab (run in OUR env).

Run from the repository root with the system python, after ``grow_svv.py`` (svv venv)
wrote ``svv_N<N>.json`` and ``svv_N<N>_tree<i>.csv``:

    python studies/2026-12-02_svv/score_svv.py --n 1000 6000 --dir /tmp/svv_study \
        --rows studies/2026-12-02_svv/rows.jsonl
    python studies/2026-12-02_svv/score_svv.py --cco --n 1000 6000   # our CCO, into rows_cco.jsonl
    python studies/2026-12-02_svv/score_svv.py --quick   # the committed N = 1000 trees, a small CCO: a temporary file

Conversion to our arrays: tree i of the svv forest is rooted at our inlet i (LCA, RCA);
a node per segment end: the inlet at the root segment's proximal point, then every
segment's distal point (a terminal where the segment has no child, a bifurcation where it
has two; degree-2 nodes (one child) would be collapsed; more than two children is an
error, svv grows binary trees; neither occurred). Node order: inlets, the N terminals, the N - K bifurcations.
Then ``engine.build_problem(config.compose(["tissue=heart", "n_terminals=N"]))`` and
``costs.full_costs`` on a ``tree.Tree`` (our radii from topology, r = r_t n^(1/gamma)):
C_v, C_w, C_s, C_o; ``costs.cavity_share`` and ``morphometry.compare_with_kassab`` per
artery with our radii (``*_ours``) and, separately, svv's own radii, per node the radius
of the segment ending at it (0 at the inlets), in two readings: ``*_own``, svv's rule
recomputed on the final tree (:func:`svv_rule_radii`: Murray exponent 3, equal terminal
flows, equal terminal pressures, svv's viscosity; svv's root radius formula), and
``*_svv_exported``, svv's radius column as exported (in 0.0.57 a few per cent of its
segments come out wider than their parent, which Murray's law forbids: the column is not
refreshed on every segment as the Forest grows). One JSON row per N appended to ``--rows``.

``--cco``: our CCO instead (``method=cco``), one tree per N (``cco.grow(problem, seed)``, seed
0: random sites with Schreiner's distance criterion, growth only timed) on the heart of
``tissue=heart n_terminals=N``, scored by the same :func:`score_arrays` (our C_v, C_w, C_o, C_s,
cavity share, Kassab errors with our radii); its rows go to ``rows_cco.jsonl`` by default. The
anneal is not rerun: its rows are quoted from ``benchmarks/results/time_to_quality_rows.jsonl``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

ARTERIES = ("RCA", "LAD", "LCX")


def load_forest(paths: list[Path]):
    """Our (parent, position, svv radius) from the svv trees' segment CSVs."""
    inlets, terms, bifs = [], [], []  # entries: (key, position, svv radius, parent key)
    for t, path in enumerate(paths):
        seg = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        prox, dist, rad = seg[:, 0:3], seg[:, 3:6], seg[:, 6]
        par = seg[:, 8].astype(int)
        kids = [[] for _ in range(len(seg))]
        for s, p in enumerate(par):
            if p >= 0:
                kids[p].append(s)
        roots = np.flatnonzero(par < 0)
        assert roots.size == 1, f"{path}: {roots.size} root segments"
        inlets.append((("in", t), prox[roots[0]], 0.0, None))

        # walk down from the root; collapse single-child chains
        stack = [(int(roots[0]), ("in", t))]
        while stack:
            s, up = stack.pop()
            r = rad[s]
            while len(kids[s]) == 1:  # degree-2 node: merge with its only child
                s = kids[s][0]
            key = ("n", t, s)
            if len(kids[s]) == 0:
                terms.append((key, dist[s], r, up))
                continue
            ch = list(kids[s])
            assert len(ch) == 2, f"{path}: segment {s} has {len(ch)} children (svv grows binary trees)"
            bifs.append((key, dist[s], r, up))
            stack += [(c, key) for c in ch]
    nodes = inlets + terms + bifs
    index = {n[0]: i for i, n in enumerate(nodes)}
    parent = np.array([-1 if n[3] is None else index[n[3]] for n in nodes], dtype=np.int64)
    position = np.array([n[1] for n in nodes], dtype=np.float64)
    radius_svv = np.array([n[2] for n in nodes], dtype=np.float64)
    return parent, position, radius_svv, len(inlets), len(terms)


SVV_MU = 0.036 * 1.06 * 0.1  # svv's default viscosity: kinematic 0.036 cm^2/s x 1.06 g/cm^3 = 3.816e-3 Pa s
Q0, P_IN, P_T = 4.16e-6, 13300.0, 12000.0  # what grow_svv.py gave svv (our physics)


def svv_rule_radii(parent, position, k, nt, mu=SVV_MU, q0=Q0, dp=P_IN - P_T, murray=3.0):
    """svv's radii recomputed from the final tree by svv's own rule (Karch et al. 1999, as in
    ``svv/tree/utils/c_update.py``): equal terminal flows (Q0/N), every terminal at the same
    pressure, Murray's law with svv's exponent 3 at each bifurcation, the split of the
    parent's radius from the daughters' reduced resistances R* = 8 mu l / pi +
    (b_l^4 / R*_l + b_r^4 / R*_r)^-1, and each root radius (R*_root Q_root / dp)^(1/4).
    Per node, the radius of the segment ending at it; 0 at the inlets."""
    n = parent.size
    length = np.zeros(n)
    seg = np.flatnonzero(parent >= 0)
    length[seg] = np.linalg.norm(position[seg] - position[parent[seg]], axis=1)
    kids = [[] for _ in range(n)]
    for i in seg:
        kids[parent[i]].append(i)
    order = []  # pre-order from the inlets
    stack = list(range(k))
    while stack:
        i = stack.pop()
        order.append(i)
        stack += kids[i]
    flow = np.zeros(n)
    rstar = np.zeros(n)
    beta = np.ones(n)  # r_child / r_parent
    qt = q0 / nt
    for i in reversed(order):
        if i < k:
            continue
        c = kids[i]
        if not c:
            flow[i] = qt
            rstar[i] = 8 * mu * length[i] / np.pi
            continue
        a, b = c
        flow[i] = flow[a] + flow[b]
        ratio = (flow[a] * rstar[a] / (flow[b] * rstar[b])) ** 0.25  # r_a / r_b
        beta[a] = (1 + ratio**-murray) ** (-1 / murray)
        beta[b] = (1 + ratio**murray) ** (-1 / murray)
        rstar[i] = 8 * mu * length[i] / np.pi + 1.0 / (beta[a] ** 4 / rstar[a] + beta[b] ** 4 / rstar[b])
    radius = np.zeros(n)
    for i in order:
        if i < k:
            continue
        p = parent[i]
        radius[i] = (rstar[i] * flow[i] / dp) ** 0.25 if p < k else beta[i] * radius[p]
    return radius


def score_arrays(parent, position, k: int, nt: int, radius_own=None, problem=None, extra_radii=()) -> dict:
    """Our cost terms, cavity share and Kassab errors of a tree in our layout.

    ``radius_own``: the method's own radii per node (svv's), scored separately from ours;
    ``problem``: the heart at N = ``nt`` (built when None)."""
    from vasc_pipeline import config, costs, engine, morphometry
    from vasc_pipeline.model.tree import (
        KIND_BIFURCATION,
        KIND_INLET,
        KIND_TERMINAL,
        Tree,
        children_from_parent,
        count_terminals,
    )

    if problem is None:
        problem = engine.build_problem(config.compose(["tissue=heart", f"n_terminals={nt}"]))
    assert k == problem.physics.n_inlets, (k, problem.physics.n_inlets)
    assert parent.size == 2 * nt
    tree = Tree(parent, children_from_parent(parent), position, count_terminals(parent, nt, k), k)
    c = costs.full_costs(tree, problem.tissue, problem.physics, problem.terms)
    w_o = problem.physics.weights[0]
    kind = np.full(parent.size, KIND_BIFURCATION, dtype=np.int8)
    kind[:k] = KIND_INLET
    kind[k : k + nt] = KIND_TERMINAL
    r_ours = engine.node_radii(tree, problem.physics)
    t = problem.tissue
    # terminals inside our tissue mask (svv samples its own domain: the marching-cubes surface)
    u = np.rint((position[k : k + nt] - t.origin) / t.voxel_size).astype(int)[:, ::-1]
    ok = np.all((u >= 0) & (u < np.array(t.mask.shape)), axis=1)
    inside = np.zeros(nt, bool)
    inside[ok] = t.mask[u[ok, 0], u[ok, 1], u[ok, 2]] > 0
    first = np.flatnonzero(parent[k:] < k) + k  # the nodes below the inlets
    row = {
        "n": nt,
        "cost_volume": c["volume"],
        "cost_power": c["power"],
        "cost_exclusion": c["exclusion"],
        "cost_exclusion_weighted": w_o * c["exclusion"],
        "cost_supply": c["supply"],
        "vascular": c["volume"] + c["power"],
        "vascular_exclusion": costs.vascular_exclusion_cost(c, w_o),
        "terminals_inside_mask": float(inside.mean()),
        "our_radius_root_m": [float(r_ours[i]) for i in first],
    }
    radii = [("ours", r_ours)]
    if radius_own is not None:
        row["own_radius_root_m"] = [float(radius_own[i]) for i in first]
        radii.append(("own", radius_own))
    radii += list(extra_radii)
    for label, rad in radii:
        row[f"cavity_share_{label}"] = float(costs.cavity_share(parent, position, rad, t))
        ds = morphometry.morphometry(parent, position, rad, kind)
        for a in ARTERIES:
            attrs = morphometry.compare_with_kassab(ds, a).attrs
            row[f"diameter_error_{a}_{label}"] = float(attrs["mean_abs_log10_ratio_diameter"])
            row[f"length_error_{a}_{label}"] = float(attrs["mean_abs_log10_ratio_length"])
    return row


def score(n: int, folder: Path, tag: str) -> dict:
    info = json.loads((folder / f"svv_{tag}.json").read_text())
    paths = sorted(folder.glob(f"svv_{tag}_tree*.csv*"))
    parent, position, radius_svv, k, nt = load_forest(paths)
    row = {
        "method": "svv",
        "svv_version": info["svv_version"],
        "roots": info["roots"],
        "terminals_per_tree": info["terminals_per_tree"],
        "wall_seconds": info["grow_seconds"],
        "domain_seconds": info["domain_seconds"],
        "surface_seconds": info["surface_seconds"],
        "surface_points": info["surface_points"],
    }
    r_rule = svv_rule_radii(parent, position, k, nt)
    row.update(score_arrays(parent, position, k, nt, radius_own=r_rule, extra_radii=[("svv_exported", radius_svv)]))
    first = np.flatnonzero(parent[k:] < k) + k
    row["svv_exported_radius_root_m"] = [float(radius_svv[i]) for i in first]
    s = np.flatnonzero(parent >= k)
    row["svv_exported_child_wider_than_parent"] = float(np.mean(radius_svv[s] > radius_svv[parent[s]] * (1 + 1e-9)))
    row["svv_exported_vs_rule_median_abs_log10"] = float(np.median(np.abs(np.log10(radius_svv[k:] / r_rule[k:]))))
    return row


def score_cco(n: int, seed: int) -> dict:
    """Our CCO tree of ``n`` terminals on the heart (``method=cco``), scored by :func:`score_arrays`."""
    from vasc_pipeline import cco, config, engine

    problem = engine.build_problem(config.compose(["tissue=heart", f"n_terminals={n}", "method=cco"]))
    result = cco.grow(problem, seed)
    t = result.tree
    row = {"method": "cco (ours)", "seed": seed, "wall_seconds": result.wall_seconds}
    row.update(score_arrays(t.parent, t.position, t.n_inlets, t.n_terminals, problem=problem))
    return row


def append(row: dict, rows: Path) -> None:
    print(json.dumps(row), flush=True)
    with rows.open("a") as f:
        f.write(json.dumps(row) + "\n")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[1000, 6000])
    ap.add_argument("--tag", default="", help="suffix of the svv run's tag, e.g. _single")
    ap.add_argument("--dir", type=Path, default=Path("/tmp/svv_study"), help="grow_svv.py's --out")
    ap.add_argument("--rows", type=Path, help="rows file (default: rows.jsonl, with --cco rows_cco.jsonl, here)")
    ap.add_argument("--cco", action="store_true", help="score our CCO (grown here) instead of svv's trees")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0], help="our CCO's seeds (with --cco)")
    ap.add_argument(
        "--quick",
        action="store_true",
        help="the committed svv trees of N = 1000 and our CCO at N = 100, into a temporary rows file",
    )
    args = ap.parse_args(argv)
    if args.quick:
        with tempfile.TemporaryDirectory() as tmp:
            rows = Path(tmp) / "rows.jsonl"
            append(score(1000, Path(__file__).with_name("trees"), "N1000"), rows)
            append(score_cco(100, 0), rows)
        return
    rows = args.rows or Path(__file__).with_name("rows_cco.jsonl" if args.cco else "rows.jsonl")
    for n in args.n:
        if args.cco:
            for seed in args.seeds:
                append(score_cco(n, seed), rows)
        else:
            append(score(n, args.dir, f"N{n}{args.tag}"), rows)


if __name__ == "__main__":
    main()
