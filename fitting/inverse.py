"""Inverse problems through the thermal DEM: recover the solid conductivity from probe temperatures.

The experiment is a flash measurement on a sintered packing (the DEM
counterpart of laser-flash analysis): a prescribed power heats the particles
on one face for a while, thermometers ("probes") on chosen particles record
the temperature every ``save_every`` steps, and the model is the explicit
pipe-network conduction of :mod:`sintercond.sim.thermal` (Rojek et al. 2022,
Eqs. 1-4):

    T_{n+1} = T_n + dt / (c m) * (kappa H(T_n) + q_n),    H(T) = heat inflow at kappa = 1 W/(m K),

on free particles; held particles stay held. Every conductance law in
:mod:`sintercond.laws.conductance` without a contact resistance is proportional to
``kappa`` (and Rojek's to ``s kappa``), so one network built at ``kappa = 1``
serves every ``kappa``; the fitted value is then ``kappa`` (or ``s kappa``:
the two are not separable from temperatures, only their product is).

Gradients of a loss on the probe histories with respect to ``kappa`` and the
specific heat ``c`` come from the discrete adjoint of the scan (exactly the
reverse-mode derivative of the explicit scheme, written out): the adjoint
runs backwards with the same symmetric network, ``lambda_n = mu - kappa L (a mu)``
with ``mu`` the adjoint masked on held particles and ``a = dt / (c m)``. States
are checkpointed every ``~sqrt(n_steps)`` steps and each segment is recomputed
once on the way back, so memory is ``O(sqrt(n_steps))`` particle-sized arrays
and the gradient sweeps the network three times per step (forward, recompute,
adjoint). Each sweep is one gather over the table; the adjoint carries
``a mu`` so that its gather reads one array, and the recompute writes ``H``
in place into one buffer shared by all segments (its cost against the forward:
benchmarks/RESULTS.md, ``inverse_gradient``; what was tried: docs/devlog/thermal_gradient.md).

Precision: float64 by default. Built in float32 (``SINTERCOND_ENABLE_X64=0``)
the readings of a 10 K flash at 300 K stay within 1e-3 K of float64 over
400 steps and the gradient within 1e-4 relative (tests/test_inverse.py).
:meth:`ProbeExperiment.temperatures` with ``gradient="autodiff"`` runs the
same model through :func:`sintercond.simulate.rollout` for JAX's own
differentiation (forward mode for Gauss-Newton Jacobians; reverse mode as
the reference the adjoint is tested against).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from fitting.core import Bounded, FitResult, least_squares
from sintercond.sim import thermal
from sintercond.contacts.network import ContactTable, contact_table, heat_inflow, laplacian, total_conductance
from sintercond.simulate import (Params, Physics, PulseParams, SaveAt, SimState, init_state, probe_temperatures,
                                 rollout, simulator, table_contacts)
from sintercond.state import ParticleState


@dataclasses.dataclass(frozen=True, eq=False)
class ProbeExperiment:
    """A transient conduction experiment on a static packing, observed at probe particles.

    Attributes:
      table: the network at ``kappa = 1 W/(m K)`` (conductances in W/K per W/(m K)).
      mass: ``[n]`` particle masses (kg); the capacity is ``c * mass``.
      initial: ``[n]`` initial temperatures (K).
      power: ``[n]`` heat input (W) while ``t < pulse_duration``.
      pulse_duration: length of the heat pulse (s).
      dt: time step (s).
      n_steps: steps simulated.
      save_every: steps between probe readings (``n_steps // save_every`` readings, the first after
        ``save_every`` steps).
      probes: ``[p]`` indices of the observed particles.
      fixed_mask, fixed_temperature: ``[n]`` held particles and their temperatures, or None.
    """

    table: ContactTable
    mass: jax.Array
    initial: jax.Array
    power: jax.Array
    pulse_duration: float
    dt: float
    n_steps: int
    save_every: int
    probes: jax.Array
    fixed_mask: jax.Array | None = None
    fixed_temperature: jax.Array | None = None

    def __post_init__(self):
        n = self.table.n_particles
        for name in ("mass", "initial", "power"):
            value = np.asarray(getattr(self, name))
            if value.shape != (n,) or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} must be a finite [{n}] array; got shape {value.shape}")
        if not np.all(np.asarray(self.mass) > 0):
            raise ValueError("mass must be > 0 kg for every particle")
        if not (self.dt > 0 and math.isfinite(self.dt)):
            raise ValueError(f"dt must be finite and > 0 s; got {self.dt!r}")
        if not (isinstance(self.n_steps, int) and isinstance(self.save_every, int)
                and 1 <= self.save_every <= self.n_steps):
            raise ValueError(f"n_steps and save_every must be integers with 1 <= save_every <= n_steps; got "
                             f"{self.n_steps!r}, {self.save_every!r}")
        probes = np.asarray(self.probes)
        if probes.ndim != 1 or probes.size == 0 or probes.min() < 0 or probes.max() >= n:
            raise ValueError(f"probes must be a non-empty 1-D array of particle indices in [0, {n}); got {probes}")
        physics = Physics.create(conductance="table", pulse=True, held=self.fixed_mask is not None,
                                 conducting_walls=int(self.table.wall_conductance is not None))
        object.__setattr__(self, "_sim", simulator(physics))
        total = np.asarray(total_conductance(self.table))
        limit = np.min(np.where(total > 0, np.asarray(self.mass) / (self.dt * np.where(total > 0, total, 1)), np.inf))
        object.__setattr__(self, "_max_ratio", float(limit))

    def max_diffusivity_ratio(self) -> float:
        """Largest ``kappa / c`` (W/(m K) per J/(kg K)) for which ``dt`` is a stable explicit step."""
        return self._max_ratio

    def temperatures(self, kappa, specific_heat, gradient="adjoint"):
        """Probe readings ``[n_steps // save_every, p]`` (K) for ``kappa`` (W/(m K)) and ``c`` (J/(kg K)).

        ``gradient="adjoint"``: reverse-mode derivatives by the checkpointed
        discrete adjoint (no forward mode). ``"autodiff"``: the same numbers
        from :func:`sintercond.simulate.rollout`, differentiable by JAX in
        both modes. Beyond the explicit stability limit
        (:meth:`max_diffusivity_ratio`) the readings are NaN (flagged, never a
        silently wrong history).
        """
        dtype = self.initial.dtype  # float64 by default; float32 when the experiment is built in float32
        kappa, specific_heat = jnp.asarray(kappa, dtype), jnp.asarray(specific_heat, dtype)
        if gradient == "adjoint":
            readings = _adjoint_readings(self, kappa, specific_heat)
        elif gradient == "autodiff":
            readings = self._simulate(kappa, specific_heat)
        else:
            raise ValueError(f"gradient must be 'adjoint' or 'autodiff'; got {gradient!r}")
        stable = kappa / specific_heat <= self.max_diffusivity_ratio() * (1 + 1e-12)
        return jnp.where(stable, readings, jnp.nan)

    def initial_state(self) -> SimState:
        """The experiment's initial :class:`~sintercond.simulate.SimState` (table at unit conductivity)."""
        n = self.table.n_particles
        initial = jnp.asarray(self.initial)
        fixed = jnp.zeros(n, bool) if self.fixed_mask is None else jnp.asarray(self.fixed_mask)
        held = initial if self.fixed_temperature is None else jnp.broadcast_to(
            jnp.asarray(self.fixed_temperature, initial.dtype), (n,))
        particles = ParticleState(positions=jnp.zeros((n, 3), initial.dtype), radii=jnp.ones(n, initial.dtype),
                                  temperature=initial, mass=jnp.asarray(self.mass),
                                  material=jnp.zeros(n, jnp.int32), fixed=fixed, fixed_temperature=held)
        contacts = table_contacts(self.table, self.table.wall_conductance, self.table.wall_temperature)
        return init_state(particles, contacts, self.dt)

    def params(self, kappa, specific_heat) -> Params:
        """:class:`~sintercond.simulate.Params` of the experiment at ``kappa`` (W/(m K)) and ``c`` (J/(kg K))."""
        dtype = jnp.asarray(self.initial).dtype
        return Params(conductivity=jnp.reshape(jnp.asarray(kappa, dtype), (1,)),
                      specific_heat=jnp.reshape(jnp.asarray(specific_heat, dtype), (1,)),
                      pulse=PulseParams(jnp.asarray(self.power), jnp.asarray(self.pulse_duration, dtype)))

    def _simulate(self, kappa, specific_heat):
        n_readings = self.n_steps // self.save_every
        _, saved = rollout(self._sim, self.initial_state(), self.params(kappa, specific_heat),
                           n_readings * self.save_every, SaveAt(self.save_every, probe_temperatures(self.probes)))
        return saved


def _power(experiment, k):
    """Heat input (W) during step ``k``, at the time ``k dt`` the simulator uses."""
    t = jnp.asarray(k, experiment.power.dtype) * experiment.dt
    return jnp.where(t < experiment.pulse_duration, experiment.power, 0.0)


def _segment_length(n_steps):
    return max(1, math.isqrt(n_steps - 1) + 1)  # ceil(sqrt(n_steps))


@functools.partial(jax.custom_vjp, nondiff_argnums=(0,))
def _adjoint_readings(experiment: ProbeExperiment, kappa, specific_heat):
    readings, _ = _adjoint_forward(experiment, kappa, specific_heat)
    return readings


def _step(experiment, kappa, specific_heat, temperature, k):
    """The simulator's explicit update (:func:`sintercond.sim.thermal.explicit_update`) keeping ``H``, the inflow at
    kappa = 1, which the adjoint needs."""
    inflow = heat_inflow(temperature, experiment.table)
    return _update(experiment, kappa, specific_heat, temperature, inflow, k), inflow


def _update(experiment, kappa, specific_heat, temperature, inflow, k):
    """Step ``k``'s new temperatures from the inflow ``H`` at kappa = 1 (W)."""
    return thermal.explicit_update(temperature, kappa * inflow + _power(experiment, k), specific_heat * experiment.mass,
                                   experiment.dt, experiment.fixed_mask, experiment.fixed_temperature)


def _run(experiment, kappa, specific_heat, temperature, k0, length):
    """``length`` steps from step ``k0``; returns the end state and the probe temperature after every step."""

    def body(carry, _):
        t, k = carry
        t, _ = _step(experiment, kappa, specific_heat, t, k)
        return (t, k + 1), t[experiment.probes]

    (t, _), probes = jax.lax.scan(body, (temperature, k0), None, length=length)
    return t, probes


def _layout(n_steps):
    seg = _segment_length(n_steps)
    return seg, n_steps // seg, n_steps % seg


def _adjoint_forward(experiment, kappa, specific_heat):
    seg, n_seg, tail = _layout(experiment.n_steps)

    def segment(carry, _):
        t, k = carry
        t_end, probes = _run(experiment, kappa, specific_heat, t, k, seg)
        return (t_end, k + seg), (t, probes)

    (t, k), (starts, probes) = jax.lax.scan(segment, (experiment.initial, 0), None, length=n_seg)
    probes = probes.reshape(n_seg * seg, -1)
    if tail:
        _, tail_probes = _run(experiment, kappa, specific_heat, t, k, tail)
        probes = jnp.concatenate([probes, tail_probes])
    readings = probes[experiment.save_every - 1::experiment.save_every]
    return readings, (starts, t, kappa, specific_heat)


def _adjoint_bwd(experiment, residuals, readings_bar):
    starts, tail_start, kappa, specific_heat = residuals
    seg, n_seg, tail = _layout(experiment.n_steps)
    n, p = experiment.table.n_particles, readings_bar.shape[1]
    every = experiment.save_every
    # cotangent of the probe temperature after every step (zero between readings)
    per_step = jnp.zeros((experiment.n_steps, p), readings_bar.dtype).at[every - 1::every].set(
        readings_bar[: experiment.n_steps // every])
    rate = experiment.dt / (specific_heat * experiment.mass)
    held = experiment.fixed_mask

    def masked(x):
        return x if held is None else jnp.where(held, 0.0, x)

    probe_rate = masked(rate)[experiment.probes]
    heated = _heated_particles(experiment)

    def backward_segment(carry, xs):
        start, k0, bar = xs
        length = bar.shape[0]
        weight, acc_inflow, acc_power, inflows = carry

        def record(j, c):  # recompute the segment, keeping H per step in the buffer (one buffer for all segments)
            t, inflows = c
            inflows = jax.lax.dynamic_update_index_in_dim(inflows, heat_inflow(t, experiment.table), j, 0)
            # H read back from the buffer: the gather writes it there in place, and the update reads it
            inflow = jax.lax.dynamic_index_in_dim(inflows, j, keepdims=False)
            return _update(experiment, kappa, specific_heat, t, inflow, k0 + j), inflows

        _, inflows = jax.lax.fori_loop(0, length, record, (start, inflows))

        def back(i, c):
            # weight = a mu, the adjoint scaled by a = dt / (c m) and masked on held particles: the one array the
            # network's gather reads (a product would be gathered factor by factor)
            weight, acc_inflow, acc_power = c
            j = length - 1 - i
            k = k0 + j
            weight = weight.at[experiment.probes].add(probe_rate * bar[j])
            on = jnp.asarray(k, rate.dtype) * experiment.dt < experiment.pulse_duration
            acc_inflow = acc_inflow + weight * jax.lax.dynamic_index_in_dim(inflows, j, keepdims=False)
            acc_power = acc_power + jnp.where(on, weight if heated is None else weight[heated], 0.0)
            weight = masked(weight - kappa * rate * laplacian(weight, experiment.table))
            return weight, acc_inflow, acc_power

        # two steps per iteration: XLA sums both steps' accumulations in one pass, and the second gather writes
        # into the loop's own buffer (no copy of the weight)
        weight, acc_inflow, acc_power = jax.lax.fori_loop(0, length, back, (weight, acc_inflow, acc_power), unroll=2)
        return (weight, acc_inflow, acc_power, inflows), None

    zeros = jnp.zeros(n, readings_bar.dtype)
    carry = (zeros, zeros, zeros if heated is None else jnp.zeros(len(heated), readings_bar.dtype),
             jnp.zeros((seg, n), readings_bar.dtype))
    if tail:
        carry, _ = backward_segment(carry, (tail_start, n_seg * seg, per_step[n_seg * seg:]))
    if n_seg:
        bars = per_step[: n_seg * seg].reshape(n_seg, seg, p)
        carry, _ = jax.lax.scan(backward_segment, carry, (starts, jnp.arange(n_seg) * seg, bars), reverse=True)
    _, acc_inflow, acc_power, _ = carry
    power = experiment.power if heated is None else experiment.power[heated]
    # d/d kappa of T + a (kappa H + q) is a H; d/dc is -(a / c)(kappa H + q)
    g_kappa = jnp.sum(acc_inflow)
    g_c = -(kappa * g_kappa + jnp.sum(acc_power * power)) / specific_heat
    return g_kappa, g_c


def _heated_particles(experiment):
    """Indices of the particles the pulse heats when they are few (a flash heats one face), else None.

    The adjoint then accumulates the pulse's cotangent on those alone, not in a pass over every particle.
    """
    heated = np.flatnonzero(np.asarray(experiment.power))
    return jnp.asarray(heated, jnp.int32) if len(heated) <= experiment.table.n_particles // 8 else None


_adjoint_readings.defvjp(_adjoint_forward, _adjoint_bwd)


def flash_experiment(centres, radii, density, axis=0, temperature_rise=10.0, pulse_duration=None, initial_temperature=300.0,
                     kappa_max=100.0, specific_heat_min=100.0, n_steps=2000, save_every=20, n_probes=4,
                     law="rojek") -> ProbeExperiment:
    """A flash experiment on a packing: heat the ``lo`` face, read probes on the ``hi`` face.

    Args:
      centres, radii: the packing (m); contacts and necks as in
        :func:`sintercond.contacts.network.contact_table` with ``law``.
      density: solid density (kg/m^3); masses ``density 4/3 pi r^3``.
      axis: flash direction.
      temperature_rise: the flash's energy as the mean rise of the packing (K) at ``c = specific_heat_min``;
        the power is shared by the particles reaching the ``lo`` face in proportion to their cross-section.
      pulse_duration: pulse length (s); default a tenth of the run.
      initial_temperature: uniform start (K).
      kappa_max, specific_heat_min: the step is the explicit stability limit at ``kappa_max / c_min``,
        so any ``kappa <= kappa_max`` with ``c >= c_min`` is stable.
      n_steps, save_every: run length and reading interval (steps).
      n_probes: probes spread over the particles reaching the ``hi`` face.
    """
    centres = np.asarray(centres, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    for name, value in (("density", density), ("temperature_rise", temperature_rise), ("kappa_max", kappa_max),
                        ("specific_heat_min", specific_heat_min)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be finite and > 0; got {value!r}")
    table = contact_table(centres, radii, 1.0, law=law)
    mass = density * 4.0 / 3.0 * np.pi * radii**3
    total = np.asarray(total_conductance(table))
    dt = float(np.min(np.where(total > 0, mass * specific_heat_min / (kappa_max * np.where(total > 0, total, 1)),
                               np.inf)))
    lo, hi = (centres[:, axis] - radii).min(), (centres[:, axis] + radii).max()
    hot = centres[:, axis] - radii <= lo + 0.5 * radii.mean()
    cold = np.flatnonzero(centres[:, axis] + radii >= hi - 0.5 * radii.mean())
    weights = np.where(hot, radii**2, 0.0)
    probes = cold[np.linspace(0, len(cold) - 1, min(n_probes, len(cold))).round().astype(int)]
    pulse_duration = float(pulse_duration if pulse_duration is not None else 0.1 * n_steps * dt)
    power = temperature_rise * specific_heat_min * mass.sum() / pulse_duration
    return ProbeExperiment(
        table=table, mass=jnp.asarray(mass), initial=jnp.full(len(radii), float(initial_temperature)),
        power=jnp.asarray(power * weights / weights.sum()),
        pulse_duration=pulse_duration, dt=dt,
        n_steps=int(n_steps), save_every=int(save_every), probes=jnp.asarray(probes))


def fit_conductivity(experiment: ProbeExperiment, readings, specific_heat, kappa0, noise=None, kappa_max=None,
                     **options) -> FitResult:
    """Recover ``kappa`` (W/(m K)) from probe readings with ``c`` known, by gradient descent through the scan.

    The loss gradient is the checkpointed adjoint; the Gauss-Newton
    covariance uses forward-mode derivatives of the same simulator. ``kappa``
    is bounded to ``(0, kappa_max)`` (default: the stability limit at this
    ``c``). ``noise``: the readings' standard deviation (K) if known.
    ``options`` go to :func:`fitting.core.least_squares`.
    """
    readings = jnp.asarray(readings)
    limit = experiment.max_diffusivity_ratio() * specific_heat
    kappa_max = limit if kappa_max is None else min(float(kappa_max), limit)
    if not 0 < kappa0 < kappa_max:
        raise ValueError(f"kappa0 must lie in (0, {kappa_max:.6g}) W/(m K) (stability limit at c = {specific_heat})")
    weights = None if noise is None else jnp.full(readings.shape, 1.0 / noise)
    model, forward_model = _conductivity_models(experiment, float(specific_heat))
    options = {"loss_tol": 1e-10, **options}  # each step is a whole simulation: stop on a flat loss
    return least_squares(model, None, readings, {"kappa": float(kappa0)}, {"kappa": Bounded(0.0, kappa_max)},
                         weights=weights, jacobian_model=forward_model, **options)


def conductivity_posterior(experiment: ProbeExperiment, readings, specific_heat, kappa0, noise, prior=None,
                           kappa_max=None, **sampler):
    """The posterior of ``kappa`` (W/(m K)) from probe readings with ``c`` (J/(kg K)) and the noise (K) known.

    The same model and bounds as :func:`fit_conductivity` (``kappa`` in ``(0, kappa_max)``), sampled by
    :func:`fitting.posterior.sample_posterior` (NUTS on the adjoint's gradients, started from the least-squares
    fit); ``prior`` on ``kappa`` (default uniform on the bounds). ``sampler`` goes to ``sample_posterior``.
    Returns its :class:`fitting.posterior.PosteriorResult`.
    """
    from fitting.posterior import Uniform, sample_posterior

    limit = experiment.max_diffusivity_ratio() * specific_heat
    kappa_max = limit if kappa_max is None else min(float(kappa_max), limit)
    if not 0 < kappa0 < kappa_max:
        raise ValueError(f"kappa0 must lie in (0, {kappa_max:.6g}) W/(m K) (stability limit at c = {specific_heat})")
    model, forward_model = _conductivity_models(experiment, float(specific_heat))
    prior = Uniform(0.0, kappa_max) if prior is None else prior
    sampler = {"fit_options": {"method": "levenberg_marquardt", "max_steps": 50, "loss_tol": 1e-10}, **sampler}
    return sample_posterior(model, None, jnp.asarray(readings), {"kappa": float(kappa0)}, priors={"kappa": prior},
                            transforms={"kappa": Bounded(0.0, kappa_max)}, sigma=noise, jacobian_model=forward_model,
                            **sampler)


@functools.lru_cache(maxsize=16)
def _conductivity_models(experiment, specific_heat):
    """The readings as functions of ``{"kappa"}`` (adjoint and autodiff), one pair per experiment and ``c``,
    so that repeated fits to new readings reuse the compiled fit."""

    def model(params, _):
        return experiment.temperatures(params["kappa"], specific_heat)

    def forward_model(params, _):
        return experiment.temperatures(params["kappa"], specific_heat, "autodiff")

    return model, forward_model
