"""The pipe network of a packing: contacts and their conductances in a padded (ELL) table.

Rojek et al. (2022), Eqs. 2-4: particle ``i`` receives ``sum_j K_ij (T_j - T_i)``.
The network is stored as two ``[n_particles, max_contacts]`` arrays, the
neighbour indices and the conductances, padded with the particle itself and
conductance 0 (the layout of jax-md's Dense neighbour format). The heat flow
is then a gather and a row sum, with no scatter, which XLA fuses into one
loop.

Contacts are found on the host with a vectorised NumPy cell list (cells of
twice the largest radius, :func:`sintercond.contacts.neighbors.cell_list_pairs`) and
confirmed in float64 from the centre distances; :func:`contact_pairs` gives
them as per-pair arrays, :func:`ell_table` lifts per-pair values to the
table. The table is built once for a static packing (no JAX compile).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from sintercond._numerics import materialized
from sintercond._symmetric import self_adjoint
from sintercond._validation import require_finite, require_positive
from sintercond.laws.conductance import pair_conductance, validate_pair_conductance_inputs
from sintercond.contacts.neighbors import cell_list_pairs, minimum_image


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ContactTable:
    """Padded contact table of a pipe network.

    Attributes:
      neighbors: ``[n, m]`` int32 contact indices; padding points at the row's own particle.
      conductance: ``[n, m]`` conductances ``K_ij`` (W/K); 0 on padding.
      wall_conductance: ``[n]`` conductance to a conducting wall (W/K), or None.
      wall_temperature: ``[n]`` temperature of that wall (K), or None.
    """

    neighbors: jax.Array
    conductance: jax.Array
    wall_conductance: jax.Array | None = None
    wall_temperature: jax.Array | None = None

    def with_walls(self, wall_conductance, wall_temperature) -> ContactTable:
        """The same network coupled to conducting walls (per particle ``K_iw`` and ``T_w``)."""
        return dataclasses.replace(self, wall_conductance=jnp.asarray(wall_conductance),
                                   wall_temperature=jnp.asarray(wall_temperature))

    @property
    def n_particles(self) -> int:
        return self.neighbors.shape[0]

    def pairs(self) -> np.ndarray:
        """``[n_pairs, 2]`` contacting pairs ``i < j`` (host-side)."""
        nbr = np.asarray(self.neighbors)
        rows = np.broadcast_to(np.arange(nbr.shape[0])[:, None], nbr.shape)
        keep = nbr > rows  # padding points at the row itself
        return np.stack([rows[keep], nbr[keep]], axis=1)


@dataclasses.dataclass(frozen=True)
class ContactPairs:
    """The contacting pairs of a packing, each once (host-side NumPy, float64).

    Attributes:
      i, j: ``[n_pairs]`` int64 particle indices, ``i < j``, sorted by ``(i, j)``.
      overlap: ``[n_pairs]`` ``h = r_i + r_j - |c_i - c_j|`` (m, minimum-image
        in a periodic box), clipped at 0: pairs closed within the tolerance touch.
      r_i, r_j: ``[n_pairs]`` radii of the two particles (m).
      n_particles: number of particles of the packing.
    """

    i: np.ndarray
    j: np.ndarray
    overlap: np.ndarray
    r_i: np.ndarray
    r_j: np.ndarray
    n_particles: int


def contact_pairs(centres, radii, tolerance=1e-9, periodic_box=None) -> ContactPairs:
    """Every contacting pair of a static packing with its overlap and radii (vectorised cell list).

    Spheres ``i, j`` are in contact when ``|c_i - c_j| <= (r_i + r_j)(1 + tolerance)``
    (touching lattices have gaps of a few ulp). With ``periodic_box`` (``[3]``
    side lengths, m) distances are minimum-image. See
    :func:`sintercond.contacts.neighbors.cell_list_pairs`.

    Args:
      centres: ``[n, 3]`` (m). radii: ``[n]`` (m).
      tolerance: relative gap still counted as contact.
      periodic_box: ``[3]`` box side lengths (m), or None.
    """
    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    if centres.ndim != 2 or centres.shape[1] != 3 or radii.shape != (len(centres),):
        raise ValueError(f"centres must be [n, 3] and radii [n]; got shapes {centres.shape} and {radii.shape}")
    require_finite("centres (m)", centres)
    require_positive("radii (m)", radii)
    box = None if periodic_box is None else np.asarray(periodic_box, dtype=np.float64)
    i, j = cell_list_pairs(centres, radii, tolerance, box)
    delta = minimum_image(centres[i] - centres[j], box)
    overlap = np.maximum(radii[i] + radii[j] - np.linalg.norm(delta, axis=1), 0.0)
    return ContactPairs(i, j, overlap, radii[i], radii[j], len(radii))


def ell_table(n_particles, i, j, *pair_values):
    """Lift pairs to the padded (ELL) layout: ``[n, m]`` neighbours and each pair value on both rows.

    Args:
      n_particles: ``n``.
      i, j: ``[n_pairs]`` pairs ``i < j``, sorted by ``(i, j)``, each once.
      *pair_values: ``[n_pairs]`` arrays, one value per pair (e.g. ``K_ij``).

    Returns:
      ``(neighbors, *values)``: ``neighbors`` ``[n, m]`` int64 with each row's
      neighbours in ascending order, padded with the row's own index;
      ``values`` ``[n, m]`` with the pair's value in both rows (so the network
      is exactly symmetric) and 0 on padding. ``m = max(degree, 1)``.
    """
    # rows j first (their neighbours i < j come out ascending), then rows i
    rows = np.concatenate([j, i])
    cols = np.concatenate([i, j])
    order = np.argsort(rows, kind="stable")
    rows, cols = rows[order], cols[order]
    degree = np.bincount(rows, minlength=n_particles)
    width = max(int(degree.max()) if n_particles else 0, 1)
    slot = np.arange(len(rows)) - np.repeat(np.cumsum(degree) - degree, degree)
    neighbors = np.repeat(np.arange(n_particles)[:, None], width, axis=1)
    neighbors[rows, slot] = cols
    out = [neighbors]
    for value in pair_values:
        table = np.zeros((n_particles, width), dtype=np.asarray(value).dtype)
        table[rows, slot] = np.concatenate([value, value])[order]
        out.append(table)
    return tuple(out)


@functools.cache
def _compiled_law(law, neck_model):
    return jax.jit(functools.partial(pair_conductance, law, neck_model=neck_model))


def pair_conductances(law, pairs: ContactPairs, kappa_i, kappa_j, params=None, neck_model=None) -> np.ndarray:
    """Validated ``K_ij`` (W/K) of :class:`ContactPairs`, ``[n_pairs]``, on the host.

    As :func:`sintercond.laws.conductance.pair_conductance` (validated first),
    compiled as one call on a length padded to a power of two with harmless
    touching pairs: eager dispatch would compile every operation at every new
    length (about 1 s); the bucketed length lets packings of similar size,
    and the persistent compilation cache, reuse the compiled law.

    Args:
      law, params, neck_model: as :func:`sintercond.laws.conductance.pair_conductance`.
      pairs: the contacts (:func:`contact_pairs`).
      kappa_i, kappa_j: ``[n_pairs]`` conductivities of the two particles (W/(m K)).
    """
    n = len(pairs.overlap)
    size = max(256, 1 << max(n - 1, 0).bit_length())

    def padded(x, value):
        return np.concatenate([np.asarray(x, dtype=np.float64), np.full(size - n, value)])

    # padding: two unit spheres touching (h = 0, K = 0), inside every law's domain
    args = (padded(pairs.r_i, 1.0), padded(pairs.r_j, 1.0), padded(pairs.overlap, 0.0), padded(kappa_i, 1.0),
            padded(kappa_j, 1.0))
    validate_pair_conductance_inputs(law, *args, params=params, neck_model=neck_model)
    params = {} if params is None else {name: jnp.asarray(value) for name, value in params.items()}
    if any(value.ndim for value in params.values()):  # per-pair parameters: the unpadded length
        args = tuple(a[:n] for a in args)
    # law objects hold a dict, so they are not hashable: compiled afresh
    compiled = _compiled_law(law, neck_model) if isinstance(law, str) else _compiled_law.__wrapped__(law, neck_model)
    return np.asarray(compiled(*args, params=params))[:n]


def contact_table(centres, radii, kappa, law="rojek", params=None, neck_model=None, tolerance=1e-9,
                  periodic_box=None) -> ContactTable:
    """Build the pipe network of a static packing.

    Args:
      centres: ``[n, 3]`` (m).
      radii: ``[n]`` (m).
      kappa: solid conductivity, scalar or ``[n]`` per particle (W/(m K)).
      law, params, neck_model: as :func:`sintercond.laws.conductance.pair_conductance`.
      tolerance: relative gap still counted as contact.
      periodic_box: ``[3]`` box side lengths (m) for a periodic packing, or None.

    Returns:
      :class:`ContactTable` with ``K_ij`` from the law; the input is validated
      first (radii, conductivities, overlaps inside the neck model's domain).
    """
    radii = np.asarray(radii, dtype=np.float64)
    kappa = np.broadcast_to(np.asarray(kappa, dtype=np.float64), radii.shape)
    p = contact_pairs(centres, radii, tolerance, periodic_box)
    k_pairs = pair_conductances(law, p, kappa[p.i], kappa[p.j], params, neck_model)
    # one value per pair on both rows: the network is exactly symmetric, so
    # heat is conserved to round-off (touching with h = 0 has no neck: K = 0)
    neighbors, k = ell_table(len(radii), p.i, p.j, k_pairs)
    return ContactTable(neighbors=jnp.asarray(np.asarray(neighbors, np.int32)), conductance=jnp.asarray(k))


def heat_inflow(temperature, table: ContactTable):
    """``sum_j K_ij (T_j - T_i) + K_iw (T_w - T_i)`` for every particle (W), Rojek et al. Eqs. 3-4."""
    if table.wall_conductance is None:  # the hot path: no zeros array to add
        return -laplacian(temperature, table)
    return wall_inflow(table, temperature.dtype) - laplacian(temperature, table)


def laplacian(x, table: ContactTable):
    """The linear part ``(L x)_i = sum_j K_ij (x_i - x_j) + K_iw x_i`` (symmetric, positive semidefinite)."""
    lx = network_laplacian(table.conductance, table.neighbors, x)
    if table.wall_conductance is not None:
        lx = lx + table.wall_conductance * x
    return lx


@jax.custom_jvp
def network_laplacian(conductance, neighbors, x):
    """``(L x)_i = sum_k K[i, k] (x_i - x[neighbors[i, k]])`` on a symmetric padded table (W per K of x).

    Differentiated by hand so that reverse mode costs about one forward
    pass: the table stores every pair on both rows with the same ``K``, so
    ``L`` is symmetric and its transpose is the same gather, ``L^T c = L c``
    (:func:`sintercond._symmetric.self_adjoint`); JAX alone would transpose
    the gather ``x[neighbors]`` into a scatter-add, several times slower on a
    CPU. Forward mode, ``vmap`` and higher orders work as usual. The
    derivative in ``conductance`` is ``dK_ik (x_i - x_j)`` per slot (each slot
    a separate input; a lift that writes one value on both rows sums them
    back). Requires ``neighbors`` to list ``j`` in row ``i`` iff it lists
    ``i`` in row ``j``, with equal ``K`` (what :func:`contact_table` builds);
    padding slots hold the row's own index (any ``K``: ``x_i - x_i = 0``).

    Args:
      conductance: ``[n, m]`` ``K_ij`` (W/K).
      neighbors: ``[n, m]`` int neighbour indices.
      x: ``[n]`` temperatures (K) or any per-particle field.
    """
    return _gather_laplacian((conductance, neighbors), x)


def _gather_laplacian(table, x):
    conductance, neighbors = table
    return jnp.sum(conductance * (x[:, None] - x[neighbors]), axis=1)


def gather_laplacian(conductance, neighbors, x):
    """:func:`network_laplacian` without its custom derivative, for derivative rules that apply ``L`` themselves."""
    return _gather_laplacian((conductance, neighbors), x)


def _gather_laplacian_cotangent(table, ct):
    # a cotangent arrives as a product (e.g. dt / C * ct); gathered unfused, that reads several arrays per slot
    return _gather_laplacian(table, materialized(ct))


def _network_laplacian_jvp(primals, tangents):
    conductance, neighbors, x = primals
    d_conductance, _, dx = tangents
    value = _gather_laplacian((conductance, neighbors), x)
    # symbolic zeros: a constant table (or field) adds no work to the tangent
    tangent = jnp.zeros_like(value)
    if not isinstance(dx, jax.custom_derivatives.SymbolicZero):
        tangent = self_adjoint(_gather_laplacian, (conductance, neighbors), dx, _gather_laplacian_cotangent)
    if not isinstance(d_conductance, jax.custom_derivatives.SymbolicZero):
        tangent = tangent + _gather_laplacian((d_conductance, neighbors), x)
    return value, tangent


network_laplacian.defjvp(_network_laplacian_jvp, symbolic_zeros=True)


def wall_inflow(table: ContactTable, dtype):
    """The constant part ``K_iw T_w`` (W); 0 without walls."""
    if table.wall_conductance is None:
        return jnp.zeros(table.neighbors.shape[0], dtype)
    return table.wall_conductance * table.wall_temperature


def total_conductance(table: ContactTable):
    """``sum_j K_ij + K_iw`` per particle (W/K): the diagonal of the Laplacian."""
    total = jnp.sum(table.conductance, axis=1)
    return total if table.wall_conductance is None else total + table.wall_conductance


def wall_conductance(centres, radii, kappa, axis, position, law="rojek", *, params=None, neck_model=None,
                     wall_kappa=None):
    """Conductance (W/K) of each particle to a plane wall ``p[axis] = position`` (0 if not touching).

    The wall enters the pair law as a neighbour of infinite radius
    (:mod:`sintercond.laws.walls`); the overlap is the particle's penetration
    ``r - |c[axis] - position|``. Validated like any pair: the law's
    parameters and conductivities, and penetrations inside the neck model's
    domain (``r/3`` for the volume-conserving neck).
    """
    from sintercond.laws import walls

    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    kappa = np.broadcast_to(np.asarray(kappa, dtype=np.float64), radii.shape)
    wall_kappa = kappa if wall_kappa is None else np.broadcast_to(np.asarray(wall_kappa, dtype=np.float64), radii.shape)
    h = radii - np.abs(centres[:, axis] - position)
    touching = h > 0
    k = np.zeros(len(radii))
    if touching.any():
        # the law, its parameters and conductivities as for any pair (the plane's radius plays no part there)
        validate_pair_conductance_inputs(law, radii[touching], radii[touching], np.zeros(int(touching.sum())),
                                         kappa[touching], wall_kappa[touching], params, neck_model)
        k[touching] = np.asarray(walls.wall_conductance(law, radii[touching], h[touching], kappa[touching],
                                                        wall_kappa[touching], params, neck_model))
        bad = ~np.isfinite(k)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise ValueError(f"wall penetration h = {h[first]!r} m of the particle of radius {radii[first]!r} m is "
                             f"beyond the neck model's domain for a plane (r/3 for the volume-conserving neck)")
    return k


def morton_order(centres, bits=10):
    """Permutation that sorts particles along a Morton (Z-order) curve of their positions.

    Renumbering particles with it makes neighbours close in memory, which
    speeds up the gather of :func:`heat_inflow` on large packings
    (benchmarks/RESULTS.md). ``bits`` per axis (<= 21).
    """
    centres = np.asarray(centres, dtype=np.float64)
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    cells = ((centres - lo) / np.where(hi > lo, hi - lo, 1.0) * (2**bits - 1)).astype(np.uint64)
    code = np.zeros(len(centres), dtype=np.uint64)
    for bit in range(bits):
        for axis in range(3):
            code |= ((cells[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")
