"""Necks that share a sphere: the coupling of a particle's necks through its surface Green function.

The pipe network (:mod:`sintercond.contacts.network`) sums each neck's pair law as if the neck were alone on its
sphere. Heat entering a sphere at one neck spreads through it and warms the surface under its other necks,
so with more than two necks per sphere the isolated network conducts too well (12-39 % on FCC, 2-14 % on
BCC at a/r 0.16-0.4 against full-field solves, ``tests/data/fullfield_cells.md``). This module keeps the
pair law and adds, per sphere, the interaction of its necks as point sources on its surface.

**Surface Green function.** Sphere of radius ``r`` (m), conductivity ``kappa`` (W/(m K)), a point heat flow
``Q`` (W) entering its surface at the pole. Inside, ``T = sum_l A_l (rho/r)^l P_l(cos theta)``; the surface
delta function is ``(Q / r^2) sum_l (2l + 1)/(4 pi) P_l`` (completeness of the Legendre polynomials), so the
Neumann condition ``kappa dT/drho = ...`` gives ``A_l = Q (2l + 1) / (4 pi kappa r l)`` for ``l >= 1``; the
``l = 0`` part is the sphere's mean temperature, set by its storage or its other necks. The surface
temperature per watt, less the mean (K/W), is therefore::

    G(theta) = 1/(4 pi kappa r) sum_{l>=1} (2l + 1)/l P_l(cos theta)
             = [1/sigma - 2 - ln(sigma (1 + sigma))] / (4 pi kappa r),   sigma = sin(theta/2)     (Eq. 1)

from the Legendre generating function ``sum_l P_l t^l = (1 - 2 x t + t^2)^(-1/2)`` (Jackson, Classical
Electrodynamics, 3rd ed., 1999, Sect. 3.3) at ``t = 1`` (``sum_l P_l = 1/(2 sigma)``) and integrated over
``t`` from 0 to 1 (``sum_{l>=1} P_l / l = -ln(sigma (1 + sigma))``). Near a neck ``G -> 1/(2 pi kappa s)``
at the arc distance ``s``: the half-space point source. ``G(pi) = -(1 + ln 2)/(4 pi kappa r)``.

**A sphere's necks.** Neck ``i`` of sphere ``s`` (unit direction ``n_i`` from the centre, outward heat flow
``q_i``, W) has the temperature ``T_i`` (K)::

    T_s - T_i = q_i / K_self,i + sum_{j != i} q_j G(theta_ij),   cos theta_ij = n_i . n_j         (Eq. 2)
    1 / K_self,i = 1 / K_half,i + G(pi)                                                           (Eq. 3)

``T_s`` is the mean surface temperature, which for a harmonic field is the centre's and the mean over the
ball (Gauss's mean-value theorem): the sphere's temperature in the network. The self term (Eq. 3) makes
two opposite necks (``q_2 = -q_1``, ``theta = pi``) give ``T_s - T_1 = q_1 / K_half``: the pair law's half,
so chains and the simple-cubic cell along an axis are unchanged and the pair law's calibration (Rojek et al.
2022, Eq. 40, fitted to FE; Batchelor & O'Brien 1977, ``4 kappa a`` per half for small necks, as Dryden & Zok
2004, Eq. 37, quote it) is
kept. Nothing is fitted. In matrix form ``T_s 1 - T_N = R_s q`` with the symmetric resistance block
``R_s`` (K/W, :func:`resistance_blocks`) and the neck conductance matrix ``C_s = R_s^{-1}`` (W/K,
:func:`conductance_blocks`): ``q = C_s (T_s 1 - T_N)``.

**Halves.** The pair law's resistance ``1/K_ij`` is split between the two spheres of a contact in the
proportion of the law's own halves (:func:`half_resistances`): for a law made of halves in series (Rojek
Eqs. 8-9, 43; the fitted and Feng laws) each sphere gets exactly its half, a contact resistance is shared in
the same proportion, and the two sides always sum to ``1/K_ij``. Equal spheres: ``K_half = 2 K_ij``.

**Held spheres** (a face layer held at a temperature). Such a sphere has no balance of its own, and
``l = 0`` would matter. The plane through its centre normal to the flux axis is taken as isothermal (it is
exactly so for a lattice site under a gradient, a mirror plane of the lattice): each neck gets a mirror
image across that plane carrying the opposite flow, so ``R_s[i, j]`` gains ``-G(theta*_ij)``, ``theta*_ij``
between ``n_i`` and the image of ``n_j`` (Eq. 4). The sources and images sum to zero (no ``l = 0`` part),
and one axial neck gets exactly the pair law's half. A neck between two spheres held at the same temperature
is left out of both (it carries heat only through the coupling; in a lattice's held layer, none by
symmetry). Where a neck's disc overlaps an image's disc (a neck close to the held plane, common in the face
layer of a poured bed) the images are not point-like; such a held sphere keeps the pair law's halves
(``R_s = diag(1/K_half)``, the other treatment of ``/work/shared/NECK_COUPLING.md``).

**Net flow (the transient).** In a steady state a free sphere's necks carry no net flow, ``sum_i q_i = 0``,
and Eqs. 2-3 need nothing more. In a transient a sphere stores heat and ``Q = sum_i q_i`` is not zero; its
``l = 0`` part is a uniform shift of every neck against ``T_s`` that Eqs. 2-3 leave open (the surface Green
function has no ``l = 0`` term). The transient network takes the shift that keeps the pair law wherever the
pipe network is calibrated, two opposite necks carrying any flows ``(q_1, q_2)``::

    R_s <- R_s - G(pi) 1 1^T   (free spheres),                                                     (Eq. 5)

so that Eq. 2 reads ``T_s - T_i = q_i / K_half,i + sum_j q_j (G(theta_ij) - G(pi))`` (the kernel measured
from the antipode, the self term ``G(pi)`` of Eq. 3 cancelled): a chain and the simple-cubic lattice heated
along an axis are the isolated network's in the transient too, and a steady state (``1^T q = 0``) is Eqs. 2-3
exactly, the sphere temperatures included. ``-G(pi) 1 1^T`` is positive semi-definite: ``R_s`` stays positive
definite. It is a modelling choice, not derived: a sphere cooling uniformly inside (the lumped capacity) gives a
shift of ``+Q/(20 pi kappa r)`` instead (its surface mean below its volume mean), ``1.49 Q/(4 pi kappa r)`` less;
the two differ only while the spheres store heat.

**Domain.** The point-source form needs the necks' discs apart: necks ``i, j`` of a sphere of radius ``r``
with neck radii ``a_i, a_j`` must satisfy ``theta_ij >= alpha_i + alpha_j``, ``alpha = arcsin(a / r)`` (the
angular half-width of a neck's disc). :func:`sphere_geometry` refuses a packing where two discs overlap,
naming the particle and both contacts, or (``beyond_domain="isolated"``, what the measurements of ``k*`` along a
run use) accepts it; such a sphere then keeps the pair law's halves, as the isolated network does
(:func:`outside_domain` finds it at the necks of the moment).
Measured against full-field solves: within 2 % up to a/r = 0.4 on
FCC (12 necks) and BCC (8 and 14 necks) once the pair law's own error is divided out (``docs/laws.md``).

**Operator.** The unknowns are the sphere temperatures ``[n]`` and the neck temperatures ``[p]`` (one per
contact, shared by its two spheres, massless: the two spheres' flows into it sum to zero). The system is
``A = sum_s B_s^T C_s B_s`` with ``B_s x = x_s 1 - x_N(s)``: symmetric positive semi-definite and
conservative. In a steady state the free spheres are eliminated exactly (:func:`neck_system`) and conjugate
gradients run on the necks (:mod:`sintercond.sim.steady`); the transient balances the necks against the spheres'
temperatures (:mod:`sintercond.sim.terms.coupling`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from sintercond._numerics import safe_divide
from sintercond.laws.conductance import conductance_from_neck

GREEN_OPPOSITE = -(1.0 + math.log(2.0))
"""``4 pi kappa r G(pi)``: the dimensionless Green function between antipodal points (Eq. 1 at ``sigma = 1``)."""


def surface_green_factor(cos_theta):
    """``4 pi kappa r G(theta) = 1/sigma - 2 - ln(sigma (1 + sigma))``, ``sigma = sin(theta/2)`` (Eq. 1).

    Dimensionless. ``cos_theta`` is clipped to ``[-1, 1]`` (round-off of unit vectors). At ``theta = 0``
    (coincident points) the value is ``+inf`` with zero gradient; elsewhere value and gradient are finite,
    ``theta = pi`` included (double ``where``: ``sigma`` is ``sqrt((1 - cos)/2)``, whose derivative is
    infinite at ``cos = 1``).
    """
    xp = np if isinstance(cos_theta, np.ndarray) else jnp  # NumPy arrays stay on the host (the geometry's build)
    c = xp.clip(xp.asarray(cos_theta), -1.0, 1.0)
    s2 = 0.5 * (1.0 - c)
    apart = s2 > 0
    sigma = xp.sqrt(xp.where(apart, s2, 1.0))
    value = 1.0 / sigma - 2.0 - xp.log(sigma * (1.0 + sigma))
    return xp.where(apart, value, xp.inf)


def surface_green(cos_theta, radius, kappa):
    """``G(theta)`` (K/W), Eq. 1: surface temperature less the mean per watt entering at angular distance theta.

    Args:
      cos_theta: ``cos theta`` between the source and the point.
      radius: sphere radius ``r`` (m), > 0.
      kappa: its conductivity (W/(m K)), > 0.
    """
    return surface_green_factor(cos_theta) / (4.0 * jnp.pi * kappa * radius)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SphereGeometry:
    """The constant (geometric) part of every sphere's resistance block, on the contact table's layout.

    Attributes:
      green: ``[n, m, m]`` dimensionless ``4 pi kappa r`` times the coupling part of ``R_s``: ``g(theta_ij)``
        off the diagonal, ``g(pi)`` on it (Eqs. 2-3), less the mirror images' ``g(theta*_ij)`` on held
        spheres (Eq. 4), with the net-flow term on free spheres (Eq. 5, ``net_flow``); 0 in every slot not
        coupled. A sphere outside the domain at the necks of the moment keeps the pair law's halves instead
        (:func:`kept_green`).
      coupled: ``[n, m]`` bool, the slot is a neck of this sphere's block (a contact with a neck, not joining
        two spheres held at the same temperature).
      neck_index: ``[n, m]`` int32, the contact (neck unknown) of each slot, 0 on padding.
      neck_slots: ``[p, 2]`` int32, each contact's two slots as flat indices ``row * m + slot``.
      neck_fixed: ``[p]`` bool, contacts in no block (no neck, or joining two spheres held alike).
      rows: the packed layout of the blocks ``C_s`` (:func:`conductance_blocks`): a tuple of ``[n_b]`` int32, the
        spheres of each bucket; a sphere with ``k`` contacts is in the narrowest bucket of width ``w_b >= k``
        (:data:`BUCKET_WIDTHS`), its block cut to ``[w_b, w_b]`` (a table row holds its contacts first).
      necks: per bucket ``[n_b, w_b]`` int32, ``neck_index`` of its spheres' first ``w_b`` slots.
      packed_slots: ``[p, 2]`` int32, each contact's two slots in the packed per-slot layout (the buckets' slots
        one after the other, row-major).
      row_order: ``[n]`` int32, where each sphere is in the buckets' rows one after the other.
      theta: ``[n, m, m]`` angles (rad) between the necks of each sphere, for the domain at the necks of the moment.
      image_theta: ``[n, m, m]`` angles (rad) from each neck of a held sphere to the mirror images of its necks
        (pi on free spheres), or None without held spheres.
    """

    green: jax.Array
    coupled: jax.Array
    neck_index: jax.Array
    neck_slots: jax.Array
    neck_fixed: jax.Array
    rows: tuple = ()
    necks: tuple = ()
    packed_slots: jax.Array | None = None
    row_order: jax.Array | None = None
    theta: jax.Array | None = None
    image_theta: jax.Array | None = None


BUCKET_WIDTHS = (2, 4, 6, 8, 10, 12, 16, 24, 32, 48, 64)
"""Widths of the packed blocks: a poured bed has 1-16 contacts a sphere (mean about 6), so a block padded to the
widest row is mostly padding; beyond the last width, rows pad to the table's width."""


