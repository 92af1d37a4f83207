"""One simulator: a static physics spec, differentiable ``Params``, one step, one rollout.

The public face of :mod:`sintercond.sim`, where the pieces live (``sim/physics.py``, ``sim/state.py``,
``sim/contacts.py``, ``sim/terms/``, ``sim/step.py``, ``sim/rollout.py``); import them from here.

Every stepping path of the package (``sintercond run``, settling, the
softening fits, prescribed motion, the benchmarks) goes through here; the
flash experiment's readings do too, while its gradient is a hand-written
discrete adjoint over :func:`sintercond.sim.thermal.explicit_update`
(:mod:`fitting.inverse`), tested against reverse mode through :func:`rollout`:

* :class:`Physics` is a frozen, hashable description of *what* is simulated
  (conduction law and neck model, static or dynamic contacts, integrator,
  heat sources, held particles and conducting walls, and room for mechanics).
  :func:`simulator` composes the physics terms that are on (one module each in
  :mod:`sintercond.sim.terms`), so what a scene does not use is not traced,
  and each distinct spec compiles one step (jax-md ``simulate.nve``'s
  ``(init_fn, apply_fn)`` pattern).
* :class:`Params` is the one differentiable input: conductivities and
  specific heats per material, the conductance law's parameters, and the
  source parameters. ``step_fn(state, params)`` takes it as an argument, so
  one compiled step serves every optimiser iteration, and gradients of any
  observable reach any of its leaves by JAX's own reverse or forward mode.
* :class:`SimState` is the whole state (particles, contacts, step counter and
  time step) as registered frozen dataclasses; a checkpoint holds all of it.
* :func:`simulate_table` advances a table network built once
  (:func:`sintercond.contacts.network.contact_table`) without building a state by
  hand: a convenience over :func:`rollout`.
* :func:`rollout` scans the step over ``jax.checkpoint``-ed segments of about
  ``sqrt(n_steps)`` steps and saves observables chosen by :class:`SaveAt`
  (probe temperatures, means, heat flows), not whole states: reverse mode
  then keeps ``O(sqrt(n_steps))`` particle arrays.

The conduction step itself (Rojek et al. 2022, Eqs. 1-4; sources of
Quintana-Ruiz & Campello 2020, Eqs. 28-31, 37-41) is
:func:`sintercond.sim.thermal.explicit_update` (or the backward-Euler solve),
with the heat powers of :func:`sintercond.sim.thermal.heat_power`.

Conductances of contacts
------------------------
``conductance="table"``: a table of ``K_ij`` at unit conductivity, built once
on the host (:func:`sintercond.contacts.network.contact_table`), times the
conductivity of the single material. Every law is linear in the
conductivity when there is one material and no contact resistance, so this
is exact; it is the fast path (the gradient with respect to the conductivity
is a scalar reduction per step).

``conductance="lifted"``: the necks of every pair are computed once from the
geometry; the law turns them into conductances from ``params`` at the start
of every rollout (:func:`conductance_lift`), so law parameters (Rojek's
slope, a contact resistance, the fitted law's coefficients) and per-material
conductivities are differentiable. Both give the same numbers and gradients
where both apply (tests/test_simulate.py).

``contacts="dynamic"``: positions move (a prescribed ``motion(t)``, or the
thermo-mechanical step); a Dense neighbour list with a skin (built from a
sorted cell list, jax-md's Dense format; :func:`sintercond.contacts.neighbors.neighbor_list`) is updated
inside the step, and whenever it is rebuilt a half pair list (each pair
``i < j`` once, within ``r_i + r_j + skin``;
:class:`sintercond.contacts.pair_list.HalfPairs`) is rebuilt from it. The law is
evaluated once per pair of the half list from the current overlaps at every
step, and heat (and force) is added to one end and taken from the other
(:func:`sintercond.contacts.pair_list.pair_exchange`): conserved by construction.
Overflow of either list is a flag in the state, recovered by the host
driver (:func:`sintercond.rollout.advance` with :func:`reallocate_neighbors`).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from sintercond._deprecation import old_names
from sintercond._validation import all_concrete, require_positive
from sintercond.sim.mechanics import MechanicalParams, MechanicalState, Mechanics  # noqa: F401
from sintercond.sim.neck_growth import NeckState, Sintering  # noqa: F401
from sintercond.contacts.network import ContactTable
from sintercond.sim.contacts import (affine_shrinkage, conducting_geometry, conductance_lift,  # noqa: F401
                                     conductivity_lookup, coupled_contacts, dynamic_contacts, follow_contacts,
                                     lifted_contacts,
                                     lifted_pair_conductance, list_region, merged_law_params, neck_conductance,
                                     pair_conductance, pair_heat_flow, pair_heat_power, pair_neck_conductance,
                                     particle_conductivity, reallocate_neighbors, sintered_geometry,
                                     sintered_pair_conductance, sintered_pair_network, table_contacts)
from sintercond.sim.physics import Conduction, Physics, Sources
from sintercond.sim.rollout import (Observable, SaveAt, mean_temperature, probe_temperatures, rollout,  # noqa: F401
                                    segment_length)
from sintercond.sim.stability import thermal_time_step  # noqa: F401
from sintercond.sim.state import (BeamParams, ConvectionParams, HeldRampParams, Params, Prepared,  # noqa: F401
                                  PulseParams, RadiationParams, SimState, Simulator, held_ramp_temperature, init_state,
                                  params_in_precision)
from sintercond.sim.step import simulator
from sintercond.sim.terms.conduction import particle_capacity  # noqa: F401
from sintercond.sim.terms.mechanics import contact_forces, resultant_forces  # noqa: F401
from sintercond.sim.terms.walls import mechanical_wall_conductance  # noqa: F401
from sintercond.sim.validation import (FLOAT32_OVERLAP_STEPS, MAX_INITIAL_OVERLAP, PrecisionWarning,  # noqa: F401
                                       validate_inputs)
from sintercond.state import (Contacts, DynamicContacts, LiftedContacts, ParticleState, TableContacts,  # noqa: F401
                              heat_capacity, pytree_dataclass)


@dataclasses.dataclass(frozen=True)
class _TemperatureSource:
    """Adapts a ``source(temperature, t)`` callable to the simulator's ``fn(state, t, params)``."""

    source: object

    def __call__(self, state, t, params):
        return self.source(state.particles.temperature, t)


