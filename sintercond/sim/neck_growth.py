"""Necks that grow in the simulator: the sintering sub-spec of :class:`sintercond.simulate.Physics`, its state and
its update.

First stage (SINTERING.md section 3 of the design notes; docs/simulator.md): the packing does not move and each
contact sinters on its own. The neck radius ``a`` of every contact is state; every ``Sintering.every`` thermal steps
it grows by the kinetic law of :mod:`sintercond.laws.sintering` over those steps' duration, and the contact's approach
follows it through Rojek et al. (2022)'s volume-conserving geometry, ``h = H(a)`` (Eqs. 23-27;
:func:`sintercond.laws.sintering.neck_overlap`). The conductance law is applied to the grown neck at every step
(``Conduction(conductance="lifted")``), so the pipe network stiffens as the necks grow, and the parameters of both
laws stay differentiable.

The temperature of a growth interval
------------------------------------
A neck update covers the ``every`` steps since the last one. The pair temperature of the interval is the mean of the
pair temperature (:func:`sintercond.laws.sintering.pair_temperature`, the mean of the two particles) at its start and at
its end, and the neck grows over the interval at that constant temperature, integrated exactly by
:func:`sintercond.laws.sintering.grow_neck`. The trapezoid makes the error second order in the interval for a smooth
temperature history (``benchmarks/sintering_step.py`` measures it against ``every``).

Shrinkage
---------
Positions are fixed in the first stage, so the shrinkage is what the contacts' approaches would give: the mean
over contacts of ``(H(a) - h_0) / (r_i + r_j)``, ``h_0`` the approach at the start of the run
(:func:`neck_statistics`). It is the linear shrinkage of a chain of such contacts.

Many-body shrinkage
-------------------
With ``Sintering(shrinkage="many_body")`` (second stage) the particles move. The contacts of a packing cannot all
approach at their own free rate (a ring of contacts, a contact that has stopped growing between two that grow), so
each update solves the overdamped force balance of the sintering contacts (Bouvard & McMeeking 1996; Parhami &
McMeeking 1998): a contact pulls its particles together with its sintering force ``F_s`` and resists their
approach rate ``dh/dt`` with the dashpot ``eta_N``, and on every particle that is free to move::

    sum_j [F_s,ij - eta_N,ij dh_ij/dt] n_ij = 0,     dh_ij/dt = (v_i - v_j) . n_ij

(``n_ij`` the unit vector from ``i`` to ``j``). No inertia enters: with diffusion data the dashpot's time
``m / eta_N`` is some 1e-24 s, so the balance is quasi-static. Over an update interval it is taken in the
displacements ``u`` with each contact's secant dashpot: the free growth of the first stage gives the contact's free
approach ``dh_free`` over the interval (``eta_N dh_free = F_s dt`` for a free pair), so
``w_ij = F_s,ij / dh_free,ij`` (``F_s`` from the kinetic law's ``force``, :class:`sintercond.laws.sintering.KineticLaw`)
and the balance is the sparse symmetric positive semi-definite system::

    sum_j w_ij [(u_i - u_j) . n_ij - dh_free,ij] n_ij = 0

solved by conjugate gradients (:func:`conjugate_gradients`) preconditioned by each particle's 3x3 block
``B_i = sum_j w_ij n_ij n_ij^T`` (:func:`balance_blocks`) and started from the Galerkin projection of the solution
on the last updates' balances (:func:`recent_start`), and differentiated implicitly
(:func:`jax.lax.custom_linear_solve`: a gradient is one more solve, never the iterations). It is the minimum of the
dissipation ``sum w (dh - dh_free)^2 / 2``: a free pair, a chain or a uniform lattice approaches exactly as the
first stage; elsewhere contacts carry forces and approach faster or slower than free. A contact that does not grow
over the interval (at its cap, or cold) is weighted as if it approached ``STIFF_CONTACT_RATIO`` times the fastest
one's approach (near-rigid, not an infinite weight). A contact may be pulled apart by its neighbours (a negative
approach): its neck does not shrink (it keeps its size, and its recorded approach ``H(a)``), while the positions
follow the balance.
The balance does not fix every motion: rigid motions of a cluster (the sintering forces have no net force or
torque) and, in a sparse packing, floppy modes (a particle sliding sideways on a single contact) cost nothing.
The solve leaves them out: its displacements are those of least ``sum_i u_i^T B_i u_i``, as if each particle
felt a vanishing drag in proportion to its dashpots along their directions (the conjugate-gradient iterates,
preconditioned by the blocks, keep ``B u`` a sum of the contacts' normals, and so does the start from the recent
balances, taken on the new normals: :func:`balance_displacements`), so a free pair or a symmetric cell keeps its
weighted centre, and the displacements do not depend on where the solve starts.
Reverse-mode gradients solve the system against a cotangent that can reach those free motions, where it is singular:
that solve adds a drag of ``GRADIENT_DRAG`` times each particle's block, so a gradient treats the choice of the
free motions as fixed (exact for distances, necks, shrinkage and temperatures away from position-dependent sources;
for absolute positions, to within the choice's own dependence on the weights).
The components given in ``NeckState.supports`` do not move (particles resting on a plate:
the plate's normal). Each contact's neck then follows its approach through Rojek's geometry,
``a = H^-1(H(a_0) + dh)`` (:func:`sintercond.laws.neck.neck_radius`), never below ``a_0`` and never beyond the
law's cap. Only sintering forces enter: gravity and external loads do not (for the 45-105 um Ti6Al4V of the
preheating scenes a particle's weight is some 1e-8 N against sintering forces of some 1e-4 N, ``pi gamma_s r*``
with ``gamma_s`` about 2 N/m), so the grain-boundary law's ``A`` need not be split into its factors.
The shrinkage of :func:`neck_statistics` is then measured from the positions.

With the mechanics
------------------
With :class:`sintercond.sim.mechanics.Mechanics` on (dynamic contacts), the neck of each pair is history on the half
pair list, :attr:`sintercond.sim.mechanics.MechanicalState.neck` with its approach ``neck_overlap = H(a)``, carried
across rebuilds and reallocations as the tangential springs are (a pair new to the list starts as a point
contact). The elastic laws act on what the neck does not account for, ``delta - H(a)`` (touching only where that
is positive; :func:`sintercond.simulate.sintered_geometry`), as a plastic overlap does in MercuryDPM's sinter
species; the conductance laws on ``max(delta, H(a))``, the volume-conserving neck of which is ``max(a,
neck(delta))``. Spheres whose surfaces are within :data:`POINT_CONTACT_GAP` of ``r_i + r_j`` are in contact (the
point contacts of a touching lattice). Every ``Sintering.every`` steps the necks grow (:func:`grow_necks`):
independently, when the particles move only under their loads (the grown neck takes its approach out of the
elastic overlap, and gravity or the walls close it), or by the many-body balance, whose displacements are added to
the positions and leave each contact's elastic overlap as it was: the packing shrinks without being loaded, and the
explicit dynamics never sees the dashpot. A pair the displacements bring into contact met at the sintering's pace:
its overlap is taken as a neck. A pair whose spheres come apart loses its neck (no sintered bond carries tension
or shear in this model; a packing that cannot stand without one, such as a frictionless simple cubic stack under
gravity, collapses as it would without necks). Start necks: :func:`pair_necks` (point contacts, or the overlaps
taken as necks). The sintering time scale is seconds to minutes and the mechanical step is set by the stiffness
(Eq. 47): a soft modulus makes such runs affordable, and changes only the elastic overlaps.

Stability
---------
Growing necks raise the conductances, and with them lower the explicit step's limit
(:func:`sintercond.sim.thermal.explicit_stability_limit`). Every neck update checks ``dt <= C_i / sum_j K_ij`` on the
grown necks (held particles left out; convection and radiation, which the automatic step of a scene linearises,
are not counted) and sets :attr:`NeckState.unstable` where it fails; :func:`sintercond.rollout.advance` and
``sintercond run`` refuse such a state on the host, naming the step and the limit. :func:`sintercond.simulate.rollout`
(a traced program: the fits) carries the flag and does not raise: call :func:`check_stable` on its end state.

The necks grow at the end of each interval of ``every`` steps: a state read between two updates (an output at a
step that is not a multiple of ``every``) shows the necks of the last update, and steps after the last update of a
run have not grown them yet.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from sintercond.laws import sintering
from sintercond._validation import all_concrete, require_law_params, shown
from sintercond.sim.mechanics import MechanicalState, pair_geometry
from sintercond.laws.neck import neck_radius
from sintercond.contacts.pair_list import pair_sum
from sintercond.state import DynamicContacts, LiftedContacts, pytree_dataclass


SHRINKAGE_MODES = ("independent", "many_body")
"""``Sintering.shrinkage``: contacts that sinter on their own on a packing that does not move (first stage), or
the many-body force balance that moves the particles (module docstring)."""

STIFF_CONTACT_RATIO = 1e-3
"""A contact whose free approach over an update is below this fraction of the update's largest is weighted in the
many-body balance as if it approached that fraction (its dashpot capped): a contact that does not grow (at its cap,
or cold) is near-rigid, and the solve stays well conditioned."""

MIN_BALANCE_ITERATIONS = 2000
"""The fewest conjugate-gradient iterations a many-body balance may take before it is flagged (at least ten per
unknown)."""

POINT_CONTACT_GAP = 1e-9
"""With the mechanics, spheres whose surfaces are less than this fraction of ``r_i + r_j`` apart are in contact for
sintering (:func:`sintercond.sim.mechanics.pair_geometry`'s ``gap``): the point contacts of a touching lattice, at zero
overlap to round-off, sinter as the static table's do."""

NECK_STARTS = ("point", "overlap")
"""How :func:`pair_necks` starts the necks of a sintering run with the mechanics: point contacts whose overlaps
stay elastic, or the overlaps taken as sintered necks."""

BLOCK_FLOOR = 1e-3
"""The fraction of each particle's trace that :func:`balance_blocks` adds to its block's diagonal: it keeps the
block invertible where the particle's contacts leave a direction free, and changes the preconditioner, not the
balance."""

RECENT_BALANCES = 4
"""How many of the last many-body updates the next balance starts from (:func:`recent_start`): two leave more
iterations on the heated lattice of ``benchmarks/balance_iterations.py``, more than four add little (measured
when the balances were kept as particle vectors: 56 against 45 an update at 10,648 spheres); ``[4, c]`` floats
carried in :class:`NeckState`."""

RAYLEIGH_FLOOR = 1e-8
"""A recent balance's remainder whose ``v^T A v / v^T B v`` is below this (:func:`recent_start`) is left out of
the start, whose normalisation would blow up what little of it is not round-off. The starts lie in the range of the
system (:func:`balance_displacements`), whose smooth modes have some ``1 / L^2`` for a packing ``L`` particles
across, far above it."""

RECENT_MISMATCH = 1.0
"""A many-body balance is kept for the next starts only while its contact values give its ``B u`` to this fraction
of the solve's tolerance (at least ``1e-3`` of the root of the machine epsilon, above the round-off of a balance
solved from rest: 1.4e-12 of ``B u`` on the 40-sphere cluster of the tests at a tolerance of 1e-12;
:func:`balance_displacements`); else the recent ones are cleared (:func:`pushed`) and the next balance starts from
rest. The free motions a start can bring are of that size, relative to ``B u``."""

GRADIENT_DRAG = 1e-8
"""The drag, relative to each particle's dashpots, that makes the reverse-mode solve of the many-body balance
regular (at least the square root of the float's epsilon): gradients hold the motions the balance leaves free
(rigid motions, floppy modes) fixed, to about this relative accuracy (module docstring)."""


@dataclasses.dataclass(frozen=True)
class Sintering:
    """The sintering sub-spec of :class:`sintercond.simulate.Physics`: necks that grow with the temperature history.

    Attributes:
      law: a key of :data:`sintercond.laws.sintering.KINETIC_LAWS` (``"grain_boundary"``, ``"power_law"``,
        ``"viscous"``); its parameters are ``Params.sintering``.
      every: thermal steps between two neck updates (>= 1); each update grows the necks over those steps. With
        ``neck_rtol``, the longest interval.
      neck_rtol: None (the necks grow every ``every`` steps), or in (0, 0.5]: the interval follows the necks'
        pace: after each update the next interval is the last one scaled by ``neck_rtol`` over the largest
        relative growth of a neck in it (``(a_new - a_old) / a_new``), at most doubled, at least one step, at
        most ``every`` steps (:func:`next_interval_length`; needs ``every > 1``). The first interval is one step,
        and so is the one after a neck is born (a neck from zero has grown by all of itself).
      quadrature_nodes, newton_iterations: of :func:`sintercond.laws.sintering.grow_neck` (>= 1). An update
        interval grows a neck by a small fraction of itself, so fewer than the law tier's defaults (8, 4)
        reach round-off: 4 and 2 agree with them to 1e-12 on the pulsed chain of ``benchmarks/sintering_step.py``
        (its table gives the error of each choice).
      shrinkage: ``"independent"`` (first stage: positions fixed, each contact's approach recorded) or
        ``"many_body"`` (the overdamped force balance moves the particles; :data:`SHRINKAGE_MODES`).
      balance_tol: relative residual of the many-body balance's conjugate-gradient solve (float32 solves to at
        least 50 machine epsilons); an update that does not reach ten times it sets ``NeckState.unbalanced``.
        The default is far below the error of updating every few steps (``benchmarks/sintering_step.py``); the
        solve's iterations, its whole cost, grow with the log of its inverse.
      recent_start: start each many-body balance on a static packing from the recent ones (:func:`recent_start`;
        the same displacements as from rest, in 3x fewer iterations an update on the heated 97,336-sphere
        lattice of ``benchmarks/balance_iterations.py``); False solves each
        from rest. With the mechanics the balances start from rest (the half pair list reorders its pairs).
    """

    law: str = "grain_boundary"
    every: int = 1
    quadrature_nodes: int = 4
    newton_iterations: int = 2
    shrinkage: str = "independent"
    balance_tol: float = 1e-8
    neck_rtol: float | None = None
    recent_start: bool = True

    def __post_init__(self):
        if self.law not in sintering.KINETIC_LAWS:
            raise ValueError(f"Sintering.law must be one of {sorted(sintering.KINETIC_LAWS)}; got {self.law!r}")
        for name in ("every", "quadrature_nodes", "newton_iterations"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                raise ValueError(f"Sintering.{name} must be an integer >= 1; got {shown(value)}")
        if self.shrinkage not in SHRINKAGE_MODES:
            raise ValueError(f"Sintering.shrinkage must be one of {list(SHRINKAGE_MODES)}; got {self.shrinkage!r}")
        if not (isinstance(self.balance_tol, (int, float)) and 0.0 < self.balance_tol < 1.0):
            raise ValueError(f"Sintering.balance_tol must be in (0, 1); got {shown(self.balance_tol)}")
        if self.neck_rtol is not None and not (isinstance(self.neck_rtol, (int, float)) and not
                                               isinstance(self.neck_rtol, bool) and 0.0 < self.neck_rtol <= 0.5):
            raise ValueError(f"Sintering.neck_rtol must be None or in (0, 0.5]; got {shown(self.neck_rtol)}")
        if not isinstance(self.recent_start, bool):
            raise ValueError(f"Sintering.recent_start must be True or False; got {shown(self.recent_start)}")
        if self.neck_rtol is not None and self.every == 1:
            raise ValueError("Sintering.neck_rtol sets the interval up to Sintering.every steps, which is 1: give "
                             "every > 1 (the longest interval)")


@pytree_dataclass
class NeckState:
    """What the sintering step carries besides the necks (which live on the contacts' pairs: the static table's
    :class:`sintercond.state.LiftedContacts`, or with the mechanics the half pair list's
    :class:`sintercond.sim.mechanics.MechanicalState`).

    Attributes:
      start_overlap: ``[c]`` the approach of each contact at the start of the run (m), for the shrinkage (None
        with the mechanics: measured from ``start_positions``).
      interval_temperature: ``[n]`` particle temperatures at the last neck update (K): the start of the
        current growth interval.
      unstable: bool scalar, set when grown necks made the time step exceed the explicit limit.
      interval_start: int scalar, the step the current growth interval started at.
      supports: ``[n, 3]`` bool, the displacement components held at zero by the many-body balance
        (``Sintering(shrinkage="many_body")``), or None (independent contacts).
      unbalanced: bool scalar, set when a many-body balance did not converge (None without one).
      start_positions: ``[n, 3]`` the positions at the start of a many-body run (m), the shrinkage's reference
        (None without one).
      interval_length: int scalar, the steps of the current growth interval with ``Sintering.neck_rtol`` (1 at the
        start; unused without it).
      recent_balances: ``[k, c]`` the last :data:`RECENT_BALANCES` many-body updates' contact values ``y`` of
        their displacements times their blocks, ``B u = sum_j y_ij n_ij`` (:func:`balance_displacements`), newest
        first (zeros before them): the next balance's start (:func:`recent_start`); None without many-body
        shrinkage, and with the mechanics.
      balance_iterations: int scalar, the conjugate-gradient iterations of the last many-body balance of an
        explicit step (the adaptive integrator's stages do not record theirs; None without many-body shrinkage).
    """

    start_overlap: Any
    interval_temperature: Any
    unstable: Any
    interval_start: Any
    supports: Any = None
    unbalanced: Any = None
    start_positions: Any = None
    interval_length: Any = None
    recent_balances: Any = None
    balance_iterations: Any = None


def neck_state(contacts: LiftedContacts, temperature, step=0, supports=None, positions=None) -> NeckState:
    """The :class:`NeckState` at the start of a run on ``contacts`` with particle ``temperature`` ``[n]`` (K), at
    ``step`` (the state's, :func:`sintercond.simulate.init_state`). The table must list each contact in both its
    rows (as :func:`sintercond.simulate.lifted_contacts` does).

    ``supports``: for ``Sintering(shrinkage="many_body")``, ``[n, 3]`` bool, the displacement components that stay
    (e.g. ``[False, False, True]`` for a particle resting on a plate normal to z); all
    False lets the packing shrink about its centre. None for independent contacts. ``positions``: ``[n, 3]`` the
    particles' positions (m), given with ``supports``: the reference of the many-body shrinkage."""
    step_type = jnp.int64 if jax.config.jax_enable_x64 else jnp.int32  # as SimState.step
    n = jnp.asarray(temperature).shape[0]
    if isinstance(contacts, DynamicContacts):  # with the mechanics: the necks live on the half pair list
        if positions is None:
            raise ValueError("neck_state on dynamic contacts (sintering with the mechanics) needs the positions: "
                             "the shrinkage is measured from them")
        start_overlap = None
    else:
        if (supports is None) != (positions is None):
            raise ValueError("neck_state takes supports and positions together (many-body shrinkage) or neither")
        check_table(contacts)
        start_overlap = jnp.asarray(contacts.overlap)
    start = None if positions is None else _start_positions(positions, n)
    return NeckState(start_overlap=start_overlap, interval_temperature=jnp.asarray(temperature),
                     unstable=jnp.zeros((), bool), interval_start=jnp.asarray(step, step_type),
                     supports=None if supports is None else _supports(supports, n),
                     unbalanced=None if supports is None else jnp.zeros((), bool),
                     start_positions=start,
                     interval_length=jnp.asarray(1, step_type),
                     recent_balances=None if supports is None or start_overlap is None else jnp.zeros(
                         (RECENT_BALANCES, start_overlap.shape[0]), start.dtype),
                     balance_iterations=None if supports is None else jnp.zeros((), step_type))


def check_table(contacts: LiftedContacts) -> None:
    """Raise ``ValueError`` unless the table of ``contacts`` lays each pair ``(i, j)`` into one slot of row ``i``
    and one of row ``j`` (concrete arrays; :func:`sintercond.simulate.lifted_contacts` builds such tables): the
    network is then exactly symmetric and every neck grown on its pair is seen from both particles."""
    if not all_concrete(contacts.neighbors, contacts.pairs, contacts.slot_pair):
        return
    neighbors, pairs, slot_pair = (np.asarray(x) for x in (contacts.neighbors, contacts.pairs, contacts.slot_pair))
    n, c = neighbors.shape[0], pairs.shape[0]
    rows = np.broadcast_to(np.arange(n)[:, None], neighbors.shape)
    valid = (neighbors != rows) & (neighbors < n)
    held = slot_pair[valid]
    ends = pairs[np.minimum(held, max(c - 1, 0))] if c else np.zeros((held.size, 2), np.int64)
    lo, hi = np.minimum(rows[valid], neighbors[valid]), np.maximum(rows[valid], neighbors[valid])
    consistent = (held < c) & (ends[:, 0] == lo) & (ends[:, 1] == hi)
    twice = held.size == 2 * c and np.all(np.bincount(held[held < c], minlength=c) == 2)
    if not (consistent.all() and twice and np.all(slot_pair[~valid] == c)):
        raise ValueError("the contact table lists a contact in one of its rows only; each contact (i, j) must be in "
                         "row i and row j (simulate.lifted_contacts builds such tables)")


def _start_positions(positions, n):
    positions = jnp.asarray(positions)
    if positions.shape != (n, 3):
        raise ValueError(f"positions must be [n, 3] = [{n}, 3] (m); got shape {positions.shape}")
    return positions


def _supports(supports, n):
    supports = np.asarray(supports)
    if supports.dtype != bool or supports.shape != (n, 3):
        raise ValueError(f"supports must be a [n, 3] = [{n}, 3] bool array (the components that stay); got "
                         f"{supports.dtype} of shape {supports.shape}")
    return jnp.asarray(supports)


def law_params(spec: Sintering, params) -> dict:
    """The kinetic law's defaults overridden by ``params`` (``Params.sintering``); unknown keys raise, naming them."""
    if params is None:
        raise ValueError("Physics.sintering needs Params.sintering: a dict of the kinetic law's parameters "
                         f"({sorted(sintering.KINETIC_LAWS[spec.law].default_params)}), {{}} for its defaults")
    if not isinstance(params, dict):
        raise ValueError(f"Params.sintering must be a dict of the kinetic law's parameters; got {params!r}")
    try:
        return sintering.law_params(spec.law, params)
    except ValueError as error:
        raise ValueError(f"Params.sintering: {error}") from None


def validate_sintering(spec: Sintering, params, contacts: LiftedContacts, radii, carried: NeckState | None = None
                       ) -> None:
    """Raise ``ValueError`` naming the field unless the necks and the kinetic parameters can grow (concrete values).

    Parameters as :func:`sintercond.laws.sintering.validate_growth_inputs` wants them; every neck in
    ``[0, min(r_i, r_j)]`` of its pair. With ``carried`` (the state's :class:`NeckState`): supports given exactly
    when the shrinkage is many-body, and then every contact's centres at the start positions no farther apart than
    its radii (a contact across a periodic boundary cannot shrink by moving its particles).
    """
    if carried is not None:
        many_body = spec.shrinkage == "many_body"
        if many_body and carried.supports is None:
            raise ValueError("Sintering(shrinkage='many_body') needs NeckState.supports: "
                             "neck_growth.neck_state(contacts, temperature, supports=..., positions=...) ([n, 3] "
                             "bool, the displacement components that stay, all False for none; the positions)")
        if not many_body and carried.supports is not None:
            raise ValueError(f"NeckState.supports is for Sintering(shrinkage='many_body'); the shrinkage is "
                             f"{spec.shrinkage!r}: build the state without supports")
        static = isinstance(contacts, LiftedContacts)
        if many_body and static and all_concrete(carried.start_positions, radii, contacts.pairs):
            x, r = np.asarray(carried.start_positions, np.float64), np.asarray(radii, np.float64)
            pairs = np.asarray(contacts.pairs)
            gap = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1) - r[pairs[:, 0]] - r[pairs[:, 1]]
            far = gap > 1e-6 * np.minimum(r[pairs[:, 0]], r[pairs[:, 1]])
            if far.any():
                k = int(np.flatnonzero(far)[0])
                raise ValueError(f"many-body shrinkage moves the particles of each contact together, so their centres "
                                 f"must be within r_i + r_j; particles {int(pairs[k, 0])} and {int(pairs[k, 1])} are "
                                 f"{gap[k]:.3g} m apart beyond it (a contact across a periodic boundary?)")
    merged = law_params(spec, params)
    if isinstance(contacts, DynamicContacts):
        _validate_law(spec, merged)
        return
    if not all_concrete(merged, contacts.neck, radii):
        return
    _validate_law(spec, merged)
    pairs, neck, r = np.asarray(contacts.pairs), np.asarray(contacts.neck, np.float64), np.asarray(radii)
    limit = np.minimum(r[pairs[:, 0]], r[pairs[:, 1]])
    bad = ~((neck >= 0) & (neck <= limit * (1 + 1e-12)))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"contact necks must lie in [0, min(r_i, r_j)]; the neck of particles {int(pairs[k, 0])} and "
                         f"{int(pairs[k, 1])} is {shown(neck[k])} m")