def _packed_layout(pair_id, neck_index, neck_slots):
    """``(rows, necks, packed_slots, row_order)`` of :class:`SphereGeometry` (host, NumPy)."""
    n, m = pair_id.shape
    count = (pair_id > 0).sum(axis=1)
    ladder = np.array([w for w in BUCKET_WIDTHS if w < m] + [m])
    width = ladder[np.searchsorted(ladder, np.maximum(count, 1))]
    rows, necks, position = [], [], np.full(n * m, -1, np.int64)
    start = 0
    for w in np.unique(width):
        members = np.flatnonzero(width == w)
        rows.append(members)
        necks.append(neck_index[members, :w])
        slots = (members[:, None] * m + np.arange(w)[None, :]).reshape(-1)
        position[slots] = start + np.arange(slots.size)
        start += slots.size
    order = np.empty(n, np.int64)
    order[np.concatenate(rows)] = np.arange(n)
    packed = position[neck_slots]
    if (packed < 0).any():  # a table row holds its contacts first, so none lies beyond its row's width
        raise ValueError("sphere_geometry: a contact's slot lies beyond its row's contacts (the table is not packed)")
    return (tuple(jnp.asarray(r, jnp.int32) for r in rows), tuple(jnp.asarray(k, jnp.int32) for k in necks),
            jnp.asarray(packed, jnp.int32), jnp.asarray(order, jnp.int32))


