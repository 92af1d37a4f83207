"""Full-field reference k*/kappa of SC, BCC and FCC cells and a small cluster, against the isolated network.

Usage: PYTHONPATH=. python benchmarks/fullfield_cells.py [--ar 0.22,0.16,...] [--kinds SC,FCC,BCC] [--no-cluster]
       PYTHONPATH=. python benchmarks/fullfield_cells.py --rizza-only   (adds Rizza & Galati's cell, minutes)
       PYTHONPATH=. python benchmarks/fullfield_cells.py --cluster-only | --refit

Issue 40, part 3: the independent reference the coupled network is tested against. For each cell it solves
steady conduction in the solid on three voxel grids refined by sqrt(2) (tests/fullfield.py: finite volumes,
Rojek's volume-conserving neck, the eighth of the conventional cell between isothermal mirror planes),
extrapolates (Richardson), and evaluates the project's isolated network (sum of Rojek pair laws) on the same
necks. Rewrites tests/data/fullfield_cells.csv after every row (minutes in all; a script, not a test).
Needs scipy and, for speed, pyamg (5.2.1).
"""

from __future__ import annotations

import argparse
import csv
import datetime
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

import fullfield as ff  # noqa: E402
from scipy.interpolate import CubicSpline  # noqa: E402

CSV = ROOT / "tests" / "data" / "fullfield_cells.csv"
MD = CSV.with_suffix(".md")
FE = ROOT / "tests" / "data" / "fe_neck_conductance.csv"
RATIO = np.sqrt(2.0)
FIELDS = ["structure", "a_over_r", "h_over_r", "quantity", "n_voxels", "value_grids", "order", "plain_finest",
          "fullfield", "err_est", "network", "ratio", "ratio_err", "coupled", "coupled_ratio", "pair_law_over_fe", "fe_pair",
          "seconds"]


def fe_half(a_over_r):
    """K_i/(kappa pi r) of one half of Rojek's neck geometry from the independent FE data (cubic spline)."""
    with open(FE) as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    x = np.array([float(row["a_over_r"]) for row in rows])
    y = np.array([float(row["K_over_Kcyl"]) for row in rows])
    return float(CubicSpline(x, y)(a_over_r))


def grids(kind, a_over_r, half):
    """Three cube sizes (voxels a side of the eighth cell), neck resolution a/h about 5.7, 8, 11.3 (4, 5.7, 8
    below a/r = 0.15, where the finer grids would not fit a few tens of seconds), at least 24 voxels."""
    n0 = max(half / a_over_r * (4.0 if a_over_r < 0.15 else 5.66), 24.0)
    return [int(round(n0 * RATIO ** k)) for k in range(3)]


def lattice_row(kind, a_over_r):
    length, sites, cylinders, h = ff.lattice_geometry(kind, a_over_r)
    t0 = time.perf_counter()
    ns = grids(kind, a_over_r, length / 2)
    values = [ff.solve_lattice(length, sites, 1.0, n, cylinders).k_star for n in ns]
    plain = ff.solve_lattice(length, sites, 1.0, ns[-1], cylinders, split=False).k_star
    ext, err, p = ff.richardson(values, RATIO)
    net = ff.network_lattice_kstar(kind, a_over_r, length)
    fe = np.pi * fe_half(a_over_r) / 2.0 / (2.0 - h) if kind == "SC" else float("nan")
    return finish(dict(structure=kind, a_over_r=a_over_r, h_over_r=h, quantity="k_star_over_kappa",
                       n_voxels=";".join(map(str, ns)), value_grids=";".join(f"{v:.6g}" for v in values), order=p,
                       plain_finest=plain,
                       fullfield=ext, err_est=err, network=net, ratio=net / ext, ratio_err=net / ext * err / ext,
                       fe_pair=fe, seconds=time.perf_counter() - t0))


RIZZA_NECKS = {2.5: (6.31, 5.96), 5.5: (7.48, 7.02), 9.5: (8.62, 8.09)}  # Table 3: x (um), couples 1 and 2