def _validate_law(spec: Sintering, merged: dict) -> None:
    """Raise ``ValueError`` naming the key unless the kinetic law's parameters ``merged`` are in range (concrete)."""
    if not all_concrete(merged):
        return
    law = sintering.kinetic_law(spec.law)
    require_law_params("Params.sintering", law, merged,
                       lambda name: f"Params.sintering[{name!r}] of kinetic law {law.name!r} ({law.units[name]})")
    if "dihedral_angle" in merged and not float(np.max(merged["dihedral_angle"])) <= 180.0:
        raise ValueError(f"Params.sintering['dihedral_angle'] must be in (0, 180] degrees; got "
                         f"{shown(merged['dihedral_angle'])}")


def validate_pair_necks(motion: MechanicalState, radii, pairs) -> None:
    """Raise ``ValueError`` unless the necks on a half pair list ``pairs`` ``[c, 2]`` exist and lie in
    ``[0, min(r_i, r_j)]`` with their approaches ``>= 0`` (concrete values)."""
    if motion is None or motion.neck is None or motion.neck_overlap is None:
        raise ValueError("sintering with the mechanics needs MechanicalState.neck and neck_overlap (the necks on the "
                         "half pair list): neck_growth.with_pair_necks(motion, contacts, positions, radii, start)")
    if not all_concrete(motion.neck, motion.neck_overlap, radii, pairs):
        return
    pairs, r = np.asarray(pairs), np.asarray(radii, np.float64)
    neck, h = np.asarray(motion.neck, np.float64), np.asarray(motion.neck_overlap, np.float64)
    if neck.shape != (len(pairs),) or h.shape != (len(pairs),):
        raise ValueError(f"MechanicalState.neck and neck_overlap must be [capacity] = [{len(pairs)}] (one per pair of "
                         f"the half list); got shapes {neck.shape} and {h.shape}")
    n = len(r)
    real = pairs[:, 0] < pairs[:, 1]
    limit = np.where(real, np.minimum(r[np.minimum(pairs[:, 0], n - 1)], r[np.minimum(pairs[:, 1], n - 1)]), 0.0)
    bad = ~((neck >= 0) & (neck <= limit * (1 + 1e-12)) & (h >= 0) & np.isfinite(h))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"MechanicalState.neck must lie in [0, min(r_i, r_j)] and neck_overlap be >= 0; pair {k} "
                         f"{tuple(int(v) for v in pairs[k])} has neck {shown(neck[k])} m, neck_overlap {shown(h[k])} m")