BEYOND_DOMAIN = ("refuse", "isolated")
"""What :func:`sphere_geometry` does with a sphere two of whose necks' discs overlap (outside the domain of point
coupling): refuse the packing, or let it keep its pair-law halves (its necks isolated, as in the pipe network)."""


def sphere_geometry(centres, radii, neighbors, pair_id, neck, *, held=None, axis=0, periodic_box=None,
                    net_flow=False, beyond_domain="refuse"):
    """Host-side :class:`SphereGeometry` of a static packing, after checking the domain of point coupling.

    The geometry holds the necks' directions only; which spheres are inside the domain is decided from the neck
    radii at each use (:func:`kept_green`), so a geometry built once serves necks that grow.

    Args:
      centres: ``[n, 3]`` (m). radii: ``[n]`` (m).
      neighbors: ``[n, m]`` contact table (:func:`sintercond.contacts.network.ell_table`), padded with the row itself.
      pair_id: ``[n, m]`` the contact's index + 1 in each slot, 0 on padding (same layout).
      neck: ``[n, m]`` neck radius ``a`` of each slot (m); slots with ``a <= 0`` carry no neck (are not coupled).
      held: ``[n]`` int labels, 0 for a free sphere and equal non-zero labels for spheres held at the same
        temperature (e.g. 1 hot, 2 cold), or None.
      axis: the flux axis; held spheres get mirror images across the plane through their centre normal to it.
      periodic_box: ``[3]`` side lengths (m) for minimum-image directions, or None.
      net_flow: the transient's blocks: free spheres get the net-flow term ``-G(pi) 1 1^T`` (Eq. 5).
      beyond_domain: ``"refuse"`` (default) or ``"isolated"``, :data:`BEYOND_DOMAIN`: at the necks ``neck``, a
        sphere two of whose necks' discs overlap is refused, or accepted (it keeps the pair law's halves,
        ``R_s = diag(1/K_half)``, the isolated network on that sphere, :func:`kept_green`).

    Raises:
      ValueError: with ``beyond_domain="refuse"``, two necks of one sphere closer than their discs' angular
        half-widths (Domain).
    """
    if beyond_domain not in BEYOND_DOMAIN:
        raise ValueError(f"beyond_domain must be one of {list(BEYOND_DOMAIN)}; got {beyond_domain!r}")
    centres = np.asarray(centres, np.float64)
    radii = np.asarray(radii, np.float64)
    neighbors = np.asarray(neighbors)
    pair_id = np.asarray(pair_id)
    neck = np.asarray(neck, np.float64)
    n, m = neighbors.shape
    held = np.zeros(n, np.int64) if held is None else np.asarray(held, np.int64)
    rows = np.arange(n)[:, None]
    has_neck = (pair_id > 0) & (neck > 0)
    coupled = has_neck & ~((held[:, None] != 0) & (held[neighbors] == held[:, None]))
    direction, cos, alpha = _neck_angles(centres, radii, neighbors, neck, periodic_box)
    pair = coupled[:, :, None] & coupled[:, None, :]
    # only the coupled pairs of slots (a sixth of [n, m, m] on a poured bed) are evaluated
    at = np.nonzero(pair)
    sphere, i, j = at
    diagonal = i == j
    theta = np.full((n, m, m), np.pi)
    theta[at] = np.arccos(cos[at])
    if beyond_domain == "refuse":
        close = ~diagonal & _apart_less_than(theta[at], alpha[sphere, i] + alpha[sphere, j])
        _refuse_overlap(np.flatnonzero(close), at, theta, alpha, neighbors)
    g = surface_green_factor(np.where(diagonal, -1.0, cos[at]))  # the diagonal holds g(pi), Eq. 3
    mirrored = held != 0
    image_theta = None
    if mirrored.any():
        e = direction[..., axis]
        image_cos = np.clip(cos[at] - 2.0 * e[sphere, i] * e[sphere, j], -1.0, 1.0)
        g = np.where(mirrored[sphere], g - surface_green_factor(image_cos), g)
        image_theta = np.full((n, m, m), np.pi)
        image_theta[at] = np.where(mirrored[sphere], np.arccos(image_cos), np.pi)
    if net_flow:
        g = np.where(held[sphere] == 0, g - GREEN_OPPOSITE, g)
    green = np.zeros((n, m, m))
    green[at] = g
    n_pairs = int(pair_id.max(initial=0))
    flat = (rows * m + np.arange(m)[None, :])[pair_id > 0]
    ids = pair_id[pair_id > 0] - 1
    order = np.argsort(ids, kind="stable")
    neck_slots = flat[order].reshape(n_pairs, 2)
    neck_fixed = ~coupled.reshape(-1)[neck_slots].any(axis=1)
    neck_index = np.maximum(pair_id - 1, 0)
    return SphereGeometry(jnp.asarray(green), jnp.asarray(coupled), jnp.asarray(neck_index, jnp.int32),
                          jnp.asarray(neck_slots, jnp.int32), jnp.asarray(neck_fixed),
                          *_packed_layout(pair_id, neck_index, neck_slots), jnp.asarray(theta),
                          None if image_theta is None else jnp.asarray(image_theta))


