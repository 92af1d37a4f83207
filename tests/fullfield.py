"""Full-field verification solver: steady conduction in the solid of a cell of overlapping spheres.

An independent reference for the conductance network (issue 40, part 3), NOT the library's hot path. The
solve imports nothing from ``sintercond``; the geometry takes the project's neck radius
(``sintercond.laws.neck.neck_radius``) so that the network (:func:`network_lattice_kstar`,
:func:`network_cluster_conductance`) and the full field see the same necks. Reference values, method and
errors: ``tests/data/fullfield_cells.md`` (written by ``benchmarks/fullfield_cells.py``).

Geometry: spheres (centre ``c_s``, radius ``r_s``); two closer than ``r_i + r_j`` (overlap ``h``) share a
neck of one of two shapes (:func:`necks`). ``"rojek"`` (default, the project's own neck): Rojek et al. (2022)'s
volume-conserving cylinder of radius ``a = sintercond.laws.neck.neck_radius(r_i, r_j, h)`` between the two cut
spheres, the geometry the pair law ``K = 1.064 kappa pi a / 2`` was fitted on. ``"lens"``: the plain union
of the spheres, ``a`` their intersection circle. The network side is evaluated with exactly the same ``a``.

Discretisation: finite volumes on a voxel grid of the box ``[lo, hi]``, one unknown per voxel that holds
solid. Each voxel carries the solid fraction of ``sub^3`` sub-cells (centre-point test); the conductance of
the face between two neighbouring voxels is ``kappa * (face area / spacing) * f``, with ``f`` the solid
fraction of the two sub-cell layers that touch the face (a 7-point Laplacian whose face areas follow the
solid; ``sub = 1`` is the plain staircase scheme, where a face conducts only between two solid voxels).
No flux crosses the solid/void surface or the box's side faces (Neumann: insulated walls, or mirror planes
of a lattice). The two box faces normal to ``axis`` are held at ``T = 1`` (``lo``) and ``T = 0`` (``hi``),
each voxel touching one linked to it over half a spacing. ``Q`` is the heat entering at ``lo``. This
*plain* scheme (:func:`solve_box`) joins two spheres through any voxel that holds both, across the thin void
wedge beside a neck, and over-conducts; the *split* scheme (:func:`solve_box_split`, the default of
:func:`solve_lattice`) keeps one unknown per sphere in such a voxel and joins spheres only through the neck
disc, and under-conducts through the staircase neck. The reference is the midpoint of the two.

Symmetric cells: for a cubic lattice (SC, BCC, FCC) the planes ``x = 0`` and ``x = L/2`` of the conventional
cell (side ``L``) are mirror planes, so under an imposed mean gradient along ``x`` the temperature is odd
about each and both are isothermal; the transverse planes ``y, z = 0, L/2`` are mirror planes with no flux.
The eighth ``[0, L/2]^3`` between held faces is therefore the exact periodic problem, and
``k* = Q (L/2) / (L/2)^2`` per unit ``kappa`` and temperature difference (:func:`solve_lattice`).

Solve: symmetric positive-definite sparse system, conjugate gradients preconditioned by pyamg's classical
(Ruge-Stuben) AMG V-cycle when pyamg is installed (benchmarks), else by Jacobi (tiny test grids).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import cg

ROJEK_SLOPE = 1.064  # Rojek et al. (2022) Eq. 40/43: each half K_i = 1.064 kappa pi a


@dataclasses.dataclass
class FieldResult:
    conductance: float   # Q / (kappa (T_hot - T_cold)), length units of the box
    k_star: float        # k*/kappa = conductance * L_axis / A_cross
    spacing: tuple       # voxel spacing per axis
    shape: tuple         # voxels per axis
    unknowns: int
    imbalance: float     # |Q_in - Q_out| / Q_in (solver check)


def intersection_neck_radius(r_i, r_j, d):
    """Radius of the intersection circle of two spheres of radii ``r_i``, ``r_j`` with centres ``d`` apart."""
    x = (d * d + r_i * r_i - r_j * r_j) / (2.0 * d)
    return float(np.sqrt(max(r_i * r_i - x * x, 0.0)))


def _voxel_fractions(centres, radii, lo, h, shape, sub, inside_fn=None, cylinders=()):
    """Per voxel: solid volume fraction and the solid fraction of its 6 face layers (``lo``/``hi`` per axis).

    ``inside_fn(x, y, z)`` (broadcast coordinate arrays -> bool), if given, adds its solid to the spheres'."""
    centres = np.asarray(centres, float)
    radii = np.asarray(radii, float)
    nx, ny, nz = shape
    # fine (sub-cell) centre coordinates along y and z, whole range
    fy = lo[1] + (np.arange(ny * sub) + 0.5) * h[1] / sub
    fz = lo[2] + (np.arange(nz * sub) + 0.5) * h[2] / sub
    out = {k: np.empty(shape, np.float32) for k in ("vol", "x0", "x1", "y0", "y1", "z0", "z1")}
    slab = max(1, int(4e6 // (ny * nz * sub ** 3)))
    for i0 in range(0, nx, slab):
        i1 = min(nx, i0 + slab)
        fx = lo[0] + (np.arange(i0 * sub, i1 * sub) + 0.5) * h[0] / sub
        inside = np.zeros((fx.size, fy.size, fz.size), bool)
        if inside_fn is not None:
            inside |= inside_fn(fx[:, None, None], fy[None, :, None], fz[None, None, :])
        for p0, p1, rad in cylinders:
            _add_cylinder(inside, fx, fy, fz, np.asarray(p0, float), np.asarray(p1, float), rad)
        for c, r in zip(centres, radii):
            dx2 = (fx - c[0]) ** 2
            dy2 = (fy - c[1]) ** 2
            dz2 = (fz - c[2]) ** 2
            if dx2.min() + dy2.min() + dz2.min() >= r * r:
                continue
            ix = np.nonzero(dx2 < r * r)[0]
            iy = np.nonzero(dy2 < r * r)[0]
            iz = np.nonzero(dz2 < r * r)[0]
            sl = (slice(ix[0], ix[-1] + 1), slice(iy[0], iy[-1] + 1), slice(iz[0], iz[-1] + 1))
            inside[sl] |= (dx2[sl[0], None, None] + dy2[None, sl[1], None] + dz2[None, None, sl[2]]) < r * r
        b = inside.reshape(i1 - i0, sub, ny, sub, nz, sub)
        out["vol"][i0:i1] = b.mean(axis=(1, 3, 5))
        out["x0"][i0:i1] = b[:, 0].mean(axis=(2, 4))
        out["x1"][i0:i1] = b[:, -1].mean(axis=(2, 4))
        out["y0"][i0:i1] = b[:, :, :, 0].mean(axis=(1, 4))
        out["y1"][i0:i1] = b[:, :, :, -1].mean(axis=(1, 4))
        out["z0"][i0:i1] = b[..., 0].mean(axis=(1, 3))
        out["z1"][i0:i1] = b[..., -1].mean(axis=(1, 3))
    return out


def _add_cylinder(inside, fx, fy, fz, p0, p1, rad):
    """Mark the fine points inside the solid cylinder of radius ``rad`` with axis from ``p0`` to ``p1``."""
    lo = np.minimum(p0, p1) - rad
    hi = np.maximum(p0, p1) + rad
    ix = np.nonzero((fx > lo[0]) & (fx < hi[0]))[0]
    iy = np.nonzero((fy > lo[1]) & (fy < hi[1]))[0]
    iz = np.nonzero((fz > lo[2]) & (fz < hi[2]))[0]
    if not (ix.size and iy.size and iz.size):
        return
    length = float(np.linalg.norm(p1 - p0))
    u = (p1 - p0) / length
    x = fx[ix[0]:ix[-1] + 1, None, None] - p0[0]
    y = fy[None, iy[0]:iy[-1] + 1, None] - p0[1]
    z = fz[None, None, iz[0]:iz[-1] + 1] - p0[2]
    t = x * u[0] + y * u[1] + z * u[2]
    perp2 = x * x + y * y + z * z - t * t
    inside[ix[0]:ix[-1] + 1, iy[0]:iy[-1] + 1, iz[0]:iz[-1] + 1] |= (t >= 0) & (t <= length) & (perp2 < rad * rad)


def _solve_spd(a, b, tol, use_amg):
    if use_amg:
        try:
            import pyamg
        except ImportError:
            use_amg = False
    if use_amg:
        m = pyamg.ruge_stuben_solver(a, max_coarse=500).aspreconditioner(cycle="V")
    else:
        m = sp.diags(1.0 / a.diagonal())
    x, info = cg(a, b, rtol=tol, atol=0.0, maxiter=20 * a.shape[0], M=m)
    if info != 0:
        raise RuntimeError(f"preconditioned CG did not converge (info {info})")
    return x


def solve_box(centres, radii, lo, hi, shape, axis=0, sub=2, tol=1e-10, use_amg=True, inside_fn=None,
              cylinders=()) -> FieldResult:
    """Steady conduction (``kappa = 1``) in the union of spheres clipped to the box ``[lo, hi]``.

    ``shape`` voxels per axis; faces normal to ``axis`` held at 1 (``lo``) and 0 (``hi``), the other four
    insulated. ``cylinders``: ``(p0, p1, a)`` solid cylinders added to the spheres (the necks of
    :func:`rojek_necks`); ``inside_fn`` adds solid of another shape (tests: a rod). Returns :class:`FieldResult`.
    """
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    shape = tuple(int(n) for n in shape)
    h = (hi - lo) / np.asarray(shape)
    fr = _voxel_fractions(np.reshape(centres, (-1, 3)), np.ravel(radii), lo, h, shape, sub, inside_fn, cylinders)
    solid = fr["vol"] > 0
    index = -np.ones(shape, np.int64)
    n = int(solid.sum())
    index[solid] = np.arange(n)
    rows, cols, vals = [], [], []
    names = "xyz"
    for ax in range(3):
        area = np.prod(np.delete(h, ax))
        g0 = area / h[ax]
        sl_a = [slice(None)] * 3
        sl_b = [slice(None)] * 3
        sl_a[ax] = slice(0, -1)
        sl_b[ax] = slice(1, None)
        sl_a, sl_b = tuple(sl_a), tuple(sl_b)
        if sub == 1:
            f = (solid[sl_a] & solid[sl_b]).astype(float)
        else:
            f = 0.5 * (fr[names[ax] + "1"][sl_a].astype(float) + fr[names[ax] + "0"][sl_b])
        ia, ib = index[sl_a], index[sl_b]
        keep = (ia >= 0) & (ib >= 0) & (f > 0)
        ia, ib, g = ia[keep], ib[keep], g0 * f[keep]
        rows += [ia, ib, ia, ib]
        cols += [ib, ia, ia, ib]
        vals += [-g, -g, g, g]
    # held faces
    area = np.prod(np.delete(h, axis))
    gb0 = area / (0.5 * h[axis])
    held = []
    for side, key in ((0, names[axis] + "0"), (shape[axis] - 1, names[axis] + "1")):
        sl = [slice(None)] * 3
        sl[axis] = side
        sl = tuple(sl)
        f = solid[sl].astype(float) if sub == 1 else fr[key][sl].astype(float)
        idx = index[sl]
        keep = (idx >= 0) & (f > 0)
        held.append((idx[keep], gb0 * f[keep]))
        rows.append(idx[keep])
        cols.append(idx[keep])
        vals.append(gb0 * f[keep])
    return _held_solve(sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                     shape=(n, n)).tocsr(), held, lo, hi, axis, (tuple(h), shape), tol, use_amg)


def solve_box_split(centres, radii, lo, hi, shape, axis=0, sub=2, tol=1e-10, use_amg=True,
                    cylinders=()) -> FieldResult:
    """As :func:`solve_box`, but a voxel holding the solid of several spheres has one unknown per sphere.

    Each solid sub-cell belongs to the sphere of least power ``|x - c|^2 - r^2`` (the radical plane of two
    spheres is their neck plane), so a voxel that straddles the thin void wedge beside a neck no longer joins
    the two spheres across it: heat passes between spheres only where solid sub-cells of both touch, i.e.
    through the neck disc. Conductances: ``kappa * (sub-face area) / (voxel spacing)`` per pair of adjacent
    solid sub-cells in different voxels or of different spheres (the plain scheme's face fraction, counted
    per sphere); each solid sub-cell of a held face's layer links its unknown to the face over half a spacing.
    """
    centres = np.reshape(np.asarray(centres, float), (-1, 3))
    radii = np.ravel(np.asarray(radii, float))
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    shape = tuple(int(n) for n in shape)
    h = (hi - lo) / np.asarray(shape)
    fshape = tuple(n * sub for n in shape)
    f = [lo[k] + (np.arange(fshape[k]) + 0.5) * h[k] / sub for k in range(3)]
    best = np.full(fshape, np.inf, np.float32)
    lab = np.full(fshape, -1, np.int32)
    for k, (c, r) in enumerate(zip(centres, radii)):
        reach = 1.25 * r
        idx = [np.nonzero(np.abs(f[d] - c[d]) < reach)[0] for d in range(3)]
        if not all(i.size for i in idx):
            continue
        sl = tuple(slice(i[0], i[-1] + 1) for i in idx)
        pw = ((f[0][sl[0]] - c[0]) ** 2)[:, None, None] + ((f[1][sl[1]] - c[1]) ** 2)[None, :, None] \
            + ((f[2][sl[2]] - c[2]) ** 2)[None, None, :] - r * r
        sub_best = best[sl]
        better = pw < sub_best
        sub_best[better] = pw[better]
        lab[sl][better] = k
    solid = best < 0
    for p0, p1, rad in cylinders:
        _add_cylinder(solid, f[0], f[1], f[2], np.asarray(p0, float), np.asarray(p1, float), rad)
    del best
    lab[~solid] = -1
    n_lab = max(len(centres), 1)
    ii, jj, kk = (np.arange(fshape[d]) // sub for d in range(3))
    vox = (ii[:, None, None] * shape[1] + jj[None, :, None]) * shape[2] + kk[None, None, :]
    key = np.where(solid, vox.astype(np.int64) * n_lab + lab, -1)
    del vox
    nodes = np.unique(key[solid])
    n = nodes.size
    rows, cols, vals = [], [], []
    for ax in range(3):
        g = np.prod(np.delete(h, ax)) / sub ** 2 / h[ax]
        sa = [slice(None)] * 3
        sb = [slice(None)] * 3
        sa[ax] = slice(0, -1)
        sb[ax] = slice(1, None)
        ka, kb = key[tuple(sa)], key[tuple(sb)]
        cross_voxel = (np.arange(fshape[ax] - 1) % sub == sub - 1)
        cshape = [1, 1, 1]
        cshape[ax] = -1
        m = (ka >= 0) & (kb >= 0) & (cross_voxel.reshape(cshape) | (ka != kb))
        ia = np.searchsorted(nodes, ka[m])
        ib = np.searchsorted(nodes, kb[m])
        keep = ia != ib
        ia, ib = ia[keep], ib[keep]
        gv = np.full(ia.size, g)
        rows += [ia, ib, ia, ib]
        cols += [ib, ia, ia, ib]
        vals += [-gv, -gv, gv, gv]
    gb = np.prod(np.delete(h, axis)) / sub ** 2 / (0.5 * h[axis])
    held = []
    for side in (0, fshape[axis] - 1):
        sl = [slice(None)] * 3
        sl[axis] = side
        kl = key[tuple(sl)]
        idx = np.searchsorted(nodes, kl[kl >= 0])
        uniq, counts = np.unique(idx, return_counts=True)
        held.append((uniq, gb * counts))
        rows.append(uniq)
        cols.append(uniq)
        vals.append(gb * counts)
    del key
    return _held_solve(sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                     shape=(n, n)).tocsr(), held, lo, hi, axis, (tuple(h), shape), tol, use_amg)


# --- cubic lattices ---------------------------------------------------------------------------------------

LATTICES = {
    # sites of the conventional cell (units of L) and nearest-neighbour distance / L
    "SC": (np.array([[0, 0, 0]]), 1.0),
    "BCC": (np.array([[0, 0, 0], [0.5, 0.5, 0.5]]), np.sqrt(3) / 2),
    "FCC": (np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]]), 1 / np.sqrt(2)),
}