def simulate_table(temperature, table: ContactTable, capacity, dt, n_steps, save_every=1, fixed_mask=None,
                   fixed_temperature=None, *, method="explicit", source=None, start_step=0, probes=None):
    """Advance a table network ``n_steps`` steps; returns ``(final, saved [n_steps // save_every, n])``.

    A convenience over :func:`rollout` for a network
    already built at its conductivity: ``method`` ``"explicit"`` (check
    ``dt <= thermal.table_time_step`` first) or ``"implicit"`` (backward Euler, any
    ``dt``; conduction only). ``source(temperature, t)``: heat powers (W), a
    hashable callable (explicit only), called with the time
    ``(start_step + k) dt`` of step ``k``. ``probes``: indices of the
    particles to save (``saved`` is then ``[.., len(probes)]``); None saves
    all. ``n_steps`` must be a multiple of ``save_every``.
    """
    if method not in ("explicit", "implicit"):
        raise ValueError(f"method must be 'explicit' or 'implicit'; got {method!r}")
    if not (isinstance(n_steps, int) and isinstance(save_every, int) and n_steps >= 1 and save_every >= 1):
        raise ValueError(f"n_steps and save_every must be integers >= 1; got {n_steps!r}, {save_every!r}")
    if n_steps % save_every:
        raise ValueError(f"n_steps ({n_steps}) must be a multiple of save_every ({save_every})")
    for name, value in (("dt (s)", dt), ("capacity (J/K)", capacity)):
        if all_concrete(value):
            require_positive(name, np.atleast_1d(np.asarray(value, np.float64)))
    return _simulate_table(temperature, table, capacity, dt, n_steps, save_every, fixed_mask, fixed_temperature,
                           method=method, source=source, start_step=start_step, probes=probes)


@functools.partial(jax.jit, static_argnames=("n_steps", "save_every", "method", "source"))
def _simulate_table(temperature, table, capacity, dt, n_steps, save_every, fixed_mask, fixed_temperature, *, method,
                    source, start_step, probes):
    if method == "implicit" and source is not None:
        raise ValueError("source terms need method='explicit'")
    walls = table.wall_conductance is not None
    physics = Physics(conduction=Conduction(conductance="table", integrator=method, held=fixed_mask is not None,
                                            conducting_walls=int(walls)),
                      sources=Sources(source=None if source is None else _TemperatureSource(source)))
    n = temperature.shape[0]
    capacity = jnp.broadcast_to(jnp.asarray(capacity, temperature.dtype), (n,))
    fixed = jnp.zeros(n, bool) if fixed_mask is None else jnp.broadcast_to(fixed_mask, (n,))
    held = temperature if fixed_temperature is None else jnp.broadcast_to(
        jnp.asarray(fixed_temperature, temperature.dtype), (n,))
    particles = ParticleState(positions=jnp.zeros((n, 3), temperature.dtype), radii=jnp.ones(n, temperature.dtype),
                              temperature=temperature, mass=capacity, material=jnp.zeros(n, jnp.int32), fixed=fixed,
                              fixed_temperature=held)
    contacts = table_contacts(table, table.wall_conductance, table.wall_temperature)
    state = init_state(particles, contacts, dt, start_step)
    params = Params(conductivity=jnp.ones(1, temperature.dtype), specific_heat=jnp.ones(1, temperature.dtype))
    saveat = SaveAt(save_every, None if probes is None else probe_temperatures(probes))
    sim = simulator(physics)
    final, saved = rollout(sim, state, params, n_steps, saveat)
    return final.particles.temperature, saved


# Old names, kept for one release: each time-step function has its own name (issue 24).
__getattr__ = old_names("sintercond.simulate", {
    "stable_time_step": ("sintercond.simulate", "thermal_time_step"),
})