def kept_green(geometry: SphereGeometry, neck, radii):
    """``[n, m, m]``: :attr:`SphereGeometry.green` on the spheres inside the domain of point coupling at the necks
    ``neck`` (``[n, m]`` table, m), 0 on the others, which keep the pair law's halves (``R_s = diag(1/K_half)``):
    a sphere two of whose coupled necks' discs overlap (:func:`outside_domain`), and a held sphere a neck of which
    overlaps a mirror image's disc (the images are not point-like there; the treatment of a face layer inside the
    domain).

    The domain is a mask (no derivative flows through it): within it, the blocks are smooth in the necks.
    """
    pair = geometry.coupled[:, :, None] & geometry.coupled[:, None, :]
    outside = outside_domain(geometry, neck, radii)
    if geometry.image_theta is not None:
        outside = outside | jnp.any(pair & _apart_less_than(geometry.image_theta, _reach(neck, radii)), axis=(1, 2))
    return jnp.where(pair & ~outside[:, None, None], geometry.green, 0.0)


def outside_domain(geometry: SphereGeometry, neck, radii):
    """``[n]`` bool: the spheres (free or held) two of whose coupled necks' discs overlap at the necks ``neck``
    (``[n, m]`` table, m), ``theta_ij < arcsin(a_i/r) + arcsin(a_j/r)``: outside the domain of point coupling, left
    at the pair law's halves by :func:`kept_green`."""
    pair = geometry.coupled[:, :, None] & geometry.coupled[:, None, :]
    off = pair & ~jnp.eye(pair.shape[1], dtype=bool)
    return jnp.any(off & _apart_less_than(geometry.theta, _reach(neck, radii)), axis=(1, 2))