def overlap_for_neck(a_over_r):
    """Overlap ``h/r`` of two equal spheres whose volume-conserving neck (the project's
    :func:`sintercond.laws.neck.neck_radius`, Rojek Eqs. 19-20) has radius ``a/r``."""
    from scipy.optimize import brentq

    from sintercond.laws.neck import max_overlap, neck_radius

    hmax = float(max_overlap(1.0, 1.0))
    return brentq(lambda h: float(neck_radius(1.0, 1.0, h)) - a_over_r, 1e-12, hmax * (1 - 1e-12), xtol=1e-14)


def necks(centres, radii, shape="rojek"):
    """Contacts of the spheres: ``(pairs, cylinders)``; ``pairs`` rows ``(i, j, a, h)`` with the neck radius
    ``a`` of ``shape`` and overlap ``h``; ``cylinders`` the ``(p0, p1, a)`` solid necks to add to the spheres.

    ``shape="rojek"``: Rojek et al. (2022)'s volume-conserving neck, the project's model: each sphere is cut
    where its section has radius ``a`` (``sqrt(r^2 - a^2)`` from its centre) and a cylinder of radius ``a``
    joins the two cuts; ``a`` is :func:`sintercond.laws.neck.neck_radius`. Since a sphere's cap beyond the cut
    lies inside that cylinder, the solid is the union of the spheres and the cylinders.
    ``shape="lens"``: the plain union of the spheres, ``a`` the radius of their intersection circle.
    """
    from sintercond.laws.neck import neck_radius

    centres = np.asarray(centres, float)
    radii = np.asarray(radii, float)
    pairs, cylinders = [], []
    for i in range(len(centres)):
        for j in range(i + 1, len(centres)):
            v = centres[j] - centres[i]
            d = float(np.linalg.norm(v))
            h = radii[i] + radii[j] - d
            if h <= 0:
                continue
            if shape == "lens":
                a = intersection_neck_radius(radii[i], radii[j], d)
            else:
                a = float(neck_radius(radii[i], radii[j], h))
                xi = np.sqrt(radii[i] ** 2 - a * a)
                xj = np.sqrt(radii[j] ** 2 - a * a)
                if xi + xj > d + 1e-12:
                    raise ValueError(f"neck {i}-{j}: cuts overlap (x_i + x_j = {xi + xj} > d = {d})")
                u = v / d
                cylinders.append((centres[i] + xi * u, centres[j] - xj * u, a))
            pairs.append((i, j, a, h))
    return pairs, cylinders