def _interval_temperature(carried: NeckState, end_temperature, i, j):
    """``[c]`` the pair temperature of the growth interval (K): the mean of its start and end values (module
    docstring), of the pairs ``(i, j)``."""
    start = carried.interval_temperature
    return 0.5 * (sintering.pair_temperature(start[i], start[j])
                  + sintering.pair_temperature(end_temperature[i], end_temperature[j]))


def _grown(spec: Sintering, params: dict, start_neck, r_i, r_j, temperature, duration):
    """``[c]`` neck of each pair after growing freely for ``duration`` (s) at ``temperature`` ``[c]`` (K) from
    ``start_neck`` ``[c]`` (m)."""
    dtype = start_neck.dtype
    return sintering._grow_neck(sintering.kinetic_law(spec.law), start_neck, r_i, r_j, temperature[None],
                                jnp.reshape(jnp.asarray(duration, dtype), (1,)), params,
                                quadrature_nodes=spec.quadrature_nodes, newton_iterations=spec.newton_iterations)[0]


def _pair_normals(pairs, positions):
    """``[c, 3]`` unit vectors ``n_ij`` from ``i`` to ``j`` of the contacts ``pairs`` ``[c, 2]`` at ``positions``."""
    separation = positions[pairs[:, 1]] - positions[pairs[:, 0]]
    return separation / jnp.linalg.norm(separation, axis=1, keepdims=True)