def rizza_row(time_s):
    """Rizza & Galati (2024)'s BCC cell at ``time_s`` (Table 3's neck radii; corner spheres 80 um)."""
    a1, a2 = RIZZA_NECKS[time_s]
    length, r2, sites, radii, cylinders = ff.rizza_bcc_geometry(a1, a2)
    half = length / 2
    t0 = time.perf_counter()
    n0 = half / min(a1, a2) * 5.66
    ns = [int(round(n0 * RATIO ** k)) for k in range(3)]
    values = [ff.solve_lattice(length, sites, radii, n, cylinders).k_star for n in ns]
    plain = ff.solve_lattice(length, sites, radii, ns[-1], cylinders, split=False).k_star
    _, _, p = ff.richardson(values, RATIO)
    net = ff.network_rizza_kstar(length, a1, a2)
    return finish(dict(structure=f"BCC_RG_{time_s}s", a_over_r=a1 / 40.0, h_over_r=(80.0 - length) / 40.0,
                       quantity=f"k_star_over_kappa (r_centre {r2:.3f} um)", n_voxels=";".join(map(str, ns)),
                       value_grids=";".join(f"{v:.6g}" for v in values), order=p, plain_finest=plain,
                       fullfield=values[-1], err_est=0.0, network=net, ratio=0.0, ratio_err=0.0,
                       fe_pair=float("nan"), seconds=time.perf_counter() - t0))