def _reach(neck, radii):
    """``[n, m, m]`` (rad): ``arcsin(a_i/r) + arcsin(a_j/r)`` of each two slots, without derivative."""
    alpha = jnp.arcsin(jnp.clip(jax.lax.stop_gradient(neck) / radii[:, None], 0.0, 1.0))
    return alpha[:, :, None] + alpha[:, None, :]


def _apart_less_than(theta, reach):
    """``theta < reach`` beyond round-off: two discs that just touch (FCC at a/r = 0.5) are inside the domain, in
    float32 too."""
    xp = np if isinstance(theta, np.ndarray) else jnp
    return theta < reach * (1.0 - max(1e-12, 8.0 * float(xp.finfo(xp.asarray(theta).dtype).eps)))


def _neck_angles(centres, radii, neighbors, neck, periodic_box):
    """``(direction [n, m, 3], cos theta_ij [n, m, m], alpha [n, m])`` of each sphere's necks (host): the unit
    vectors to its contacts, the cosines between them, and each disc's angular half-width ``arcsin(a / r)``."""
    centres, radii = np.asarray(centres, np.float64), np.asarray(radii, np.float64)
    delta = centres[neighbors] - centres[:, None, :]
    if periodic_box is not None:
        box = np.asarray(periodic_box, np.float64)
        delta = delta - box * np.round(delta / box)
    length = np.linalg.norm(delta, axis=-1)
    direction = delta / np.where(length > 0, length, 1.0)[..., None]
    cos = np.clip(np.einsum("nik,njk->nij", direction, direction), -1.0, 1.0)
    return direction, cos, np.arcsin(np.clip(neck / radii[:, None], 0.0, 1.0))