def lattice_geometry(kind, a_over_r, shape="rojek"):
    """Equal spheres of radius ``r = 1`` on a cubic lattice whose nearest-neighbour necks have radius
    ``a = a_over_r`` (neck ``shape`` as in :func:`necks`). Returns ``(L, sites, cylinders, h)``: the
    conventional cell side, every sphere touching the eighth ``[0, L/2]^3``, the neck cylinders touching
    it, and the overlap ``h``."""
    basis, dnn = LATTICES[kind]
    if shape == "lens":
        h = 2.0 - 2.0 * np.sqrt(1.0 - a_over_r ** 2)
    else:
        h = overlap_for_neck(a_over_r)
    length = (2.0 - h) / dnn
    shifts = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], float)
    sites = (basis[None, :, :] + shifts[:, None, :]).reshape(-1, 3) * length
    half = length / 2
    sites = sites[np.all((sites > -1.5) & (sites < half + 1.5), axis=1)]
    pairs, cylinders = necks(sites, np.ones(len(sites)), shape)
    a = np.array([p[2] for p in pairs])
    if not np.allclose(a, a_over_r, rtol=1e-9, atol=0):
        raise ValueError(f"{kind}: second neighbours overlap at a/r = {a_over_r}")
    near = np.all((sites > -1) & (sites < half + 1), axis=1)
    cylinders = [c for c in cylinders
                 if np.all(np.minimum(c[0], c[1]) < half + c[2]) and np.all(np.maximum(c[0], c[1]) > -c[2])]
    return length, sites[near], cylinders, h