def balance_displacements(pairs, positions, weights, free_approach, supports, tol, normal=None, recent=None,
                          table=None):
    """Displacements ``[n, 3]`` (m) of the many-body balance ``sum_j w_ij [(u_i - u_j) . n_ij - dh_free,ij] n_ij = 0``
    on the components that are not ``supports`` (module docstring), whether its solve fell short, its iterations,
    and what the next balances start from.

    Preconditioned conjugate gradients (:func:`conjugate_gradients`), each particle's 3x3 block of the system
    inverted (block Jacobi, :func:`balance_blocks`), started from the balance's Galerkin projection on the
    ``recent`` balances (:func:`recent_start`): over an interval the displacements change little from one update
    to the next, so the start leaves a small fraction of the right-hand side as its residual.
    A balance is kept as the contact values ``y`` ``[c]`` of its ``B u = sum_j y_ij n_ij`` (``B`` each particle's
    block; :func:`conjugate_gradients` carries them along its iterates, which from rest keep ``B u`` in the range of
    the system, a sum of the contacts' normals) and started from as ``B^-1 sum_j y_ij n_ij`` on the new normals and
    blocks: whatever the ``y``, such a start has no part along the motions the balance leaves free, so the solve
    gives the displacements it gives from rest (those of least ``sum_i u_i^T B_i u_i``) and only takes fewer
    iterations. Kept as particle vectors (``u``, or ``B u`` mapped by the new blocks), the starts carried the free
    motions that the normals' turn left in them, amplified by the blocks' floor on a particle with one or two
    contacts: the preheating bed's shrinkage went to -0.060 against 0.0042 from rest.

    Args:
      pairs: ``[c, 2]`` the contacts; positions ``[n, 3]`` (m) give their normals ``n_ij`` (``i`` to ``j``).
      weights: ``[c]`` the secant dashpots ``w_ij`` (any consistent unit; only ratios enter), >= 0.
      free_approach: ``[c]`` the approach each contact would make on its own (m).
      supports: ``[n, 3]`` bool, the components held at zero.
      tol: relative residual of the conjugate-gradient solve.
      normal: ``[c, 3]`` the unit normals, if given (a half pair list's, whose padding pairs have weight 0);
        else from ``positions``.
      recent: ``[k, c]`` earlier balances on the same contacts (the last return value), or None (start from rest).
      table: ``(slot_pair, neighbors)`` ``[n, m]`` of a static table listing each pair in both its rows
        (:class:`sintercond.state.LiftedContacts`), or None: the forces on the particles are then gathered from
        each row's slots instead of scattered from the pairs (the same sums, some 2.5 times faster on a CPU).

    Returns:
      ``(u, unbalanced, iterations, balance)``: the displacements, a bool scalar set when the residual exceeds
      ``10 tol``, the iterations the solve took (int scalar), and the contact values ``y`` ``[c]`` of ``B u`` (for
      ``recent``).
    """
    i, j = pairs[:, 0], pairs[:, 1]
    normal = _pair_normals(pairs, positions) if normal is None else normal
    movable = ~supports

    if table is not None:
        slot_sign, slot_pair = _slot_signs(table, positions.dtype)

    def on_particles(per_pair):  # [c] -> [n, 3]: + along n_ij on i, - on j, on the movable components
        f = per_pair[:, None] * normal
        if table is None:
            summed = jnp.zeros_like(positions).at[i].add(f).at[j].add(-f)
        else:
            padded = jnp.concatenate([f, jnp.zeros((1, 3), f.dtype)])  # slot_pair is c in padding
            summed = jnp.sum(slot_sign * padded[slot_pair], axis=1)
        return jnp.where(movable, summed, 0.0)

    def pulled(u):  # the dashpots' pull w_ij (u_i - u_j) . n_ij [c] on the movable components
        u_free = jnp.where(movable, u, 0.0)
        return weights * jnp.sum((u_free[i] - u_free[j]) * normal, axis=1)

    def operator_and_pull(u):  # P K P + (I - P): symmetric, the held components decoupled
        pull = pulled(u)
        return jnp.where(movable, on_particles(pull), u), pull

    def operator(u):
        return operator_and_pull(u)[0]

    rhs = on_particles(weights * free_approach)
    blocks, inverse_blocks = balance_blocks(pairs, normal, weights, movable)
    precondition = lambda r: jnp.einsum("nab,nb->na", inverse_blocks, r)  # noqa: E731
    start = _recent(recent, on_particles, precondition, operator, positions.dtype, blocks)
    maxiter = max(10 * positions.size, MIN_BALANCE_ITERATIONS)

    def solve(matvec, b):  # b is rhs (the primal solve): the contact values follow it; else they are not used
        x0, y0 = start(b)
        # a start farther from the balance than rest (the contacts changed since the recent balances) is not taken
        taken = jax.lax.stop_gradient(jnp.linalg.norm(b - matvec(x0)) <= jnp.linalg.norm(b))
        x0, y0 = jnp.where(taken, x0, 0.0), jnp.where(taken, y0, 0.0)
        x, iterations, y = conjugate_gradients(matvec, b, x0, precondition, tol, maxiter, operator_and_pull,
                                               weights * free_approach - pulled(x0))
        return x, (iterations, y0 + y)

    # reverse mode solves the system against a cotangent that need not lie in its range (the free motions):
    # there the drag that selects the solution is made finite, GRADIENT_DRAG times the blocks (the norm in which
    # the forward solve leaves the free motions out)
    drag = max(GRADIENT_DRAG, float(jnp.finfo(positions.dtype).eps) ** 0.5)

    def transpose_solve(matvec, b):
        x, iterations = conjugate_gradients(
            lambda v: matvec(v) + drag * jnp.where(movable, jnp.einsum("nab,nb->na", blocks, v), 0.0), b,
            jnp.zeros_like(b), precondition, tol, maxiter)
        return x, (iterations, jnp.zeros_like(weights))

    u, (iterations, balance) = jax.lax.custom_linear_solve(operator, rhs, solve, transpose_solve, has_aux=True)
    residual = jnp.linalg.norm(rhs - operator(u))
    converged = (residual <= 10.0 * tol * jnp.linalg.norm(rhs)) & jnp.all(jnp.isfinite(u))
    # y is defined up to the packing's self-stresses (contact values in balance on their own), which each solve adds
    # to and the starts carry on; as they grow, so does their round-off in B u: such a balance is not kept
    balance, u_held = jax.lax.stop_gradient((balance, u))
    kept = jnp.where(movable, jnp.einsum("nab,nb->na", blocks, u_held), 0.0)
    bound = max(RECENT_MISMATCH * tol, 1e-3 * float(jnp.finfo(positions.dtype).eps) ** 0.5) * jnp.linalg.norm(kept)
    represents = jnp.linalg.norm(on_particles(balance) - kept) <= bound
    return u, ~converged, iterations, jnp.where(represents, balance, 0.0)