def _refuse_overlap(close, at, theta, alpha, neighbors):
    """Raise if two necks' discs overlap (``close``: indices into the coupled pairs of slots ``at``), naming the
    first."""
    if close.size:
        s, i, j = (int(v[close[0]]) for v in at)
        reach = alpha[s, i] + alpha[s, j]
        raise ValueError(
            f"coupling='sphere': on particle {s} the necks of contacts ({s}, {int(neighbors[s, i])}) and "
            f"({s}, {int(neighbors[s, j])}) are {np.degrees(theta[s, i, j]):.4g} deg apart, closer than their "
            f"discs' angular half-widths arcsin(a/r) sum to ({np.degrees(reach):.4g} deg): point "
            f"coupling needs theta_ij >= arcsin(a_i/r) + arcsin(a_j/r); use coupling='none' for this packing, or "
            f"(steady solvers) beyond_domain='isolated' to keep such a sphere's pair-law halves")


def half_resistances(law, radii, neighbors, neck, overlap, kappa, law_params, conductance):
    """``[n, m]`` resistance (K/W) of each slot's half of its contact: ``1/K_half`` of Eq. 3.

    The pair law's ``1/K_ij`` (``conductance``, ``[n, m]`` W/K, the table's) split in the proportion of the
    law's halves: the law evaluated on the symmetric pair of each sphere (``r_s, r_s, kappa_s``, no contact
    resistance) is half that sphere's own conductance ``K_s`` (halves in series, Rojek et al. 2022, Eqs. 8-9),
    and sphere ``s`` gets ``(1/K_ij) K_n / (K_s + K_n)``. Both sides sum to ``1/K_ij``; for Rojek's law
    (Eq. 43) each is exactly ``1/(slope kappa_s pi a)`` and for equal spheres ``1/(2 K_ij)``. 0 where
    ``K_ij = 0``. Differentiable in ``kappa`` and ``law_params``.

    Args:
      law: the conductance law (name or :class:`sintercond.laws.conductance.ConductanceLaw`).
      radii: ``[n]`` (m). neighbors, neck, overlap: ``[n, m]`` table, neck radii and overlaps (m).
      kappa: ``[n]`` conductivities (W/(m K)). law_params: the law's parameters, merged with its defaults.
    """
    params = dict(law_params)
    if "contact_resistance" in params:
        params["contact_resistance"] = jnp.zeros_like(jnp.asarray(params["contact_resistance"]))
    r_s = jnp.broadcast_to(radii[:, None], neighbors.shape)
    k_s = jnp.broadcast_to(kappa[:, None], neighbors.shape)
    own = conductance_from_neck(law, neck, r_s, r_s, overlap, k_s, k_s, params)
    other = conductance_from_neck(law, neck, radii[neighbors], radii[neighbors], overlap, kappa[neighbors],
                                  kappa[neighbors], params)
    return safe_divide(other, (own + other) * conductance)


def resistance_blocks(geometry: SphereGeometry, half_resistance, radii, kappa, neck):
    """``R_s`` ``[n, m, m]`` (K/W), Eqs. 2-4: ``diag(1/K_half) + G`` on the coupled slots, ``G`` on the spheres
    inside the domain at the necks ``neck`` (:func:`kept_green`).

    Uncoupled slots get the identity scaled to the row's mean coupled diagonal (or ``1/(kappa r)`` on a
    sphere with none), so that the block stays invertible and well scaled; :func:`conductance_blocks` masks
    them out again.

    Args:
      geometry: :func:`sphere_geometry`.
      half_resistance: ``[n, m]`` ``1/K_half`` (K/W), :func:`half_resistances`.
      radii: ``[n]`` (m). kappa: ``[n]`` (W/(m K)). neck: ``[n, m]`` neck radii (m) on the table.
    """
    coupled = geometry.coupled
    green = kept_green(geometry, neck, radii)
    scale = 1.0 / (4.0 * jnp.pi * kappa * radii)
    diag = jnp.where(coupled, half_resistance, 0.0)
    count = jnp.sum(coupled, axis=1).astype(diag.dtype)
    filler = jnp.where(count > 0, safe_divide(jnp.sum(diag, axis=1), count), 4.0 * jnp.pi * scale)
    diag = jnp.where(coupled, diag, filler[:, None])
    return green * scale[:, None, None] + diag[:, :, None] * jnp.eye(coupled.shape[1], dtype=diag.dtype)


