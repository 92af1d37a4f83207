"""The state of a simulation and its differentiable inputs: :class:`SimState`, :class:`Params` (with the source
parameters) and what a rollout computes once from them (:class:`Prepared`).

:class:`Params` is the one differentiable input: conductivities and specific heats per material, the conductance
law's parameters, the sources', the contact material's and the kinetic law's. ``step_fn(state, params)`` takes it as
an argument, so one compiled step serves every optimiser iteration, and gradients of any observable reach any of its
leaves by JAX's own reverse or forward mode. :class:`SimState` is the whole state (particles, contacts, step counter
and time step, mechanics, necks) as registered frozen dataclasses; a checkpoint holds all of it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from sintercond.sim.mechanics import MechanicalParams, MechanicalState
from sintercond.sim.neck_growth import NeckState
from sintercond.sim.physics import Physics
from sintercond.state import Contacts, ParticleState, pytree_dataclass
from sintercond.laws.tortuosity import preheating_temperature


@pytree_dataclass
class BeamParams:
    """A vertical beam moving along a polyline (Quintana-Ruiz & Campello 2020, Eqs. 29-31).

    Attributes:
      intensity: ``I0`` (W/m^2).
      reach: Lambert-Beer attenuation ``mu`` (1/m) for a laser, ``d_max`` (m) for a nozzle.
      spot_radius: beam radius (m).
      absorptance: ``a`` in [0, 1].
      speed: speed along the path (m/s).
      path: ``[k, 2]`` waypoints (x, y) (m), absolute coordinates.
      segments_on: ``[k - 1]`` 1 where the beam heats along a segment, 0 where it jumps (None: always on).
      after_path: 0 (the beam is off once its path is done) or 1 (it stays on at the last waypoint).
    """

    intensity: Any
    reach: Any
    spot_radius: Any
    absorptance: Any
    speed: Any
    path: Any
    segments_on: Any = None
    after_path: Any = 0.0


@pytree_dataclass
class ConvectionParams:
    """Newton cooling (Eqs. 37-39): environment temperature (K), conductivity (W/(m K)), Nusselt number."""

    environment_temperature: Any
    environment_conductivity: Any
    nusselt: Any


@pytree_dataclass
class RadiationParams:
    """Stefan-Boltzmann exchange (Eq. 41): environment temperature (K) and emissivity."""

    environment_temperature: Any
    emissivity: Any


@pytree_dataclass
class PulseParams:
    """A prescribed heat input: ``power`` ``[n]`` (W) while ``t < duration`` (s)."""

    power: Any
    duration: Any


@pytree_dataclass
class HeldRampParams:
    """A stepped temperature ramp of the held particles (Rizza & Galati 2024, Eq. 6, with its erratum).

    Each held particle rises from its ``fixed_temperature`` ``T_0`` to ``end_temperature`` in ``steps`` equal
    steps of ``duration / steps``, each step held at the temperature it ends at (the reading that reproduces their
    Table 1): ``T(t) = T_0 + (T_end - T_0) min(ceil(steps t / duration), steps) / steps`` (K, t in s). ``steps`` is
    a float holding a whole number; the ramp's ``duration`` and ``steps`` have zero gradient (a staircase).
    """

    end_temperature: Any
    duration: Any
    steps: Any


def held_ramp_temperature(ramp: HeldRampParams, start, t):
    """The held temperatures ``[n]`` (K) at time ``t`` (s) of a :class:`HeldRampParams` from ``start`` ``[n]``:
    the level of :func:`sintercond.laws.tortuosity.preheating_temperature` (its reading at the step's end)."""
    level = preheating_temperature(t, 0.0, ramp.duration, 0.0, 1.0, ramp.steps, at_step_end=True)
    return start + (ramp.end_temperature - start) * level


@pytree_dataclass
class Params:
    """The differentiable inputs of a simulation (SI units).

    Attributes:
      conductivity: ``[n_materials]`` solid conductivities (W/(m K)).
      specific_heat: ``[n_materials]`` (J/(kg K)); capacities are ``m_i c``.
      law: the conductance law's parameters in use (e.g. ``{"slope": 1.064}``),
        merged over the law's defaults; ``{}`` for the defaults.
      beam, convection, radiation, pulse: source parameters, or None where
        the physics has no such source.
      mechanics: :class:`sintercond.sim.mechanics.MechanicalParams` (moduli,
        damping, friction, softening) with ``Physics.mechanics``, else None.
      sintering: the kinetic law's parameters in use (e.g. ``{"A": 1e-17, "activation_energy": 40.0}``),
        merged over the law's defaults (:data:`sintercond.laws.sintering.KINETIC_LAWS`), with
        ``Physics.sintering``; else None.
      held_ramp: :class:`HeldRampParams` with ``Conduction.held_ramp``, else None.
    """

    conductivity: Any
    specific_heat: Any
    law: dict = dataclasses.field(default_factory=dict)
    beam: BeamParams | None = None
    convection: ConvectionParams | None = None
    radiation: RadiationParams | None = None
    pulse: PulseParams | None = None
    mechanics: MechanicalParams | None = None
    sintering: dict | None = None
    held_ramp: HeldRampParams | None = None


@pytree_dataclass
class SimState:
    """The whole state of a simulation.

    Attributes:
      particles: positions, radii, temperatures, masses, materials, held flags.
      contacts: the network, one class per mode (:data:`sintercond.state.Contacts`: :class:`TableContacts`,
        :class:`LiftedContacts` or :class:`DynamicContacts`).
      step: int scalar, steps taken (time ``step * dt``).
      dt: the time step (s), scalar.
      overflow: bool scalar, set when a dynamic neighbour list overflowed
        since the last host check (the results after it are invalid).
      mechanics: velocities, spins and contact springs
        (:class:`sintercond.sim.mechanics.MechanicalState`) with
        ``Physics.mechanics``, else None (nothing traced).
      sintering: the start approaches, the growth interval's start temperatures and the stability flag
        (:class:`sintercond.sim.neck_growth.NeckState`) with ``Physics.sintering``, else None; the necks
        themselves are ``contacts.neck``.
      adaptive_step: with ``Conduction.integrator="implicit"`` run by :func:`sintercond.sim.rollout.advance`, the
        step (s) the adaptive integrator tries first in the next output interval (0: none taken yet, the whole
        interval is tried), carried in the state so that a checkpoint resumes the run exactly; else None.
    """

    particles: ParticleState
    contacts: Contacts
    step: Any
    dt: Any
    overflow: Any
    mechanics: MechanicalState | None = None
    sintering: NeckState | None = None
    adaptive_step: Any = None

    @property
    def temperature(self):
        return self.particles.temperature

    @property
    def time(self):
        """``step * dt`` (s)."""
        return self.step.astype(self.dt.dtype) * self.dt


class Prepared(NamedTuple):
    """What one rollout computes once from ``(state, params)`` and every step reuses."""

    params: Params
    capacity: jax.Array
    conductance: jax.Array | None  # [n, m] static conductances (W/K), or None for dynamic contacts
    scale: jax.Array  # multiplies the table (the conductivity, table mode) or 1
    wall_conductance: jax.Array | None  # [n_walls or 1, n] (W/K)
    wall_temperature: jax.Array | None  # [n_walls or 1, n] broadcastable (K)
    rates: tuple | None = None  # thermal.conduction_rates(scale, capacity) of the static explicit step, or None
    neck_blocks: tuple | None = None  # coupling="sphere" on necks that stay: coupling.NeckNetwork


class Simulator(NamedTuple):
    """``step_fn(state, params) -> state``; ``prepare_fn``/``advance_fn`` split it for
    :func:`sintercond.sim.rollout.rollout`."""

    physics: Physics
    step_fn: Callable
    prepare_fn: Callable
    advance_fn: Callable
    heat_power_fn: Callable


# --------------------------------------------------------------------------
# conductances


def params_in_precision(params: Params, dtype) -> Params:
    """``params`` with every floating leaf (Python floats included) in ``dtype``, the state's float type, when that
    is narrower than float64: a float32 state with parameters written as Python floats would otherwise be promoted
    to float64 in the step (and refused by the scan that carries it). Float64 states take their parameters as
    given."""
    if jnp.dtype(dtype) == jnp.float64:
        return params

    def cast(leaf):
        floating = isinstance(leaf, float) or (hasattr(leaf, "dtype") and jnp.issubdtype(leaf.dtype, jnp.floating))
        return jnp.asarray(leaf, dtype) if floating else leaf

    return jax.tree_util.tree_map(cast, params)



def init_state(particles: ParticleState, contacts: Contacts, dt, step=0, mechanics=None, sintering=None,
               adaptive_step=None) -> SimState:
    """A :class:`SimState` at ``step`` (default 0) with time step ``dt`` (s).

    ``mechanics``: a :class:`sintercond.sim.mechanics.MechanicalState` for
    ``Physics.mechanics`` (:func:`sintercond.sim.mechanics.mechanical_state`).
    ``sintering``: a :class:`sintercond.sim.neck_growth.NeckState` for ``Physics.sintering``
    (:func:`sintercond.sim.neck_growth.neck_state`).
    ``adaptive_step``: ``SimState.adaptive_step`` (0.0 for an implicit run that resumes exactly), or None.
    """
    dtype = particles.temperature.dtype

    def scalar(value, kind):  # a Python number through NumPy: op by op, jnp.asarray(number, dtype) compiles
        return jnp.asarray(np.asarray(value, kind)) if isinstance(value, (int, float, np.number)) else (
            jnp.asarray(value, kind))

    return SimState(particles=particles, contacts=contacts,
                    step=scalar(step, jnp.int64 if jax.config.jax_enable_x64 else jnp.int32), dt=scalar(dt, dtype),
                    overflow=jnp.asarray(np.zeros((), bool)), mechanics=mechanics, sintering=sintering,
                    adaptive_step=None if adaptive_step is None else scalar(adaptive_step, dtype))