def rizza_bcc_geometry(a_corner, a_centre, r_corner=40.0):
    """BCC cell of Rizza & Galati (2024) with Rojek necks: corner spheres of radius ``r_corner`` (80 um
    diameter) joined along the cube edges by necks ``a_corner`` (which sets the overlap, hence ``L``), and a
    centre sphere whose radius is chosen so that its neck with each corner sphere is ``a_centre`` (the
    paper's 58.6 um diameter and both necks cannot all hold with one ``L``). Returns
    ``(L, r_centre, sites, radii, cylinders)``, spheres and necks touching the eighth ``[0, L/2]^3``."""
    from scipy.optimize import brentq

    from sintercond.laws.neck import max_overlap, neck_radius

    hmax = float(max_overlap(r_corner, r_corner))
    h1 = brentq(lambda h: float(neck_radius(r_corner, r_corner, h)) - a_corner, 1e-12 * r_corner, hmax * (1 - 1e-12))
    length = 2.0 * r_corner - h1
    dc = np.sqrt(3) / 2 * length

    def miss(r2):
        h2 = r_corner + r2 - dc
        return (float(neck_radius(r_corner, r2, h2)) if h2 > 0 else 0.0) - a_centre

    grid = np.linspace(dc - r_corner + 1e-9, dc, 400)
    values = np.array([miss(r2) for r2 in grid])
    k = int(np.argmax(values > 0))  # first radius whose neck exceeds a_centre (neck grows with r2)
    r_centre = brentq(miss, grid[k - 1], grid[k], xtol=1e-12)
    shifts = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], float)
    sites = np.concatenate([shifts * length, (shifts + 0.5) * length])
    radii = np.concatenate([np.full(len(shifts), r_corner), np.full(len(shifts), r_centre)])
    half = length / 2
    near = np.all((sites > -radii[:, None] - half) & (sites < half + radii[:, None] + half), axis=1)
    sites, radii = sites[near], radii[near]
    _, cylinders = necks(sites, radii)
    touch = np.all((sites > -radii[:, None]) & (sites < half + radii[:, None]), axis=1)
    cylinders = [c for c in cylinders
                 if np.all(np.minimum(c[0], c[1]) < half + c[2]) and np.all(np.maximum(c[0], c[1]) > -c[2])]
    return length, float(r_centre), sites[touch], radii[touch], cylinders