def conductance_blocks(geometry: SphereGeometry, resistance):
    """``C_s = R_s^{-1}`` (W/K) on the coupled slots, 0 elsewhere, symmetrised, in the packed layout: a tuple of
    ``[n_b, w_b, w_b]``, one per bucket of :class:`SphereGeometry` (each sphere's block cut to its bucket's width,
    which holds all its coupled slots). One batched inverse of the full blocks: inverses per bucket in one program
    ran for minutes on XLA's CPU backend (several LAPACK calls at once, 10,841 spheres).

    Differentiable (through ``jnp.linalg.inv``). ``R_s`` is symmetric positive definite inside the domain
    (its diagonal dominates: ``1/K_half`` grows as ``1/a`` while ``|G|`` between discs apart stays below it).
    """
    c = jnp.linalg.inv(resistance)
    c = 0.5 * (c + jnp.swapaxes(c, 1, 2))
    c = jnp.where(geometry.coupled[:, :, None] & geometry.coupled[:, None, :], c, 0.0)
    return tuple(c[rows][:, :w, :w] for rows, w in zip(geometry.rows, (k.shape[1] for k in geometry.necks)))


def slot_flows(geometry: SphereGeometry, conductance, sphere_x, neck_x):
    """``q`` (W), packed per slot (:class:`SphereGeometry`): the heat leaving each sphere through each of its slots,
    ``q_s = C_s (x_s 1 - x_N(s))``.

    Linear in ``(sphere_x [n], neck_x [p])``; the one product with the blocks that the operator, the neck balance
    and the contact flows share (per bucket a product summed over the last axis, which XLA fuses into one pass
    over the blocks).
    """
    return jnp.concatenate([
        jnp.sum(c * (sphere_x[rows][:, None] - neck_x[necks])[:, None, :], axis=2).reshape(-1)
        for c, rows, necks in zip(conductance, geometry.rows, geometry.necks)])


def at_necks(geometry: SphereGeometry, per_slot):
    """``[p, 2]``: a packed per-slot value at each contact's two slots."""
    return per_slot[geometry.packed_slots]


def row_sums(geometry: SphereGeometry, per_slot):
    """``[n]``: a packed per-slot value summed over each sphere's slots."""
    sums, start = [], 0
    for necks in geometry.necks:
        size = necks.size
        sums.append(jnp.sum(per_slot[start:start + size].reshape(necks.shape), axis=1))
        start += size
    return jnp.concatenate(sums)[geometry.row_order]


def slot_diagonal(conductance):
    """The blocks' diagonals, packed per slot (W/K)."""
    return jnp.concatenate([jnp.diagonal(c, axis1=1, axis2=2).reshape(-1) for c in conductance])


class NeckSystem(NamedTuple):
    """The steady network with its free spheres eliminated (:func:`neck_system`): a linear system on the necks."""

    free: jax.Array  # [n] bool, the spheres eliminated
    slot_total: jax.Array  # packed per slot: C_s 1 (W/K)
    total: jax.Array  # [n] 1^T C_s 1 (W/K)
    diagonal: jax.Array  # [p] the diagonal of K (W/K), for a Jacobi preconditioner


