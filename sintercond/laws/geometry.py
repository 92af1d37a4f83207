"""Geometry of a sphere packing inside a box: the inputs of the Rizza & Galati model.

Everything here is NumPy preprocessing (the measures are fixed inputs of a
fit, not its variables). Lengths in any one unit.

* :func:`circle_rectangle_area` and :func:`sphere_box_volume` clip discs and
  spheres by axis-aligned rectangles and boxes: the area in closed form, the
  volume as the integral of that area along one axis by tanh-sinh quadrature
  on the pieces between the points where the section's circle touches an edge
  or a corner (exact up to ~1e-14 relative).
* :func:`contacts` finds touching or overlapping pairs; necks of radius ``x``
  (Rizza & Galati's neck radius) fill the gap between the two spheres inside
  the cylinder of radius ``x`` about the centre line. Their volume is
  ``(pi/3) Z(x)``, Rojek et al.'s residual (Eq. 27), and the parts inside the
  box are integrated numerically (``NECK_QUADRATURE``; relative accuracy of
  the neck part ~1e-4, i.e. ~1e-8 of the solid volume for the tables' necks).
* :func:`rev_measures` assembles U_0, U_0s, S_0, S_ss, n, the contact graph,
  coordination numbers, ``phi`` and per-pair ``gamma`` (Rizza & Galati 2024,
  Eqs. 4-5 and Sect. 2), and lattice builders make the SC, BCC and FCC cells.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import numpy as np

NECK_QUADRATURE = (24, 96, 16)
"""(radial, angular, axial) points for the neck volume and section integrals."""


# --------------------------------------------------------------------------
# exact areas and volumes


def _segment_antiderivative(x, r):
    """``S(x) = int_0^x sqrt(r^2 - t^2) dt`` for ``|x| <= r``."""
    x = np.clip(x, -r, r)
    return 0.5 * (x * np.sqrt(np.maximum(r * r - x * x, 0.0)) + r * r * np.arcsin(np.clip(x / np.where(r > 0, r, 1), -1, 1)))


def _quadrant_area(x, y, r):
    """Area of the disc ``|p| <= r`` (centre 0) with ``p_x <= x`` and ``p_y <= y``."""
    x, y, r = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, r)))
    xc = np.clip(x, -r, r)
    yc = np.clip(y, -r, r)
    x_star = np.sqrt(np.maximum(r * r - yc * yc, 0.0))  # where the chord at height y meets the circle

    def overlap(a, b):
        lo = np.maximum(a, -r)
        hi = np.minimum(b, xc)
        return lo, np.maximum(hi, lo)

    # |X| < x_star: column from -s(X) up to y; |X| > x_star: whole column (y > 0) or nothing (y < 0)
    lo, hi = overlap(-x_star, x_star)
    inner = yc * (hi - lo) + _segment_antiderivative(hi, r) - _segment_antiderivative(lo, r)
    outer = np.zeros_like(inner)
    for a, b in ((-r, -x_star), (x_star, r)):
        lo, hi = overlap(a, b)
        outer += 2.0 * (_segment_antiderivative(hi, r) - _segment_antiderivative(lo, r))
    return np.where(yc > 0, inner + outer, inner)


def circle_rectangle_area(cx, cy, r, x0, x1, y0, y1):
    """Exact area of the disc (centre ``(cx, cy)``, radius ``r >= 0``) inside ``[x0, x1] x [y0, y1]``.

    Inclusion-exclusion of the closed-form quadrant areas; broadcasts.
    """
    cx, cy, r, x0, x1, y0, y1 = (np.asarray(v, dtype=np.float64) for v in (cx, cy, r, x0, x1, y0, y1))
    area = (
        _quadrant_area(x1 - cx, y1 - cy, r)
        - _quadrant_area(x0 - cx, y1 - cy, r)
        - _quadrant_area(x1 - cx, y0 - cy, r)
        + _quadrant_area(x0 - cx, y0 - cy, r)
    )
    return np.maximum(area, 0.0)


@functools.cache
def _tanh_sinh(level=6):
    """Tanh-sinh nodes and weights on ``[-1, 1]`` (step 2^-level on ``[-3.2, 3.2]``)."""
    h = 2.0**-level
    k = np.arange(-int(3.2 / h), int(3.2 / h) + 1)
    t = k * h
    u = 0.5 * np.pi * np.sinh(t)
    x = np.tanh(u)
    w = h * 0.5 * np.pi * np.cosh(t) / np.cosh(u) ** 2
    keep = np.abs(x) < 1.0
    return x[keep], w[keep]


def _integrate_pieces(f, breaks):
    """``int f`` over consecutive intervals of ``breaks`` by tanh-sinh (endpoint singularities welcome)."""
    x, w = _tanh_sinh()
    total = 0.0
    for a, b in zip(breaks[:-1], breaks[1:]):
        if b > a:
            total += 0.5 * (b - a) * np.sum(w * f(0.5 * (a + b) + 0.5 * (b - a) * x))
    return total


def sphere_box_volume(centre, radius, box_lo, box_hi):
    """Volume of a sphere inside an axis-aligned box.

    The disc cut at ``x`` has radius ``rho(x) = sqrt(r^2 - (x - c_x)^2)`` and its
    area in the box's ``y z`` rectangle is :func:`circle_rectangle_area`; that
    area is smooth between the ``x`` at which ``rho`` equals the distance to a
    rectangle edge or corner, so the integral is split there and each piece
    integrated by tanh-sinh quadrature.
    """
    c = np.asarray(centre, dtype=np.float64)
    lo, hi = np.asarray(box_lo, dtype=np.float64), np.asarray(box_hi, dtype=np.float64)
    r = float(radius)
    a, b = max(lo[0], c[0] - r), min(hi[0], c[0] + r)
    if b <= a:
        return 0.0
    dy = np.array([lo[1] - c[1], hi[1] - c[1]])
    dz = np.array([lo[2] - c[2], hi[2] - c[2]])
    distances = np.concatenate([np.abs(dy), np.abs(dz), np.hypot(dy[:, None], dz[None, :]).ravel()])
    offsets = np.sqrt(np.maximum(r * r - distances[distances < r] ** 2, 0.0))
    breaks = np.unique(np.clip(np.concatenate([[a, b], c[0] - offsets, c[0] + offsets]), a, b))

    def section(x):
        rho = np.sqrt(np.maximum(r * r - (x - c[0]) ** 2, 0.0))
        return circle_rectangle_area(c[1], c[2], rho, lo[1], hi[1], lo[2], hi[2])

    return float(_integrate_pieces(section, breaks))


def sphere_face_areas(centre, radius, box_lo, box_hi):
    """Areas of the sphere's sections on the six faces of the box, ``[6]`` in the order
    ``x = lo, x = hi, y = lo, y = hi, z = lo, z = hi`` (exact)."""
    c = np.asarray(centre, dtype=np.float64)
    lo, hi = np.asarray(box_lo, dtype=np.float64), np.asarray(box_hi, dtype=np.float64)
    areas = np.zeros(6)
    for axis in range(3):
        u, v = [k for k in range(3) if k != axis]
        for side, plane in enumerate((lo[axis], hi[axis])):
            rho = np.sqrt(max(radius**2 - (plane - c[axis]) ** 2, 0.0))
            areas[2 * axis + side] = circle_rectangle_area(c[u], c[v], rho, lo[u], hi[u], lo[v], hi[v])
    return areas


# --------------------------------------------------------------------------
# contacts and necks


def contacts(centres, radii, tolerance=1e-9):
    """Pairs ``(i, j)``, ``i < j``, whose spheres touch or overlap.

    ``tolerance`` is relative to ``r_i + r_j``: lattices built with touching
    spheres have gaps of a few ulp. O(N^2); packings here are REV-sized.
    """
    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    i, j = np.triu_indices(len(radii), k=1)
    distance = np.linalg.norm(centres[i] - centres[j], axis=1)
    reach = radii[i] + radii[j]
    touching = distance <= reach * (1.0 + tolerance)
    return np.stack([i[touching], j[touching]], axis=1)


def neck_volume(x, r_i, r_j, h=0.0):
    """Volume a neck of radius ``x`` adds between two spheres: ``(pi/3) Z(x)`` (Rojek et al. 2022, Eq. 27).

    The cylinder of radius ``x`` about the centre line between the two sphere
    surfaces, less the spheres: ``pi x^2 h_n - V_cap_i - V_cap_j`` with
    ``h_n = h_ci + h_cj - h``.
    """
    from sintercond.laws.neck import neck_residual  # one definition of Z

    return float(np.pi / 3.0 * np.asarray(neck_residual(x, r_i, r_j, h)))


def _neck_points(c_i, c_j, r_i, r_j, x):
    """Quadrature points and weights filling the neck of radius ``x`` between spheres i and j."""
    n_rho, n_theta, n_axial = NECK_QUADRATURE
    axis = c_j - c_i
    d = np.linalg.norm(axis)
    e = axis / d
    helper = np.array([1.0, 0.0, 0.0]) if abs(e[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(e, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(e, e1)
    g, gw = np.polynomial.legendre.leggauss(n_rho)
    rho = 0.5 * x * (g + 1)
    w_rho = 0.5 * x * gw
    theta = (np.arange(n_theta) + 0.5) * 2 * np.pi / n_theta  # never on a plane through the axis at 0, pi/2, ...
    ga, gaw = np.polynomial.legendre.leggauss(n_axial)
    # along the axis, from sphere i's surface to sphere j's surface at radius rho
    z_start = np.sqrt(np.maximum(r_i**2 - rho**2, 0.0))
    z_end = d - np.sqrt(np.maximum(r_j**2 - rho**2, 0.0))
    length = np.maximum(z_end - z_start, 0.0)
    z = z_start[:, None] + 0.5 * length[:, None] * (ga[None, :] + 1)  # [rho, axial]
    w_z = 0.5 * length[:, None] * gaw[None, :]
    weight = (w_rho * rho)[:, None, None] * w_z[:, None, :] * (2 * np.pi / n_theta)  # [rho, theta, axial]
    offsets = (rho[:, None, None, None] * (np.cos(theta)[None, :, None, None] * e1 + np.sin(theta)[None, :, None, None] * e2)
               + z[:, None, :, None] * e)
    points = c_i + offsets
    return points.reshape(-1, 3), np.broadcast_to(weight, (n_rho, n_theta, n_axial)).reshape(-1)


def _neck_section_on_plane(c_i, c_j, r_i, r_j, x, axis, plane, *, box):
    """Area of the neck's section by the plane ``p[axis] = plane``, inside the box face.

    A plane containing the neck's axis (the lattice case: contacts on faces
    and edges) is integrated in the neck's own coordinates, Gauss in the
    distance ``s`` from the axis and in ``t`` along it over the gap between
    the spheres, with the face rectangle as an indicator (exact when the
    rectangle's edge is the axis, as in lattices). Other planes that cut the
    neck use a fine midpoint grid around the contact point. ``box``: its ``(lo, hi)`` corners ``[3]`` (m).
    """
    box_lo, box_hi = box
    u, v = [k for k in range(3) if k != axis]
    axis_vec = c_j - c_i
    d = np.linalg.norm(axis_vec)
    e = axis_vec / d
    contact = c_i + e * (r_i - 0.5 * (r_i + r_j - d))
    reach = x + x * x / min(r_i, r_j)  # bounding radius of the neck about the contact point
    if abs(contact[axis] - plane) > reach:
        return 0.0
    on_plane = abs(c_i[axis] - plane) <= 1e-12 * d and abs(c_j[axis] - plane) <= 1e-12 * d
    if on_plane:
        f = np.zeros(3)
        f[u], f[v] = -e[v], e[u]  # in the plane, perpendicular to the axis
        gs, gws = np.polynomial.legendre.leggauss(2 * NECK_QUADRATURE[0])
        s_nodes, s_weights = x * gs, x * gws  # s in [-x, x]
        gt, gwt = np.polynomial.legendre.leggauss(NECK_QUADRATURE[2])
        t0 = np.sqrt(np.maximum(r_i**2 - s_nodes**2, 0.0))
        t1 = d - np.sqrt(np.maximum(r_j**2 - s_nodes**2, 0.0))
        length = np.maximum(t1 - t0, 0.0)
        t = t0[:, None] + 0.5 * length[:, None] * (gt[None, :] + 1)
        w = s_weights[:, None] * 0.5 * length[:, None] * gwt[None, :]
        p = c_i + t[..., None] * e + s_nodes[:, None, None] * f
        inside = _in_box_face(p.reshape(-1, 3), u, v, box_lo, box_hi)
        return float(np.sum(w.ravel()[inside]))
    n = 400
    grid = (np.arange(n) + 0.5) / n * 2 - 1
    uu, vv = np.meshgrid(contact[u] + reach * grid, contact[v] + reach * grid, indexing="ij")
    p = np.zeros((n * n, 3))
    p[:, axis] = plane
    p[:, u], p[:, v] = uu.ravel(), vv.ravel()
    inside = _in_neck(p, c_i, c_j, r_i, r_j, x) & _in_box_face(p, u, v, box_lo, box_hi)
    return float(np.sum(inside) * (2 * reach / n) ** 2)


def _in_neck(p, c_i, c_j, r_i, r_j, x):
    axis = c_j - c_i
    d = np.linalg.norm(axis)
    e = axis / d
    t = (p - c_i) @ e
    rho = np.linalg.norm((p - c_i) - t[:, None] * e, axis=1)
    outside_i = np.linalg.norm(p - c_i, axis=1) > r_i
    outside_j = np.linalg.norm(p - c_j, axis=1) > r_j
    return (rho <= x) & (t > 0) & (t < d) & outside_i & outside_j


def _in_box_face(p, u, v, lo, hi):
    return (p[:, u] >= lo[u]) & (p[:, u] <= hi[u]) & (p[:, v] >= lo[v]) & (p[:, v] <= hi[v])


# --------------------------------------------------------------------------
# the representative volume


@dataclasses.dataclass(frozen=True)
class REVMeasures:
    """Geometry of a packing in a box (Rizza & Galati 2024, Sect. 2).

    Attributes:
      U_0: box volume.
      U_0s: solid volume in the box (clipped spheres plus necks).
      S_0: box surface area.
      S_ss: solid area on the box faces (sphere and neck sections).
      n: relative density ``U_0s / U_0``.
      pairs: ``[n_pairs, 2]`` contacting pairs ``(i, j)``.
      neck_radii: ``[n_pairs]`` neck radius ``x`` of each pair (0 without necks).
      gamma: ``[n_pairs]`` ``(D - 2x)/D`` with ``D`` the larger diameter (Eq. 4).
      coordination: ``[n_particles]`` contacts of each particle.
      phi: the largest coordination number (Rizza & Galati's choice of phi).
      sphere_volume: the part of ``U_0s`` from spheres alone.
      sphere_face_area: the part of ``S_ss`` from spheres alone.
    """

    U_0: float
    U_0s: float
    S_0: float
    S_ss: float
    n: float
    pairs: np.ndarray
    neck_radii: np.ndarray
    gamma: np.ndarray
    coordination: np.ndarray
    phi: int
    sphere_volume: float
    sphere_face_area: float

    @property
    def sss_over_s0(self) -> float:
        return self.S_ss / self.S_0


def rev_measures(centres, radii, box, necks: float | Callable | None = None, tolerance=1e-9) -> REVMeasures:
    """U_0, U_0s, S_0, S_ss, n, contact graph, coordination, phi and gamma of a packing.

    Args:
      centres: ``[n, 3]`` sphere centres (spheres may stick out of the box or
        lie outside it; only what is inside counts, but every contact counts
        for the coordination numbers).
      radii: ``[n]`` radii.
      box: ``(lo, hi)`` corners of the axis-aligned box, each ``[3]``.
      necks: neck radius of every contact (a number), a function
        ``f(r_i, r_j) -> x`` (per pair type), or None for point contacts.
      tolerance: relative gap still counted as contact (see :func:`contacts`).

    Returns:
      :class:`REVMeasures`.
    """
    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in box)
    if centres.ndim != 2 or centres.shape[1] != 3 or radii.shape != centres.shape[:1]:
        raise ValueError(f"centres must be [n, 3] and radii [n]; got {centres.shape} and {radii.shape}")
    if not np.all(np.isfinite(radii) & (radii > 0)):
        raise ValueError("radii must be finite and > 0")
    if not np.all(hi > lo):
        raise ValueError(f"box must have hi > lo on every axis; got lo={lo}, hi={hi}")
    size = hi - lo
    u_0 = float(np.prod(size))
    s_0 = float(2 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2]))
    sphere_volume = sum(sphere_box_volume(c, r, lo, hi) for c, r in zip(centres, radii))
    sphere_area = sum(float(np.sum(sphere_face_areas(c, r, lo, hi))) for c, r in zip(centres, radii))

    pairs = contacts(centres, radii, tolerance)
    if necks is None:
        x = np.zeros(len(pairs))
    elif callable(necks):
        x = np.array([float(necks(radii[i], radii[j])) for i, j in pairs])
    else:
        x = np.full(len(pairs), float(necks))
    if np.any((x < 0) | (x >= np.minimum(radii[pairs[:, 0]], radii[pairs[:, 1]]) if len(pairs) else False)):
        raise ValueError("neck radii must be >= 0 and below the smaller radius of their pair")

    neck_volume_in_box, neck_area = 0.0, 0.0
    for (i, j), xx in zip(pairs, x):
        if xx <= 0:
            continue
        points, weights = _neck_points(centres[i], centres[j], radii[i], radii[j], xx)
        inside = np.all((points >= lo) & (points <= hi), axis=1)
        neck_volume_in_box += float(np.sum(weights[inside]))
        for axis in range(3):
            for plane in (lo[axis], hi[axis]):
                neck_area += _neck_section_on_plane(centres[i], centres[j], radii[i], radii[j], xx, axis, plane,
                                                    box=(lo, hi))

    diameters = 2 * radii
    d_max = np.maximum(diameters[pairs[:, 0]], diameters[pairs[:, 1]]) if len(pairs) else np.zeros(0)
    coordination = np.bincount(pairs.ravel(), minlength=len(radii)) if len(pairs) else np.zeros(len(radii), int)
    u_0s = sphere_volume + neck_volume_in_box
    return REVMeasures(
        U_0=u_0, U_0s=u_0s, S_0=s_0, S_ss=sphere_area + neck_area, n=u_0s / u_0,
        pairs=pairs, neck_radii=x, gamma=(d_max - 2 * x) / d_max if len(pairs) else np.zeros(0),
        coordination=coordination, phi=int(coordination.max()) if len(radii) else 0,
        sphere_volume=sphere_volume, sphere_face_area=sphere_area,
    )


# --------------------------------------------------------------------------
# lattice cells


def _corners(a):
    return np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.float64) * a


def simple_cubic_cell(diameter):
    """SC unit cell: 8 touching spheres of ``diameter`` centred on the corners of a cube of edge ``diameter``.

    Returns ``(centres [8, 3], radii [8], box)``.
    """
    a = float(diameter)
    return _corners(a), np.full(8, a / 2), (np.zeros(3), np.full(3, a))


def bcc_cell(corner_diameter, cell_size=None, centre_diameter=None):
    """BCC unit cell: corner spheres plus one centre sphere.

    Rizza & Galati (2024, Sect. 3.2): 80 um corner spheres, an 80 um cell and a
    58.6 um centre sphere, which is the one that just touches the corners,
    ``sqrt(3) a - d`` (58.56 um). Defaults: cell = corner diameter (corners
    touch along the edges), centre sphere touching the corners.
    """
    d = float(corner_diameter)
    a = d if cell_size is None else float(cell_size)
    dc = np.sqrt(3.0) * a - d if centre_diameter is None else float(centre_diameter)
    centres = np.vstack([_corners(a), np.full((1, 3), a / 2)])
    radii = np.concatenate([np.full(8, d / 2), [dc / 2]])
    return centres, radii, (np.zeros(3), np.full(3, a))


def fcc_cell(diameter):
    """FCC unit cell: spheres on the corners and face centres, touching along the face diagonals
    (cell edge ``diameter * sqrt(2)``)."""
    d = float(diameter)
    a = d * np.sqrt(2.0)
    faces = np.array([[0.5, 0.5, 0], [0.5, 0.5, 1], [0.5, 0, 0.5], [0.5, 1, 0.5], [0, 0.5, 0.5], [1, 0.5, 0.5]]) * a
    centres = np.vstack([_corners(a), faces])
    return centres, np.full(len(centres), d / 2), (np.zeros(3), np.full(3, a))