def lattice_block(kind, a_over_r, cells=2):
    """Equal spheres (r = 1) of a cubic lattice whose nearest necks have radius ``a_over_r``: ``cells`` conventional
    cells along x between the held layers x = 0 and x = cells L, two cells across, periodic across x. Returns
    ``(centres, radii, L, kwargs)`` for ``sintercond.sim.steady.steady_state_conductivity`` (``box``, ``periodic_box``):
    the network's k* of the infinite lattice, its held layers being lattice mirror planes."""
    basis, dnn = LATTICES[kind]
    length = (2.0 - overlap_for_neck(a_over_r)) / dnn
    return _periodic_block(basis, np.ones(len(basis)), length, cells)


def rizza_block(a_corner, a_centre, cells=2):
    """Rizza & Galati (2024)'s BCC cell (:func:`rizza_bcc_geometry`: corner spheres of 40 um, a centre sphere sized
    for its neck), as :func:`lattice_block`: 14 necks on a corner sphere, 8 on a centre one."""
    length, r_centre, *_ = rizza_bcc_geometry(a_corner, a_centre)
    return _periodic_block(LATTICES["BCC"][0], np.array([40.0, r_centre]), length, cells)


def _periodic_block(basis, basis_radii, length, cells):
    sites, radii = [], []
    for i in range(cells + 1):
        for j in range(2):
            for k in range(2):
                for b, r in zip(basis, basis_radii):
                    if i + b[0] <= cells + 1e-9:
                        sites.append((np.array([i, j, k]) + b) * length)
                        radii.append(r)
    box = (np.array([-1e-9, 0.0, 0.0]), np.array([cells * length + 1e-9, 2 * length, 2 * length]))
    return np.array(sites), np.array(radii), length, dict(box=box, periodic_box=[1.0, 2 * length, 2 * length])