def neck_system(geometry: SphereGeometry, conductance, free) -> NeckSystem:
    """The steady coupled network on the necks alone.

    A free sphere touches nothing but its necks, so its row of the steady system, ``1^T C_s (T_s 1 - x_N) = 0``,
    gives its temperature from its necks', ``T_s = 1^T C_s x_N / 1^T C_s 1``, and it is eliminated exactly: the
    necks' balance becomes ``K x = b`` with ``K = sum_s P_s`` (on each sphere's necks), ``P_s = C_s - C_s 1 1^T C_s
    / 1^T C_s 1`` for a free sphere (symmetric positive semi-definite, ``P_s 1 = 0``: a free sphere passes heat on,
    keeps none) and ``C_s`` for a held one, ``b`` the held spheres' ``C_s 1 T_s``. ``K`` is symmetric positive
    definite wherever the necks connect to a held sphere. Conjugate gradients on it take as many iterations as
    the isolated network's on the spheres (a rolled bed of 10,841 spheres densified by 4 %: 128, isolated 127, the
    joint system of spheres and necks 406), one block product each (:func:`neck_flows`).

    Args:
      geometry: :func:`sphere_geometry`. conductance: the packed blocks of :func:`conductance_blocks`.
      free: ``[n]`` bool, the spheres to eliminate (the rest are held).
    """
    slot_total = jnp.concatenate([jnp.sum(c, axis=2).reshape(-1) for c in conductance])
    total = row_sums(geometry, slot_total)
    eliminated = per_slot(geometry, free & (total > 0))
    rank_one = jnp.where(eliminated, safe_divide(slot_total**2, per_slot(geometry, total)), 0.0)
    diagonal = jnp.sum(at_necks(geometry, slot_diagonal(conductance) - rank_one), axis=1)
    return NeckSystem(free, slot_total, total, diagonal)


def neck_flows(geometry: SphereGeometry, conductance, system: NeckSystem, neck_x, held_x=None):
    """``(q, sphere_x)``: the heat leaving each sphere through each of its slots (W, packed) and the sphere
    temperatures ``[n]``, with the free spheres at the temperature their necks ``neck_x`` ``[p]`` give them
    (:func:`neck_system`) and the held ones at ``held_x`` (``[n]``, default 0). One product with the blocks."""
    products = jnp.concatenate([jnp.sum(c * neck_x[necks][:, None, :], axis=2).reshape(-1)
                                for c, necks in zip(conductance, geometry.necks)])  # C_s x_N
    own = safe_divide(row_sums(geometry, products), system.total)
    sphere_x = jnp.where(system.free, own, 0.0 if held_x is None else held_x)
    return system.slot_total * per_slot(geometry, sphere_x) - products, sphere_x


def per_slot(geometry: SphereGeometry, per_sphere):
    """A ``[n]`` value of each sphere laid on its packed slots."""
    return jnp.concatenate([jnp.broadcast_to(per_sphere[rows][:, None], necks.shape).reshape(-1)
                            for rows, necks in zip(geometry.rows, geometry.necks)])


def coupled_blocks(geometry: SphereGeometry, half_resistance, radii, kappa, neck):
    """``C_s`` (W/K, packed) from the halves at the necks ``neck`` (``[n, m]``, m): :func:`conductance_blocks` of
    :func:`resistance_blocks`."""
    return conductance_blocks(geometry, resistance_blocks(geometry, half_resistance, radii, kappa, neck))


def mean_flow(q_at_necks):
    """``[p]`` heat flow (W) through each contact from its first sphere (``neck_slots[:, 0]``) to its second, from
    the two spheres' outflows into its neck ``[p, 2]`` (:func:`at_necks` of :func:`slot_flows`).

    The mean ``(q_ic - q_jc) / 2``: equal to each of them when the neck temperatures balance (a massless neck),
    and antisymmetric by construction, so the network conserves heat to round-off whatever the neck balance's
    residual.
    """
    return 0.5 * (q_at_necks[:, 0] - q_at_necks[:, 1])


def block_total(geometry: SphereGeometry, conductance):
    """``[n]`` ``1^T C_s 1`` (W/K): the heat leaving sphere ``s`` per kelvin above all its necks.

    ``x^T S x <= sum_s 1^T C_s 1 x_s^2`` for the sphere operator ``S`` left once the necks are eliminated (it is
    the minimum of the coupled operator's form over the neck temperatures, here taken at 0), so
    ``dt <= 2 min_s C_s / (1^T C_s 1)`` keeps explicit Euler stable. For isolated necks (``C_s`` diagonal, the
    halves) it is the pipe network's ``C_i / sum_j K_ij``; it is attained by the alternating mode of a bipartite
    lattice (neighbours at ``+1`` and ``-1``, every neck at 0 by symmetry).
    """
    return row_sums(geometry, jnp.concatenate([jnp.sum(c, axis=2).reshape(-1) for c in conductance]))