def _slot_signs(table, dtype):
    """``(sign, slot_pair)``: ``[n, m, 1]`` +1 where a static table's row is its pair's ``i``, -1 where its ``j``."""
    slot_pair, neighbors = table
    rows = jnp.arange(neighbors.shape[0], dtype=neighbors.dtype)[:, None]
    return jnp.where(neighbors > rows, 1.0, -1.0).astype(dtype)[:, :, None], slot_pair  # pairs have i < j


def _recent(recent, on_particles, precondition, operator, dtype, blocks):
    """The start of a balance as a linear map of its right-hand side ``b``: ``(x0, y0)``, the displacements
    ``[n, 3]`` and their contact values ``[c]`` (``B x0 = sum_j y0_ij n_ij``), from the ``recent`` balances'
    contact values ``[k, c]`` (:func:`balance_displacements`); from rest without them."""
    if recent is None:
        return lambda b: (jnp.zeros_like(b), 0.0)
    recent = jax.lax.stop_gradient(recent.astype(dtype))
    displacements = jax.vmap(lambda y: precondition(on_particles(y)))(recent)
    coefficients = recent_start(operator, displacements, dtype, blocks)

    def start(b):
        c = coefficients(b)
        return jnp.einsum("k,kna->na", c, displacements), c @ recent

    return start


def balance_blocks(pairs, normal, weights, movable):
    """``(blocks, inverses)`` ``[n, 3, 3]``: each particle's diagonal block ``sum_j w_ij n_ij n_ij^T`` of the
    many-body balance on its movable components (:func:`balance_displacements`), with :data:`BLOCK_FLOOR` of its
    trace added to its diagonal, and their inverses (the held components' rows and columns are the identity's).

    A direction that none of a particle's contacts resists (a particle on one contact, or on two) has no row in
    the system: the floor only keeps the block invertible there, and the iterates never move along it."""
    i, j = pairs[:, 0], pairs[:, 1]
    outer = weights[:, None, None] * normal[:, :, None] * normal[:, None, :]
    n = movable.shape[0]
    blocks = jnp.zeros((n, 3, 3), normal.dtype).at[i].add(outer).at[j].add(outer)
    both_movable = movable[:, :, None] & movable[:, None, :]
    trace = jnp.trace(blocks, axis1=1, axis2=2)
    floor = jnp.where(trace > 0, BLOCK_FLOOR * trace, 1.0)
    diagonal = jnp.where(movable, floor[:, None], 1.0)
    blocks = jnp.where(both_movable, blocks, 0.0) + diagonal[:, :, None] * jnp.eye(3, dtype=normal.dtype)
    return blocks, jnp.linalg.inv(blocks)


