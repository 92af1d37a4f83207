"""Necks that grow in the simulator: the sintering sub-spec of :class:`sintercond.simulate.Physics`, its state and
its update.

First stage (SINTERING.md section 3 of the design notes; docs/simulator.md): the packing does not move and each
contact sinters on its own. The neck radius ``a`` of every contact is state; every ``Sintering.every`` thermal steps
it grows by the kinetic law of :mod:`sintercond.sintering` over those steps' duration, and the contact's approach
follows it through Rojek et al. (2022)'s volume-conserving geometry, ``h = H(a)`` (Eqs. 23-27;
:func:`sintercond.sintering.neck_overlap`). The conductance law is applied to the grown neck at every step
(``Conduction(conductance="lifted")``), so the pipe network stiffens as the necks grow, and the parameters of both
laws stay differentiable.

The temperature of a growth interval
------------------------------------
A neck update covers the ``every`` steps since the last one. The pair temperature of the interval is the mean of the
pair temperature (:func:`sintercond.sintering.pair_temperature`, the mean of the two particles) at its start and at
its end, and the neck grows over the interval at that constant temperature, integrated exactly by
:func:`sintercond.sintering.grow_neck`. The trapezoid makes the error second order in the interval for a smooth
temperature history (``benchmarks/sintering_step.py`` measures it against ``every``).

Shrinkage
---------
Positions are fixed in the first stage, so the shrinkage is what the contacts' approaches would give: the mean
over contacts of ``(H(a) - h_0) / (r_i + r_j)``, ``h_0`` the approach at the start of the run
(:func:`neck_statistics`). It is the linear shrinkage of a chain of such contacts.

Stability
---------
Growing necks raise the conductances, and with them lower the explicit step's limit
(:func:`sintercond.thermal.explicit_stability_limit`). Every neck update checks ``dt <= C_i / sum_j K_ij`` on the
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
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import sintering
from sintercond._validation import all_concrete, require_law_params
from sintercond.state import LiftedContacts, pytree_dataclass


@dataclasses.dataclass(frozen=True)
class Sintering:
    """The sintering sub-spec of :class:`sintercond.simulate.Physics`: necks that grow with the temperature history.

    Attributes:
      law: a key of :data:`sintercond.sintering.KINETIC_LAWS` (``"grain_boundary"``, ``"power_law"``,
        ``"viscous"``); its parameters are ``Params.sintering``.
      every: thermal steps between two neck updates (>= 1); each update grows the necks over those steps.
      quadrature_nodes, newton_iterations: of :func:`sintercond.sintering.grow_neck` (>= 1). An update
        interval grows a neck by a small fraction of itself, so fewer than the law tier's defaults (8, 4)
        reach round-off: 4 and 2 agree with them to 1e-12 on the pulsed chain of ``benchmarks/sintering_step.py``
        (its table gives the error of each choice).
    """

    law: str = "grain_boundary"
    every: int = 1
    quadrature_nodes: int = 4
    newton_iterations: int = 2

    def __post_init__(self):
        if self.law not in sintering.KINETIC_LAWS:
            raise ValueError(f"Sintering.law must be one of {sorted(sintering.KINETIC_LAWS)}; got {self.law!r}")
        for name in ("every", "quadrature_nodes", "newton_iterations"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                raise ValueError(f"Sintering.{name} must be an integer >= 1; got {value!r}")


@pytree_dataclass
class NeckState:
    """What the sintering step carries besides the necks (which live in the contacts' table, both rows of a pair).

    Each contact is grown once, on its pair ``(i, j)``, ``i < j``, and its neck gathered back to the two slots of
    the table that hold it.

    Attributes:
      start_overlap: ``[n, m]`` the approach of each contact at the start of the run (m), for the shrinkage.
      interval_temperature: ``[n]`` particle temperatures at the last neck update (K): the start of the
        current growth interval.
      unstable: bool scalar, set when grown necks made the time step exceed the explicit limit.
      interval_start: int scalar, the step the current growth interval started at.
      pairs: ``[c, 2]`` int32 the contacts ``(i, j)``, ``i < j``.
      pair_slot: ``[c]`` int32 the flat index of each pair's slot in row ``i`` of the table.
      slot_pair: ``[n, m]`` int32 the pair each slot of the table holds; ``c`` in padding.
    """

    start_overlap: Any
    interval_temperature: Any
    unstable: Any
    interval_start: Any
    pairs: Any
    pair_slot: Any
    slot_pair: Any


def neck_state(contacts: LiftedContacts, temperature, step=0) -> NeckState:
    """The :class:`NeckState` at the start of a run on ``contacts`` with particle ``temperature`` ``[n]`` (K), at
    ``step`` (the state's, :func:`sintercond.simulate.init_state`). The table must list each contact in both its
    rows (as :func:`sintercond.simulate.lifted_contacts` does)."""
    neighbors = np.asarray(contacts.neighbors)
    n, m = neighbors.shape
    rows = np.broadcast_to(np.arange(n)[:, None], (n, m))
    valid = (neighbors != rows) & (neighbors < n)
    lower = valid & (rows < neighbors)
    pairs = np.stack([rows[lower], neighbors[lower]], axis=1)  # row-major: sorted by (i, j)
    slot_pair = np.full((n, m), len(pairs), np.int64)
    slot_pair[lower] = np.arange(len(pairs))
    # the upper slots: pair (j, i) seen from row i > j, found by its rank among the sorted pairs
    upper = valid & (rows > neighbors)
    keys = pairs[:, 0].astype(np.int64) * n + pairs[:, 1]
    wanted = neighbors[upper].astype(np.int64) * n + rows[upper]
    found = np.minimum(np.searchsorted(keys, wanted), max(len(keys) - 1, 0))
    if len(wanted) != len(keys) or (len(wanted) and np.any(keys[found] != wanted)):
        raise ValueError("the contact table lists a contact in one of its rows only; each contact (i, j) must be in "
                         "row i and row j (simulate.lifted_contacts builds such tables)")
    slot_pair[upper] = found
    step_type = jnp.int64 if jax.config.jax_enable_x64 else jnp.int32  # as SimState.step
    return NeckState(start_overlap=jnp.asarray(contacts.overlap), interval_temperature=jnp.asarray(temperature),
                     unstable=jnp.zeros((), bool), interval_start=jnp.asarray(step, step_type),
                     pairs=jnp.asarray(pairs, jnp.int32),
                     pair_slot=jnp.asarray(np.flatnonzero(lower), jnp.int32),
                     slot_pair=jnp.asarray(slot_pair, jnp.int32))


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


def validate_sintering(spec: Sintering, params, contacts: LiftedContacts, radii) -> None:
    """Raise ``ValueError`` naming the field unless the necks and the kinetic parameters can grow (concrete values).

    Parameters as :func:`sintercond.sintering.validate_growth_inputs` wants them; every neck in
    ``[0, min(r_i, r_j)]`` of its pair.
    """
    merged = law_params(spec, params)
    if not all_concrete(merged, contacts.neck, radii):
        return
    law = sintering.kinetic_law(spec.law)
    require_law_params("Params.sintering", law, merged,
                       lambda name: f"Params.sintering[{name!r}] of kinetic law {law.name!r} ({law.units[name]})")
    if "dihedral_angle" in merged and not float(np.max(merged["dihedral_angle"])) <= 180.0:
        raise ValueError(f"Params.sintering['dihedral_angle'] must be in (0, 180] degrees; got "
                         f"{merged['dihedral_angle']!r}")
    neighbors, neck, r = np.asarray(contacts.neighbors), np.asarray(contacts.neck, np.float64), np.asarray(radii)
    n = r.shape[0]
    rows = np.arange(n)[:, None]
    valid = (neighbors != rows) & (neighbors < n)
    limit = np.minimum(r[:, None], r[np.minimum(neighbors, n - 1)])
    bad = valid & ~((neck >= 0) & (neck <= limit * (1 + 1e-12)))
    if bad.any():
        i, k = map(int, np.argwhere(bad)[0])
        raise ValueError(f"contact necks must lie in [0, min(r_i, r_j)]; the neck of particles {i} and "
                         f"{int(neighbors[i, k])} is {neck[i, k]!r} m")


def _pairs(neighbors, n):
    """``(lo, hi, valid)`` of every slot of a padded table: the pair in index order, and whether it is a contact."""
    rows = jnp.arange(n, dtype=neighbors.dtype)[:, None]
    valid = (neighbors != rows) & (neighbors < n)
    j = jnp.where(valid, neighbors, rows)
    return jnp.minimum(rows, j), jnp.maximum(rows, j), valid


def grow_table_necks(spec: Sintering, params: dict, carried: NeckState, neck, radii, end_temperature, duration):
    """Necks and approaches ``[n, m]`` (m) of a padded table after one growth interval of ``duration`` (s).

    The pair temperature is the mean of its value at the start (``carried.interval_temperature``, K) and at the
    end (``end_temperature`` ``[n]``) of the interval (module docstring). Each contact grows once, on its pair,
    and both slots of the table take its neck: the conductances stay exactly symmetric, heat is conserved.
    Padding slots stay 0.
    """
    i, j = carried.pairs[:, 0], carried.pairs[:, 1]
    r_i, r_j = radii[i], radii[j]
    start = carried.interval_temperature
    temperature = 0.5 * (sintering.pair_temperature(start[i], start[j])
                         + sintering.pair_temperature(end_temperature[i], end_temperature[j]))
    dtype = neck.dtype
    a = sintering._grow_neck(sintering.kinetic_law(spec.law), neck.reshape(-1)[carried.pair_slot], r_i, r_j,
                             temperature[None], jnp.reshape(jnp.asarray(duration, dtype), (1,)), params,
                             spec.quadrature_nodes, spec.newton_iterations)[0]
    h = sintering.neck_overlap(a, r_i, r_j)
    padded = lambda x: jnp.concatenate([x, jnp.zeros((1,), x.dtype)])[carried.slot_pair]  # noqa: E731
    return padded(a), padded(h)


def neck_statistics(state) -> dict:
    """Mean and largest neck ratio ``a / min(r_i, r_j)`` over the contacts, and the mean linear shrinkage
    ``(H(a) - h_0) / (r_i + r_j)`` (module docstring) of a :class:`sintercond.simulate.SimState` with sintering.

    Returns ``{"mean_neck_ratio", "max_neck_ratio", "shrinkage"}`` (scalars; 0 without contacts).
    """
    contacts, radii = state.contacts, state.particles.radii
    lo, hi, valid = _pairs(contacts.neighbors, radii.shape[0])
    r_lo, r_hi = radii[lo], radii[hi]
    count = jnp.sum(valid.astype(radii.dtype))
    per = lambda x: jnp.sum(jnp.where(valid, x, 0.0)) / jnp.maximum(count, 1.0)  # noqa: E731
    ratio = contacts.neck / jnp.minimum(r_lo, r_hi)
    approach = contacts.overlap - state.sintering.start_overlap
    return {"mean_neck_ratio": per(ratio), "max_neck_ratio": jnp.max(jnp.where(valid, ratio, 0.0), initial=0.0),
            "shrinkage": per(approach / (r_lo + r_hi))}


def particle_neck_ratio(state):
    """``[n]`` each particle's mean neck ratio ``a / min(r_i, r_j)`` over its contacts (0 without contacts)."""
    contacts, radii = state.contacts, state.particles.radii
    lo, hi, valid = _pairs(contacts.neighbors, radii.shape[0])
    ratio = jnp.where(valid, contacts.neck / jnp.minimum(radii[lo], radii[hi]), 0.0)
    count = jnp.sum(valid.astype(radii.dtype), axis=1)
    return jnp.sum(ratio, axis=1) / jnp.maximum(count, 1.0)


def necks_at_cap(spec: Sintering, params, contacts: LiftedContacts, radii) -> LiftedContacts:
    """``contacts`` with every neck at the kinetic law's cap (and its approach ``H``): the largest conductances
    the run can reach, for its time step."""
    merged = law_params(spec, params)
    radii = jnp.asarray(radii)
    lo, hi, valid = _pairs(contacts.neighbors, radii.shape[0])
    r_lo, r_hi = radii[lo], radii[hi]
    cap = jnp.minimum(sintering.kinetic_law(spec.law).cap(r_lo, r_hi, merged), jnp.minimum(r_lo, r_hi))
    neck = jnp.where(valid, jnp.maximum(cap, contacts.neck), 0.0)
    return dataclasses.replace(contacts, neck=neck, overlap=jnp.where(valid, sintering.neck_overlap(neck, r_lo, r_hi),
                                                                      0.0))


def check_stable(state) -> None:
    """Refuse (``FloatingPointError``) a state whose grown necks made its time step unstable."""
    if state.sintering is not None and bool(state.sintering.unstable):
        raise FloatingPointError(
            f"the necks grew so that the time step {float(state.dt):.4g} s exceeds the explicit stability limit "
            f"by step {int(state.step)}; start from a smaller dt (simulate.thermal_time_step on the necks you "
            "expect at the end, e.g. at the kinetic law's cap)")


def update_interval(spec: Sintering, step) -> jax.Array:
    """Whether the step numbered ``step`` (after it was taken) ends a growth interval."""
    return step % spec.every == 0


__all__ = ["NeckState", "Sintering", "check_stable", "grow_table_necks", "law_params", "neck_state",
           "neck_statistics", "necks_at_cap", "particle_neck_ratio", "validate_sintering"]