def _on_circle(p1, d1, p2, d2):
    """Centre, radius and two unit axes of the circle of points at distance d1 from p1 and d2 from p2."""
    dist = np.linalg.norm(p2 - p1)
    e = (p2 - p1) / dist
    x = (d1 * d1 - d2 * d2 + dist * dist) / (2 * dist)
    rho = np.sqrt(d1 * d1 - x * x)
    u = np.cross(e, [0.0, 0.0, 1.0]) if abs(e[2]) < 0.9 else np.cross(e, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return p1 + x * e, rho, u, np.cross(e, u)


def _place(p1, d1, p2, d2, weight):
    """The point at distances d1, d2 from p1, p2 maximising ``weight . point``."""
    c, rho, u, v = _on_circle(p1, d1, p2, d2)
    phi = np.arctan2(weight @ v, weight @ u)
    return c + rho * (np.cos(phi) * u + np.sin(phi) * v)


def cluster_geometry(seed=40):
    """Seven spheres (r = 1 +- 10 %) between plates z = 0 and z = H: A, B held on the hot plate (centres on
    it: the plate is an isothermal plane through them), C, D, E, F free, G held on the cold plate. Each
    sphere is placed against two earlier ones (overlaps h/r ~ 0.015-0.045, Rojek necks a/r ~ 0.17-0.3):
    C on A, B; D on B, C; E on A, C; F on C, E (a side loop); G above D. Deterministic."""
    rng = np.random.default_rng(seed)
    r = 1.0 + 0.1 * rng.uniform(-1, 1, 7)

    def dist(i, j):
        return r[i] + r[j] - rng.uniform(0.015, 0.045) * min(r[i], r[j])

    c = np.zeros((7, 3))
    c[1] = [2.5, 0.0, 0.0]
    c[2] = _place(c[0], dist(0, 2), c[1], dist(1, 2), np.array([0.0, 0.0, 1.0]))
    c[3] = _place(c[1], dist(1, 3), c[2], dist(2, 3), np.array([0.3, 0.5, 1.0]))
    c[4] = _place(c[0], dist(0, 4), c[2], dist(2, 4), np.array([-0.3, -0.5, 1.0]))
    c[5] = _place(c[2], dist(2, 5), c[4], dist(4, 5), np.array([0.0, -1.0, 0.2]))
    c[6] = c[3] + [0.0, 0.0, dist(3, 6)]
    if c[5, 2] + r[5] >= c[6, 2] or min(c[2:6, 2] - r[2:6]) <= 0:
        raise ValueError("a free sphere reaches a plate")
    return c, r


def cluster_row():
    centres, radii = cluster_geometry()
    pairs, cylinders = ff.necks(centres, radii)
    hot = centres[:, 2] == 0.0
    cold = centres[:, 2] == centres[:, 2].max()
    lo = np.array([centres[:, 0].min() - 1.15, centres[:, 1].min() - 1.15, 0.0])
    hi = np.array([centres[:, 0].max() + 1.15, centres[:, 1].max() + 1.15, centres[:, 2].max()])
    t0 = time.perf_counter()
    h0 = 0.06  # voxel side (r ~ 1): neck a/h ~ 2.9-4.8 coarse, 5.7-9.7 fine (about 1 GB, minutes)
    ns = []
    values = []
    for k in range(3):
        hk = h0 / RATIO ** k
        shape = np.maximum(np.round((hi - lo) / hk).astype(int), 1)
        ns.append("x".join(map(str, shape)))
        values.append(ff.solve_box_split(centres, radii, lo, hi, shape, axis=2, cylinders=cylinders).conductance)
    plain = ff.solve_box(centres, radii, lo, hi, shape, axis=2, cylinders=cylinders).conductance
    ext, err, p = ff.richardson(values, RATIO)
    net = ff.network_cluster_conductance(len(centres), pairs, hot, cold)
    mean_ar = float(np.mean([p[2] / min(radii[p[0]], radii[p[1]]) for p in pairs]))
    return finish(dict(structure="cluster7", a_over_r=mean_ar, h_over_r=float("nan"), quantity="Q_over_kappa_dT_r",
                n_voxels=";".join(ns), value_grids=";".join(f"{v:.6g}" for v in values), order=p,
                plain_finest=plain,
                fullfield=ext, err_est=err, network=net, ratio=net / ext, ratio_err=net / ext * err / ext,
                fe_pair=float("nan"), seconds=time.perf_counter() - t0))


def bracket(split, plain):
    """Reference value and error from the two schemes on the finest grid.

    The split scheme converges from below (no heat crosses a void wedge; the staircase neck is too thin),
    the plain scheme (its voxels join the two sides of the wedge) from above, on every cell here but within
    0.2 % on the SC pair at a/r = 0.3. Richardson on three grids is not reliable here: the sequences
    oscillate by 0.3 % as the neck's staircase moves against the grid, and the BCC/FCC split sequences are
    not yet asymptotic (their increments grow). So: the midpoint, with half the bracket as the error, and
    never less than 0.5 % (the SC cells' distance from the independent FE pair, in the .md)."""
    mid = 0.5 * (split + plain)
    return mid, max(0.5 * abs(plain - split), 0.005 * mid)


def finish(r):
    """Fill a row's derived columns from its value_grids, network and geometry."""
    values = [float(v) for v in r["value_grids"].split(";")]
    _, _, p = ff.richardson(values, RATIO)
    ext, err = bracket(values[-1], r["plain_finest"])
    r.update(fullfield=ext, err_est=err, order=p, ratio=r["network"] / ext, ratio_err=r["network"] / ext * err / ext)
    if r["structure"] in ff.LATTICES:
        ar = r["a_over_r"]
        length = (2.0 - r["h_over_r"]) / ff.LATTICES[r["structure"]][1]
        r["coupled"] = ff.coupled_lattice_kstar(r["structure"], ar, length)
        r["coupled_ratio"] = r["coupled"] / ext
        r["pair_law_over_fe"] = ff.ROJEK_SLOPE * ar / fe_half(ar)
    else:
        r.update(coupled=float("nan"), coupled_ratio=float("nan"), pair_law_over_fe=float("nan"))
    return r


def read():
    """The rows of the existing CSV, numbers as floats."""
    with open(CSV) as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    keep = ("structure", "quantity", "n_voxels", "value_grids")
    return [{k: (v if k in keep else float(v)) for k, v in r.items() if k in FIELDS} for r in rows]


def write(rows, command):
    CSV.parent.mkdir(exist_ok=True)
    with open(CSV, "w", newline="") as f:
        f.write("# Full-field reference conductivities of sphere cells with Rojek's volume-conserving necks (issue 40).\n")
        f.write(f"# Written by: {command}  on {datetime.date.today().isoformat()} (tests/fullfield.py, see"
                " tests/data/fullfield_cells.md).\n")
        f.write("# value_grids: k of the split scheme on the n_voxels grids (refined by sqrt 2); order: their observed"
                " Richardson order (nan: oscillating or not asymptotic); plain_finest: the plain scheme on the finest"
                " grid; fullfield: midpoint of the finest split and plain values; err_est: half their spread, at"
                " least 0.5 %; network: isolated sum-of-pair-laws (Rojek Eq. 45);"
                " ratio = network/fullfield; fe_pair: SC only, k* from the independent FE pair half.\n")
        w = csv.DictWriter(f, FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def write_md(rows, command):
    """The table of tests/data/fullfield_cells.md (between its markers; the prose around it is kept)."""
    lines = ["| structure | a/r | full-field k*/kappa | network (isolated) | network / full-field | coupled (note) / "
             "full-field | Rojek pair law / FE pair |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['structure']} | {r['a_over_r']:.3g} | {r['fullfield']:.4f} +- {r['err_est']:.4f} | "
                     f"{r['network']:.4f} | {r['ratio']:.3f} +- {r['ratio_err']:.3f} | "
                     f"{r['coupled_ratio']:.3f} | {r['pair_law_over_fe']:.3f} |")
    table = "\n".join(lines)
    stamp = f"Written by `{command}` on {datetime.date.today().isoformat()}."
    text = MD.read_text() if MD.exists() else "<!-- table -->\n<!-- /table -->\n"
    head, rest = text.split("<!-- table -->", 1)
    tail = rest.split("<!-- /table -->", 1)[1]
    MD.write_text(f"{head}<!-- table -->\n{stamp}\n\n{table}\n<!-- /table -->{tail}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ar", default="0.22,0.16,0.3,0.4")
    ap.add_argument("--kinds", default="SC,FCC,BCC")
    ap.add_argument("--no-cluster", action="store_true")
    ap.add_argument("--cluster-only", action="store_true", help="recompute the cluster row of the existing CSV")
    ap.add_argument("--rizza-only", action="store_true",
                    help="recompute the rows of Rizza & Galati's BCC cell (2.5, 5.5, 9.5 s) in the existing CSV")
    ap.add_argument("--add", action="store_true", help="keep the existing CSV's other rows (replace same cells)")
    ap.add_argument("--refit", action="store_true",
                    help="recompute fullfield, err_est, order and ratio of the existing CSV from its value_grids")
    args = ap.parse_args()
    command = "PYTHONPATH=. python benchmarks/fullfield_cells.py " + " ".join(sys.argv[1:])
    if args.refit or args.cluster_only or args.rizza_only:
        rows = read()
        if args.rizza_only:
            rows = [r for r in rows if not r["structure"].startswith("BCC_RG")]
            for t in RIZZA_NECKS:
                rows.append(rizza_row(t))
                print(rows[-1], flush=True)
                write(rows, command)
        if args.cluster_only:
            rows = [r for r in rows if not r["structure"].startswith("cluster")] + [cluster_row()]
            print(rows[-1], flush=True)
        for r in rows:
            finish(r)
        write(rows, command)
        write_md(rows, command)
        return
    rows = read() if args.add else []
    for k, ar in enumerate(map(float, args.ar.split(","))):
        if k == 1 and not (args.no_cluster or args.add):
            rows.append(cluster_row())
            write(rows, command)
            print(rows[-1], flush=True)
        for kind in args.kinds.split(","):
            row = lattice_row(kind, ar)
            rows = [r for r in rows if not (r["structure"] == kind and r["a_over_r"] == ar)] + [row]
            write(rows, command)
            print(f"{kind:4s} a/r={ar:.2f} grids {row['n_voxels']:>12s} {row['value_grids']:>28s} "
                  f"ff={row['fullfield']:.5f}+-{row['err_est']:.5f} net={row['network']:.5f} "
                  f"ratio={row['ratio']:.4f} fe={row['fe_pair']:.5f} {row['seconds']:.0f}s", flush=True)
    write_md(rows, command)


if __name__ == "__main__":
    main()