def recent_start(operator, recent, dtype, blocks=None):
    """The start of a balance's solve: the Galerkin projection of its solution on the span of the ``recent``
    displacements ``[k, n, 3]`` (``V (V^T A V)^-1 V^T b``, ``A`` the ``operator``), as the map from the right-hand
    side ``b`` to the ``[k]`` coefficients of the displacements. The basis is A-orthonormalised by Gram-Schmidt; a
    displacement whose remainder keeps less than 1000 machine epsilons of its energy ``v^T A v`` is dropped (it
    repeats the others, or is 0), and so, given the ``blocks`` ``B``, is one whose remainder's
    ``v^T A v / v^T B v`` is below :data:`RAYLEIGH_FLOOR`.
    Linear in ``b``, so the solve stays a linear map (:func:`jax.lax.custom_linear_solve`); the displacements are
    constants to it (their derivative does not enter the solution's, which the solve's own implicit derivative
    gives)."""
    floor = 1e3 * float(jnp.finfo(dtype).eps)  # below it, a remainder is round-off of the others
    k = recent.shape[0]
    basis, images, combinations = [], [], []
    for index, v in enumerate(jax.lax.stop_gradient(recent.astype(dtype))):
        av = operator(v)
        energy = jnp.vdot(v, av)
        combination = jnp.zeros((k,), dtype).at[index].set(1.0)  # of the recent displacements
        for q, aq, cq in zip(basis, images, combinations):
            c = jnp.vdot(q, av)
            v, av, combination = v - c * q, av - c * aq, combination - c * cq
        norm_sq = jnp.vdot(v, av)
        keep = norm_sq > floor * energy
        if blocks is not None:  # a remainder with little energy for its size: its normalisation would blow it up
            keep = keep & (norm_sq > RAYLEIGH_FLOOR * jnp.vdot(v, jnp.einsum("nab,nb->na", blocks, v)))
        inverse_norm = jnp.where(keep, jax.lax.rsqrt(jnp.where(keep, norm_sq, 1.0)), 0.0)
        basis.append(v * inverse_norm)
        images.append(av * inverse_norm)
        combinations.append(combination * inverse_norm)
    return lambda b: sum(jnp.vdot(q, b) * cq for q, cq in zip(basis, combinations))


def conjugate_gradients(matvec, b, x0, preconditioner, tol, maxiter, with_pull=None, pulled_residual=None):
    """``(x, iterations)``: preconditioned conjugate gradients on the symmetric positive semi-definite ``matvec``
    from ``x0``, until the residual is at most ``tol |b|``, after ``maxiter`` iterations, or when a search
    direction has no positive curvature left (round-off, or a right-hand side outside the range).

    :func:`jax.scipy.sparse.linalg.cg` with its iterations counted (it does not report them), and optionally
    carrying the contact values of its steps: given ``with_pull(p) -> (A p, g p)`` for an operator ``A = P g``
    (``g`` to another space, ``P`` back; ``A`` on ``b``'s components where ``P`` is not) and the residual of ``x0``
    there, ``b - A x0 = P pulled_residual``, it returns ``(x, iterations, y)`` with ``B (x - x0) = P y``, ``B`` the
    inverse of the ``preconditioner`` (the iterates are sums of preconditioned residuals, each ``P`` of something).
    """
    threshold = (tol * jnp.linalg.norm(b)) ** 2
    carried = with_pull is not None
    if not carried:
        with_pull = lambda p: (matvec(p), jnp.zeros((0,), b.dtype))  # noqa: E731
        pulled_residual = jnp.zeros((0,), b.dtype)

    def unfinished(carry):
        r, k, broken = carry[1], carry[4], carry[5]
        return (jnp.vdot(r, r) > threshold) & (k < maxiter) & ~broken

    def iterate(carry):
        x, r, p, rz, k, _, y, rho, pi = carry  # B p = P pi, r = P rho (where P is), B (x - x0) = P y
        ap, gp = with_pull(p)
        curvature = jnp.vdot(p, ap)
        broken = ~(curvature > 0) | ~(rz > 0)  # no descent left (or not finite): the caller checks the residual
        alpha = jnp.where(broken, 0.0, rz / jnp.where(broken, 1.0, curvature))
        x, r, y, rho = x + alpha * p, r - alpha * ap, y + alpha * pi, rho - alpha * gp
        z = preconditioner(r)
        rz_new = jnp.vdot(r, z)
        beta = jnp.where(broken, 0.0, rz_new / jnp.where(broken, 1.0, rz))
        return x, r, z + beta * p, rz_new, k + 1, broken, y, rho, rho + beta * pi

    r = b - matvec(x0)
    z = preconditioner(r)
    zero = jnp.zeros_like(pulled_residual)
    start = (x0, r, z, jnp.vdot(r, z), jnp.zeros((), jnp.int32), jnp.zeros((), bool), zero, pulled_residual,
             pulled_residual)
    x, _, _, _, iterations, _, y, _, _ = jax.lax.while_loop(unfinished, iterate, start)
    return (x, iterations, y) if carried else (x, iterations)


def _balanced_necks(spec: Sintering, params: dict, pairs, normal, active, a_start, r_i, r_j, temperature, duration,
                    positions, supports, recent, table):
    """The many-body update of the pairs ``[c, 2]`` (module docstring): ``(a, u, unbalanced, iterations, balance)``,
    the necks ``[c]`` (m) after the interval, the displacements ``[n, 3]`` (m), whether the balance fell short, its
    solve's iterations (started from the ``recent`` balances) and its contact values for the next starts
    (:func:`balance_displacements`). Only the ``active`` pairs sinter and enter the balance; the others keep
    ``a_start``."""
    i, j = pairs[:, 0], pairs[:, 1]
    law = sintering.kinetic_law(spec.law)
    a_free = _grown(spec, params, a_start, r_i, r_j, temperature, duration)
    h_start = sintering.neck_overlap(a_start, r_i, r_j)
    free = jnp.where(active, sintering.neck_overlap(a_free, r_i, r_j) - h_start, 0.0)
    fastest = jnp.max(free, initial=0.0)
    growing = fastest > 0
    weights = jnp.where(growing & active, law.force(0.5 * (a_start + a_free), r_i, r_j, params)
                        / jnp.maximum(free, jnp.where(growing, STIFF_CONTACT_RATIO * fastest, 1.0)), 0.0)
    tol = max(spec.balance_tol, 50.0 * float(jnp.finfo(positions.dtype).eps))
    u, unbalanced, iterations, balance = balance_displacements(pairs, positions, weights, free, supports, tol,
                                                               normal, recent, table)
    approach = jnp.sum((u[i] - u[j]) * normal, axis=1)
    cap = jnp.minimum(law.cap(r_i, r_j, params), jnp.minimum(r_i, r_j))
    h = jnp.clip(h_start + approach, h_start, sintering.neck_overlap(cap, r_i, r_j))
    a = jnp.where(active, jnp.clip(neck_radius(r_i, r_j, h), a_start, cap), a_start)
    return a, u, unbalanced, iterations, balance