def solve_lattice(length, sites, radii, n, cylinders=(), sub=2, tol=1e-10, use_amg=True, split=True) -> FieldResult:
    """k*/kappa along x of a cubic cell of side ``length``: the eighth ``[0, L/2]^3``, ``n`` voxels a side
    (:func:`solve_box_split`, or :func:`solve_box` with ``split=False``)."""
    radii = np.broadcast_to(np.asarray(radii, float), (len(sites),))
    half = length / 2
    solver = solve_box_split if split else solve_box
    return solver(sites, radii, np.zeros(3), np.full(3, half), (n, n, n), axis=0, sub=sub, tol=tol,
                  use_amg=use_amg, cylinders=cylinders)


def network_lattice_kstar(kind, a_over_r, length, slope=ROJEK_SLOPE):
    """The isolated (sum-of-pair-laws) network's k*/kappa of an equal-sphere cubic lattice of cell side
    ``length`` with ``r = 1`` and necks ``a``: the affine field is exact on these centrosymmetric lattices, so
    ``k* = (1/V) sum_bonds K (d_x)^2`` with ``K = slope pi a / 2`` (Rojek Eq. 45: halves in series; this is
    :func:`sintercond.laws.conductance.rojek_pair_conductance` at the overlap whose neck is ``a``)."""
    k = slope * np.pi * a_over_r / 2.0
    bonds_dx2 = {"SC": 1.0, "BCC": 2.0, "FCC": 4.0}[kind]  # sum over a cell's bonds of (d_x / L)^2
    return k * bonds_dx2 / length