def grow_necks(spec: Sintering, params: dict, carried: NeckState, pairs, neck, active, *, positions, radii,
               end_temperature, duration, normal=None, table=None):
    """One growth interval of the necks of the contacts ``pairs`` ``[c, 2]``: a :class:`Grown`.

    The one growth path of both contact sets (a static packing's pairs, :class:`sintercond.state.LiftedContacts`;
    the half pair list that follows the motion with the mechanics). ``neck`` ``[c]`` (m) at the start of the
    interval of ``duration`` (s); only the ``active`` pairs (bool ``[c]``, or True) sinter, the others get no neck.
    The pair temperature of the interval is the mean of its value at the start (``carried.interval_temperature``)
    and at the end (``end_temperature`` ``[n]``, K; module docstring). Each contact grows on its own
    (``shrinkage="independent"``) or in the many-body balance that moves the particles, with the unit normals
    ``normal`` ``[c, 3]`` if given, else from ``positions`` ``[n, 3]`` (m); the balance starts from
    ``carried.recent_balances`` and sums its forces on a static packing's ``table`` (``(slot_pair,
    neighbors)``, :func:`balance_displacements`) when given.
    """
    i, j = pairs[:, 0], pairs[:, 1]
    r_i, r_j = radii[i], radii[j]
    temperature = _interval_temperature(carried, end_temperature, i, j)
    active = jnp.broadcast_to(jnp.asarray(active), i.shape)
    a_start = jnp.where(active, neck, 0.0)
    u = unbalanced = iterations = balance = None
    if spec.shrinkage == "many_body":
        normal = _pair_normals(pairs, positions) if normal is None else normal
        a, u, unbalanced, iterations, balance = _balanced_necks(spec, params, pairs, normal, active, a_start, r_i, r_j,
                                                       temperature, duration, positions, carried.supports,
                                                       carried.recent_balances if spec.recent_start else None,
                                                       table)
    else:
        a = _grown(spec, params, a_start, r_i, r_j, temperature, duration)
    a = jnp.where(active, a, 0.0)
    return Grown(a, jnp.where(active, sintering.neck_overlap(a, r_i, r_j), 0.0), u, unbalanced, iterations, balance)


class Grown(NamedTuple):
    """What :func:`grow_necks` returns. ``neck``, ``neck_overlap``: ``[c]`` the necks and their approaches ``H(a)``
    (m); with many-body shrinkage ``displacement`` ``[n, 3]`` (m), ``unbalanced`` (bool scalar, the balance fell
    short), ``iterations`` (int scalar, its solve's) and ``balance`` (``[c]``, the contact values of ``B u``: what
    the next balances start from, :func:`balance_displacements`), else None."""

    neck: Any
    neck_overlap: Any
    displacement: Any = None
    unbalanced: Any = None
    iterations: Any = None
    balance: Any = None


def with_displacement(carried: NeckState, grown: Grown) -> NeckState:
    """``carried`` after a many-body update ``grown``: its balance the newest of the recent ones (:func:`pushed`),
    its iterations recorded, its shortfall flagged (``carried`` itself without many-body shrinkage)."""
    if grown.displacement is None:
        return carried
    return dataclasses.replace(
        carried, recent_balances=None if carried.recent_balances is None else pushed(carried.recent_balances,
                                                                                     grown.balance),
        unbalanced=carried.unbalanced | grown.unbalanced,
        balance_iterations=grown.iterations.astype(carried.balance_iterations.dtype))


def pushed(recent, balance):
    """``recent`` ``[k, c]`` (:attr:`NeckState.recent_balances`) with ``balance`` ``[c]`` the newest, the oldest
    dropped; all cleared by a balance of zeros (one not kept: :data:`RECENT_MISMATCH`)."""
    return jnp.where(jnp.any(balance != 0), jnp.concatenate([balance.astype(recent.dtype)[None], recent[:-1]]), 0.0)


def met_necks(geometry, neck, neck_overlap, moved, radii):
    """``(neck, neck_overlap)`` ``[c]`` (m) of a half pair list after a many-body balance moved its particles to
    ``moved`` ``[n, 3]`` (m): a pair that the displacements brought into contact met at the sintering's creeping
    pace, not by an impact, so its overlap is taken as a neck (``a = H^-1(delta)``) and the elastic laws do not
    see it. ``geometry``: the :class:`sintercond.sim.mechanics.PairGeometry` before the move, with the gap
    :data:`POINT_CONTACT_GAP`."""
    after = pair_geometry(moved, radii, geometry.pairs, POINT_CONTACT_GAP)
    closed = after.touching & ~geometry.touching
    met = jnp.maximum(after.overlap, 0.0)
    return (jnp.where(closed, neck_radius(radii[geometry.i], radii[geometry.j], met), neck),
            jnp.where(closed, met, neck_overlap))


def pair_necks(contacts: DynamicContacts, positions, radii, start: str = "point"):
    """``(neck, neck_overlap)`` ``[capacity]`` (m) of a half pair list at the start of a sintering run with the
    mechanics: :attr:`sintercond.sim.mechanics.MechanicalState.neck` and ``neck_overlap``.

    ``start``: ``"point"``, every contact a point contact (``a = 0``: the overlaps stay elastic, the packing keeps
    its load); ``"overlap"``, every overlap ``delta`` taken as a sintered neck, the volume-conserving neck of it
    (``a = H^-1(delta)``, Rojek et al. 2022, Eqs. 23-27) with ``H(a) = delta``: the contacts then carry no elastic
    load at the start.
    """
    if start not in NECK_STARTS:
        raise ValueError(f"the start of the necks must be one of {list(NECK_STARTS)}; got {start!r}")
    geometry = pair_geometry(jnp.asarray(positions), jnp.asarray(radii), contacts.pairs.pairs)
    zeros = jnp.zeros(geometry.overlap.shape, geometry.overlap.dtype)
    if start == "point":
        return zeros, zeros
    r_i, r_j = jnp.asarray(radii)[geometry.i], jnp.asarray(radii)[geometry.j]
    return jnp.where(geometry.touching, neck_radius(r_i, r_j, geometry.overlap), 0.0), geometry.overlap


def with_pair_necks(motion: MechanicalState, contacts: DynamicContacts, positions, radii, start: str = "point"
                    ) -> MechanicalState:
    """``motion`` (:func:`sintercond.sim.mechanics.mechanical_state`) with the necks of :func:`pair_necks`."""
    neck, overlap = pair_necks(contacts, positions, radii, start)
    return dataclasses.replace(motion, neck=neck, neck_overlap=overlap)


def neck_statistics(state) -> dict:
    """Mean and largest neck ratio ``a / min(r_i, r_j)`` over the contacts, and the mean linear shrinkage
    ``(h - h_0) / (r_i + r_j)`` (module docstring) of a :class:`sintercond.simulate.SimState` with sintering:
    ``h - h_0`` the change of the approach ``H(a)`` of the neck (independent contacts), or of the distance
    ``|x_i - x_j|`` from the start positions (many-body shrinkage).

    With the mechanics (necks on the half pair list) the contacts are the pairs whose spheres overlap, and the
    shrinkage is measured from the start positions.

    Returns ``{"mean_neck_ratio", "max_neck_ratio", "shrinkage"}`` (scalars; 0 without contacts).
    """
    if _on_pairs(state):
        g, ratio = _pair_ratio(state)
        x0, x = state.sintering.start_positions, state.particles.positions
        distance = lambda y: jnp.linalg.norm(jnp.where(g.touching[:, None], y[g.j] - y[g.i], 1.0), axis=-1)  # noqa: E731
        radii = state.particles.radii
        count = jnp.sum(g.touching.astype(radii.dtype))
        per = lambda v: jnp.sum(jnp.where(g.touching, v, 0.0)) / jnp.maximum(count, 1.0)  # noqa: E731
        return {"mean_neck_ratio": per(ratio), "max_neck_ratio": jnp.max(jnp.where(g.touching, ratio, 0.0), initial=0.0),
                "shrinkage": per((distance(x0) - distance(x)) / (radii[g.i] + radii[g.j]))}
    contacts, radii = state.contacts, state.particles.radii
    lo, hi = contacts.pairs[:, 0], contacts.pairs[:, 1]
    r_lo, r_hi = radii[lo], radii[hi]
    per = lambda x: jnp.sum(x) / jnp.maximum(x.shape[0], 1)  # noqa: E731
    ratio = contacts.neck / jnp.minimum(r_lo, r_hi)
    if state.sintering.start_positions is None:
        approach = contacts.overlap - state.sintering.start_overlap
    else:
        distance = lambda x: jnp.linalg.norm(x[hi] - x[lo], axis=-1)  # noqa: E731
        approach = distance(state.sintering.start_positions) - distance(state.particles.positions)
    return {"mean_neck_ratio": per(ratio), "max_neck_ratio": jnp.max(ratio, initial=0.0),
            "shrinkage": per(approach / (r_lo + r_hi))}


def particle_neck_ratio(state):
    """``[n]`` each particle's mean neck ratio ``a / min(r_i, r_j)`` over its contacts (0 without contacts)."""
    if _on_pairs(state):
        g, ratio = _pair_ratio(state)
        n = state.particles.radii.shape[0]
        pairs = jnp.where(g.touching[:, None], g.pairs, n)
        count = pair_sum(*(2 * [g.touching.astype(ratio.dtype)]), pairs, n)
        return pair_sum(ratio, ratio, pairs, n) / jnp.maximum(count, 1.0)
    contacts, radii = state.contacts, state.particles.radii
    pairs, n = contacts.pairs, radii.shape[0]
    ratio = contacts.neck / jnp.minimum(radii[pairs[:, 0]], radii[pairs[:, 1]])
    count = pair_sum(*(2 * [jnp.ones(ratio.shape, ratio.dtype)]), pairs, n)
    return pair_sum(ratio, ratio, pairs, n) / jnp.maximum(count, 1.0)


def _on_pairs(state) -> bool:
    """Whether the state's necks live on its half pair list (sintering with the mechanics)."""
    return state.mechanics is not None and state.mechanics.neck is not None


def _pair_ratio(state):
    """``(geometry, ratio)``: the pair geometry of a state with the mechanics and each pair's ``a / min(r_i, r_j)``."""
    p = state.particles
    g = pair_geometry(p.positions, p.radii, state.contacts.pairs.pairs, POINT_CONTACT_GAP)
    return g, jnp.where(g.touching, state.mechanics.neck / jnp.minimum(p.radii[g.i], p.radii[g.j]), 0.0)


def necks_at_cap(spec: Sintering, params, contacts: LiftedContacts, radii) -> LiftedContacts:
    """``contacts`` with every neck at the kinetic law's cap (and its approach ``H``): the largest conductances
    the run can reach, for its time step."""
    merged = law_params(spec, params)
    radii = jnp.asarray(radii)
    r_lo, r_hi = radii[contacts.pairs[:, 0]], radii[contacts.pairs[:, 1]]
    cap = jnp.minimum(sintering.kinetic_law(spec.law).cap(r_lo, r_hi, merged), jnp.minimum(r_lo, r_hi))
    neck = jnp.maximum(cap, contacts.neck)
    return dataclasses.replace(contacts, neck=neck, overlap=sintering.neck_overlap(neck, r_lo, r_hi))


def pair_necks_at_cap(spec: Sintering, params, motion: MechanicalState, contacts: DynamicContacts, positions, radii
                      ) -> MechanicalState:
    """``motion`` with the neck of every touching pair of the half pair list (:data:`POINT_CONTACT_GAP`) at the
    kinetic law's cap (and its approach ``H``): :func:`necks_at_cap` for sintering with the mechanics."""
    merged = law_params(spec, params)
    radii = jnp.asarray(radii)
    g = pair_geometry(jnp.asarray(positions, radii.dtype), radii, contacts.pairs.pairs, POINT_CONTACT_GAP)
    r_i, r_j = radii[g.i], radii[g.j]
    cap = jnp.minimum(sintering.kinetic_law(spec.law).cap(r_i, r_j, merged), jnp.minimum(r_i, r_j))
    neck = jnp.where(g.touching, jnp.maximum(cap, motion.neck), 0.0)
    return dataclasses.replace(motion, neck=neck,
                               neck_overlap=jnp.where(g.touching, sintering.neck_overlap(neck, r_i, r_j), 0.0))


def check_stable(state) -> None:
    """Refuse (``FloatingPointError``) a state whose grown necks made its time step unstable, or whose many-body
    balance fell short of its tolerance."""
    if state.sintering is None:
        return
    if state.sintering.unbalanced is not None and bool(state.sintering.unbalanced):
        raise FloatingPointError(
            f"the many-body sintering balance did not converge by step {int(state.step)} (its conjugate-gradient "
            "residual stayed above Sintering.balance_tol): loosen balance_tol or check the packing for contacts "
            "that hold nothing in place")
    if bool(state.sintering.unstable):
        raise FloatingPointError(
            f"the necks grew so that the time step {float(state.dt):.4g} s exceeds the explicit stability limit "
            f"by step {int(state.step)}; start from a smaller dt (simulate.thermal_time_step on the necks you "
            "expect at the end, e.g. at the kinetic law's cap)")


def update_interval(spec: Sintering, step, carried: NeckState) -> jax.Array:
    """Whether the step numbered ``step`` (after it was taken) ends a growth interval: every ``spec.every`` steps,
    or with ``spec.neck_rtol`` after ``carried.interval_length`` steps."""
    if spec.neck_rtol is None:
        return step % spec.every == 0
    return step - carried.interval_start >= carried.interval_length


def next_interval_length(spec: Sintering, carried: NeckState, step, start_neck, neck, active) -> jax.Array:
    """The steps of the next growth interval (``Sintering.neck_rtol``; ``carried.interval_length`` without it).

    The interval just ended (``step - carried.interval_start`` steps) grew each neck from ``start_neck`` to
    ``neck`` ``[c]`` (m); its largest relative growth ``g = max (a - a_start) / a`` over the ``active`` necks sets
    the next one: ``floor(length neck_rtol / g)``, clipped to ``[1, min(2 length, every)]`` (doubled at most, so a
    neck that starts to grow after a quiet spell is caught within a few updates)."""
    if spec.neck_rtol is None:
        return carried.interval_length
    steps = carried.interval_length.dtype
    length = (step - carried.interval_start).astype(steps)
    growth = jnp.where(active & (neck > 0), (neck - start_neck) / jnp.where(neck > 0, neck, 1.0), 0.0)
    largest = jnp.max(growth, initial=0.0)
    scaled = length.astype(neck.dtype) * spec.neck_rtol / jnp.where(largest > 0, largest, 1.0)
    longest = jnp.minimum(2 * length, jnp.asarray(spec.every, steps))
    proposed = jnp.where(largest > 0, jnp.floor(jnp.minimum(scaled, longest.astype(neck.dtype))).astype(steps),
                         longest)
    return jnp.clip(proposed, jnp.asarray(1, steps), longest)


__all__ = ["BLOCK_FLOOR", "Grown", "NECK_STARTS", "NeckState", "POINT_CONTACT_GAP", "RAYLEIGH_FLOOR", "RECENT_BALANCES",
           "RECENT_MISMATCH",
           "SHRINKAGE_MODES", "STIFF_CONTACT_RATIO", "Sintering", "balance_blocks", "balance_displacements",
           "check_stable", "check_table", "conjugate_gradients", "grow_necks", "law_params", "met_necks",
           "neck_state", "neck_statistics", "necks_at_cap", "pair_necks", "pair_necks_at_cap", "particle_neck_ratio",
           "pushed", "recent_start", "validate_pair_necks", "validate_sintering", "with_displacement",
           "with_pair_necks"]