def coupled_lattice_kstar(kind, a_over_r, length, slope=ROJEK_SLOPE):
    """k*/kappa of the same lattice from the coupled neck network of /work/shared/NECK_COUPLING.md, for
    comparison only (not part of the reference): necks as point sources on the sphere (``r = 1``),
    ``T_s - T_i = q_i / K_self + sum_j q_j G(theta_ij)``, ``G = [1/s - 2 - ln(s (1 + s))] / (4 pi)`` with
    ``s = sin(theta/2)``, ``1/K_self = 1/K_half + G(pi)``, ``K_half = slope pi a``. Under a unit gradient
    along x the neck midway between two sites sits at their mean temperature (inversion centre), so
    ``T_s - T_i = -d_x,i / 2``; ``k* = -(1 / 2 V_site) sum_i q_i d_x,i``."""
    basis, dnn = LATTICES[kind]
    d = dnn * length
    cand = np.array([[i, j, k] for i in (-1, -0.5, 0, 0.5, 1) for j in (-1, -0.5, 0, 0.5, 1)
                     for k in (-1, -0.5, 0, 0.5, 1)], float) * length
    vec = cand[np.isclose(np.linalg.norm(cand, axis=1), d)]
    if kind == "FCC":
        vec = vec[np.isclose(np.abs(vec).sum(axis=1) / length, 1.0)]
    n = vec / d
    cos = np.clip(n @ n.T, -1.0, 1.0)
    sig = np.sqrt((1.0 - cos) / 2.0)
    off = ~np.eye(len(n), dtype=bool)
    g = np.zeros_like(cos)
    g[off] = (1.0 / sig[off] - 2.0 - np.log(sig[off] * (1.0 + sig[off]))) / (4.0 * np.pi)
    g_pi = -(1.0 + np.log(2.0)) / (4.0 * np.pi)
    g[~off] = 1.0 / (slope * np.pi * a_over_r) + g_pi
    dx = vec[:, 0]
    q = np.linalg.solve(g, -dx / 2.0)
    v_site = length ** 3 / len(basis)
    return float(-(q @ dx) / (2.0 * v_site))


def network_rizza_kstar(length, a_corner, a_centre, slope=ROJEK_SLOPE):
    """Isolated network k*/kappa of :func:`rizza_bcc_geometry`'s cell along x (affine field exact: every site
    is an inversion centre). Bonds per cell: 3 edge bonds (one along x, d_x = L), 8 corner-centre bonds
    (d_x = L/2)."""
    k1 = slope * np.pi * a_corner / 2.0
    k2 = slope * np.pi * a_centre / 2.0
    return (k1 * length ** 2 + 8 * k2 * (length / 2) ** 2) / length ** 3


def network_cluster_conductance(n, pairs, hot, cold, slope=ROJEK_SLOPE):
    """Q/(kappa dT) of the isolated network on a cluster of ``n`` spheres with contacts ``pairs`` (rows
    ``(i, j, a, h)`` of :func:`necks`): ``K = slope pi a / 2`` per contact, spheres ``hot`` held at 1 and
    ``cold`` at 0 (dense solve)."""
    lap = np.zeros((n, n))
    for i, j, a, _ in pairs:
        k = slope * np.pi * a / 2.0
        lap[[i, j], [i, j]] += k
        lap[i, j] -= k
        lap[j, i] -= k
    hot, cold = np.asarray(hot), np.asarray(cold)
    held = hot | cold
    t = np.where(hot, 1.0, 0.0)
    free = ~held
    t[free] = np.linalg.solve(lap[np.ix_(free, free)], -lap[np.ix_(free, held)] @ t[held])
    return float((lap[hot] @ t).sum())


def richardson(values, ratio):
    """Extrapolate three values on grids refined by ``ratio`` each (coarse to fine).

    Returns ``(value, error_estimate, order)``. When the two changes have the same sign and shrink with an
    observed order ``0.5 <= p <= 3``, ``value`` is the Richardson extrapolation and the error estimate its
    distance from the finest value (at least half the last change). Otherwise (the voxel values oscillate
    as the neck's staircase moves against the grid, or do not yet converge) ``value`` is the finest value,
    ``order`` is NaN, and the error estimate is the larger of the last change and half the first.
    """
    f1, f2, f3 = values
    d1, d2 = f2 - f1, f3 - f2
    if d1 * d2 > 0 and abs(d2) < abs(d1):
        p = float(np.log(abs(d1 / d2)) / np.log(ratio))
        if 0.5 <= p <= 3.0:
            ext = f3 + d2 / (ratio ** p - 1.0)
            return float(ext), float(max(abs(ext - f3), 0.5 * abs(d2))), p
    return float(f3), float(max(abs(d2), 0.5 * abs(d1))), float("nan")


def _held_solve(a, held, lo, hi, axis, grid, tol, use_amg) -> FieldResult:
    """Solve the assembled conductance matrix ``a`` with the hot (T = 1) and cold (T = 0) faces' conductances
    ``held = [(hot cells, g), (cold cells, g)]``, on the solid joined to a held face only (floating bits make the
    system singular): ``FieldResult`` with the heat in, k* = q L / A across ``axis``, and the balance's mismatch.
    ``grid``: ``(spacings, shape)`` of the voxels."""
    _, label = connected_components(a, directed=False)
    anchored = np.zeros(label.max() + 1, bool)
    anchored[label[held[0][0]]] = True
    anchored[label[held[1][0]]] = True
    live = anchored[label]
    renum = -np.ones(a.shape[0], np.int64)
    renum[live] = np.arange(int(live.sum()))
    a = a[live][:, live].tocsr()
    b = np.zeros(a.shape[0])
    hot_idx, hot_g = renum[held[0][0]], held[0][1]
    cold_idx, cold_g = renum[held[1][0]], held[1][1]
    np.add.at(b, hot_idx, hot_g)
    t = _solve_spd(a, b, tol, use_amg)
    q_in = float(np.sum(hot_g * (1.0 - t[hot_idx])))
    q_out = float(np.sum(cold_g * t[cold_idx]))
    length = hi[axis] - lo[axis]
    cross = float(np.prod(np.delete(hi - lo, axis)))
    return FieldResult(q_in, q_in * length / cross, *grid, int(a.shape[0]), abs(q_in - q_out) / max(abs(q_in), 1e-300))
