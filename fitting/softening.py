"""Fit of the thermal-softening law through the coupled thermo-mechanical simulation.

The law (Quintana-Ruiz & Campello 2020, Eq. 42, with the rate and floor of
MECHANICS.md erratum 6; :func:`sintercond.laws.materials.softened_modulus`)::

    E(theta) = max(E_min, E0 exp(min(0, rate (1 - theta / theta*))))

is fitted to temperature and overlap (or settlement) histories by weighted
least squares (:func:`fitting.core.least_squares`) through
:func:`sintercond.simulate.rollout` of ``Physics.create(mechanics=True,
softening=True)``: the model of the data *is* the simulation, differentiated
by JAX itself. ``method="adam"`` uses reverse mode over the rollout's
``jax.checkpoint``-ed segments of ~``sqrt(n_steps)`` steps (memory
``O(sqrt(n_steps))`` states); the default ``"levenberg_marquardt"`` uses
forward-mode Jacobians (a handful of parameters: ~(1 + p) forward runs per
iteration, constant memory, about ten iterations). Both end with the
Gauss-Newton covariance of :mod:`fitting.core`.

Parameters in unconstrained space
---------------------------------
Every fitted quantity is positive, so the optimiser works on its natural
logarithm (``log_E0``, ``log_theta_star``, ``log_rate``, ``log_E_min``,
``log_conductivity``: :class:`fitting.core.Free` variables). The
Gauss-Newton covariance of the logarithms is the relative covariance of the
values; intervals are ``exp(log x +- z s)`` (never negative) and the
reported standard errors are ``x s`` (delta method).

What the data identify
----------------------
* Overlap and temperature together (Example 5.1): at quasi-static
  equilibrium the overlap under the weight is Hertz's
  ``delta = (3 m g / (4 E* sqrt(r)))^(2/3)``, ``E* = E / (1 - nu^2)`` against a
  rigid floor (Remark 1), so every ``(theta, delta)`` reading gives
  ``E(theta)`` directly (:func:`oracle_modulus`): ``E0`` from the readings
  below ``theta*``, ``theta*`` and the rate from those above.
* Temperatures alone: heat enters through the contact, conductance
  ``k pi r delta / (r - delta)`` (conductivity law, Hertz area; Eq. 32) with
  ``delta ~ E^(-2/3)``; so the heating curve depends on the conductivity
  ``k`` and ``E0`` only through ``k E0^(-2/3)`` (up to ``delta / r ~ 2e-3``
  and the millisecond settling transient). Fit one with the other fixed
  (``theta(t)`` alone with ``k`` known identifies ``E0``, ``theta*``, rate);
  fitting both returns the ridge, flagged in :attr:`SofteningFit.warnings`
  with the identified combination (:func:`ridge_combination`).
* Below ``theta*``: ``E = E0`` exactly, the data do not depend on ``theta*``
  or the rate at all (zero Jacobian columns). The fit therefore starts
  ``theta*`` inside the observed temperature range, and a result whose
  ``theta*`` is at or above the hottest reading says so
  (:attr:`SofteningFit.softening_observed` False, infinite standard errors
  from the rank-deficient Jacobian, and a warning): all such data say is
  ``theta* >= max theta``.
* ``E_min`` is identified only where the floor binds inside the data.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from fitting.core import FitResult, Free, least_squares
from sintercond import examples, simulate
from sintercond.sim import mechanics
from sintercond.laws.materials import softened_modulus

FITTABLE = ("E0", "theta_star", "rate", "E_min", "conductivity")
"""Quantities :func:`fit_softening` can fit (SI units), each through its logarithm."""

GRAVITY = 9.81


# --------------------------------------------------------------------------
# experiments: a coupled simulation observed every few steps


@dataclasses.dataclass(frozen=True, eq=False)
class SofteningExperiment:
    """A coupled thermo-mechanical run observed every ``save_every`` steps (hashed by identity).

    Attributes:
      sim, state, params: the simulator, its initial state and the nominal
        :class:`sintercond.simulate.Params` (the values not fitted).
      n_steps: steps simulated (a multiple of ``save_every``).
      save_every: steps between readings.
      observe: hashable ``fn(state) -> [n_channels]``.
      channels: names of the observed channels; a name starting with
        ``"temperature"`` is a temperature (K), others are lengths (m).
      load: the static load (N) on the contact whose overlap is observed
        (``m g`` in Example 5.1; for :func:`oracle_modulus`), or None.
      step_checkpoint: reverse mode recomputes each step of a segment
        instead of storing its intermediates
        (:func:`sintercond.simulate.rollout`'s ``step_checkpoint``). The
        coupled step has hundreds of small intermediates per step: storing
        them (one write each per step, then a read) costs more than
        running the step once more (faster: docs/devlog/softening_gradient.md,
        branch softbwd). The same numbers either way (round-off);
        forward mode is unaffected.
    """

    sim: simulate.Simulator
    state: simulate.SimState
    params: simulate.Params
    n_steps: int
    save_every: int
    observe: Callable
    channels: tuple
    load: float | None = None
    step_checkpoint: bool = True

    def __post_init__(self):
        if not (isinstance(self.n_steps, int) and isinstance(self.save_every, int) and self.save_every >= 1
                and self.n_steps >= self.save_every and self.n_steps % self.save_every == 0):
            raise ValueError(f"n_steps ({self.n_steps!r}) must be a positive multiple of save_every "
                             f"({self.save_every!r})")
        object.__setattr__(self, "_predict", jax.jit(self._readings_and_overflow,
                                                     compiler_options=mechanics.compiler_options(self.sim.physics)))

    def _readings_and_overflow(self, values: Mapping):
        state, saved = self.rollout(values)
        return saved, state.overflow

    def readings(self, values: Mapping) -> np.ndarray:
        """:meth:`predict` compiled once per experiment, as a NumPy array.

        Raises:
          ValueError: a neighbour or pair list of the run ran out of room (pairs were dropped, so the
            readings would be wrong); :func:`bed_experiment`'s ``capacity_multiplier`` gives more.
        """
        _check_values(values, "values")
        saved, overflow = self._predict({k: float(v) for k, v in values.items()})
        if bool(overflow):
            raise ValueError(f"the contact lists overflowed during the run at {dict(values)} (pairs were dropped); "
                             "rebuild the experiment with more room (bed_experiment's capacity_multiplier)")
        return np.asarray(saved)

    @property
    def times(self) -> np.ndarray:
        """``[n_saves]`` times of the readings (s)."""
        k = np.arange(1, self.n_steps // self.save_every + 1)
        return k * self.save_every * float(self.state.dt)

    def temperature_channels(self) -> np.ndarray:
        return np.array([c.startswith("temperature") for c in self.channels])

    def params_with(self, values: Mapping) -> simulate.Params:
        """The nominal parameters with ``values`` (natural units, keys of :data:`FITTABLE`) in place."""
        mp = self.params.mechanics
        changes = {k: jnp.asarray(v, jnp.result_type(float)) for k, v in values.items() if k != "conductivity"}
        params = dataclasses.replace(self.params, mechanics=dataclasses.replace(mp, **changes))
        if "conductivity" in values:
            kappa = jnp.asarray(self.params.conductivity)
            params = dataclasses.replace(params, conductivity=jnp.broadcast_to(
                jnp.asarray(values["conductivity"], kappa.dtype), kappa.shape))
        return params

    def nominal(self) -> dict:
        """The nominal values of :data:`FITTABLE` (natural units)."""
        mp = self.params.mechanics
        out = {k: float(getattr(mp, k)) for k in FITTABLE if k != "conductivity"}
        out["conductivity"] = float(jnp.atleast_1d(self.params.conductivity)[0])
        return out

    def rollout(self, values: Mapping):
        """``(final state, readings [n_saves, n_channels])`` for ``values`` (traceable)."""
        return self.run(self.params_with(values))

    def run(self, params: simulate.Params, saveat: simulate.SaveAt | None = None, checkpoint=True):
        """:func:`sintercond.simulate.rollout` of the experiment from ``params`` (default: its readings), with its
        checkpointing (``checkpoint=False``: no segments, every step's intermediates kept)."""
        saveat = simulate.SaveAt(self.save_every, self.observe) if saveat is None else saveat
        return simulate.rollout(self.sim, self.state, params, self.n_steps, saveat, checkpoint=checkpoint,
                                step_checkpoint=self.step_checkpoint)

    def predict(self, values: Mapping):
        """Readings ``[n_saves, n_channels]`` for ``values`` (natural units; traceable, differentiable)."""
        return self.rollout(values)[1]

    def log_model(self, logs: Mapping, columns):
        """Model for :func:`fitting.core.least_squares`: ``{"log_E0": ..}`` -> the readings of ``columns``, flat."""
        return self.log_model_and_overflow(logs, columns)[0]

    def log_model_and_overflow(self, logs: Mapping, columns):
        """:meth:`log_model` and whether the run's lists overflowed (``least_squares(..., invalid=True)``)."""
        values = {name[4:]: jnp.exp(v) for name, v in logs.items()}
        state, saved = self.rollout(values)
        return jnp.ravel(saved[:, columns]), state.overflow


def _overlap_on_floor(state):
    """Temperature (K) and overlap with the floor ``z = 0`` (m) of particle 0."""
    p = state.particles
    return jnp.stack([p.temperature[0], p.radii[0] - p.positions[0, 2]])


def example_5_1_experiment(t_end=3.0, save_every=2500, initial_temperature=None, dt=2e-5, **example) -> \
        SofteningExperiment:
    """Example 5.1 (a sphere on a 700 K floor, :func:`sintercond.examples.example_5_1`) observed as ``(theta, delta)``.

    Args:
      t_end: duration (s); the paper runs 40 s, thermal equilibrium comes at ~12 s.
      save_every: steps between readings (2500 steps = 0.05 s at the default ``dt``).
      initial_temperature: the sphere's initial temperature (K); None: the paper's 300 K.
      dt: time step (s).
      example: further arguments of :func:`sintercond.examples.example_5_1`.
    """
    sim, state, params, _ = examples.example_5_1(softening=True, dt=dt, t_end=t_end, **example)
    if initial_temperature is not None:
        state = dataclasses.replace(state, particles=dataclasses.replace(
            state.particles, temperature=jnp.full_like(state.particles.temperature, float(initial_temperature))))
    n_steps = int(round(t_end / dt / save_every)) * save_every
    mass = float(state.particles.mass[0])
    return SofteningExperiment(sim, state, params, n_steps, int(save_every), _overlap_on_floor,
                               ("temperature", "overlap"), load=mass * GRAVITY)


# --------------------------------------------------------------------------
# the closed-form oracle of Example 5.1


def oracle_modulus(overlap, load, radius, nu):
    """Young's modulus (Pa) that makes ``overlap`` Hertz's static overlap of a sphere under ``load`` on a rigid plane.

    Inverts :func:`sintercond.examples.static_overlap`,
    ``delta = (3 F / (4 E* sqrt(r)))^(2/3)`` with ``E* = E / (1 - nu^2)``
    (Quintana-Ruiz & Campello 2020, Eqs. 2-4 at rest; Remark 1 for the
    wall): ``delta ~ E^(-2/3)``, so ``E = E_ref (delta_ref / delta)^(3/2)``.
    Valid where the sphere is at rest (after the landing transient, heating
    slow against the contact's period).

    Args:
      overlap: ``[k]`` overlaps (m), > 0.
      load: static normal load (N), e.g. ``m g``.
      radius: sphere radius (m).
      nu: Poisson ratio.
    """
    overlap = np.asarray(overlap, np.float64)
    if not np.all(np.isfinite(overlap) & (overlap > 0)):
        raise ValueError("overlap must be finite and > 0 m")
    reference = examples.static_overlap(load, radius, 1.0, nu)  # at E = 1 Pa
    return (reference / overlap) ** 1.5


def _modulus_from_logs(logs, theta):
    """``log E(theta)`` for logarithmic parameters (the softening law; E_min from ``log_E_min`` if given)."""
    e_min = jnp.exp(logs["log_E_min"]) if "log_E_min" in logs else 0.0
    modulus = softened_modulus(theta, jnp.exp(logs["log_E0"]), jnp.exp(logs["log_theta_star"]),
                               jnp.exp(logs["log_rate"]), e_min)
    return jnp.log(modulus)


def fit_modulus_curve(theta, modulus, start=None, **options) -> dict:
    """Fit the law to ``(theta, E)`` points directly (the oracle's readings; no simulation): natural values.

    Least squares on ``log E`` over ``log E0``, ``log theta*``, ``log rate``.
    ``theta*`` starts at the middle of the temperatures given (a start
    above all of them leaves it, and the rate, with zero gradient).
    """
    theta, modulus = np.asarray(theta, np.float64), np.asarray(modulus, np.float64)
    if start is None:
        start = {"E0": float(np.max(modulus)), "theta_star": float(0.5 * (theta.min() + theta.max())), "rate": 1.0}
    logs0 = {f"log_{k}": math.log(v) for k, v in start.items()}
    options = {"method": "levenberg_marquardt", "max_steps": 200, **options}
    fit = least_squares(_modulus_from_logs, jnp.asarray(theta), np.log(modulus), logs0, **options)
    return {k[4:]: math.exp(v) for k, v in fit.params.items()}


# --------------------------------------------------------------------------
# the fit


@dataclasses.dataclass(frozen=True)
class SofteningFit:
    """Outcome of :func:`fit_softening`.

    Attributes:
      values: fitted values, natural units (``E0``, ``E_min`` Pa; ``theta_star`` K; ``rate``; ``conductivity`` W/(m K)).
      stderr: their standard errors (delta method on the logarithms' Gauss-Newton covariance; inf: not identified).
      log_covariance: ``[p, p]`` covariance of the logarithms, order of ``names``.
      names: fitted quantities.
      fit: the :class:`fitting.core.FitResult` on the logarithms.
      fixed: the values held fixed (natural units).
      softening_observed: the hottest reading exceeds the fitted ``theta*`` and the fitted ``theta*`` and rate
        have finite standard errors below their values (else they are not identified: the data only say that
        ``E`` stays ``E0`` up to the hottest reading, ``theta* >= max theta`` or a vanishing rate).
      max_temperature: the hottest temperature reading (K).
      warnings: what the data do not identify, in words.
    """

    values: dict
    stderr: dict
    log_covariance: np.ndarray
    names: tuple
    fit: FitResult
    fixed: dict
    softening_observed: bool
    max_temperature: float
    warnings: tuple

    def interval(self, name, z=1.959964):
        """``(low, high)``: ``exp(log x -+ z s)``, the interval of ``name`` (95 % at the default ``z``)."""
        k = self.names.index(name)
        s = math.sqrt(self.log_covariance[k, k])
        return self.values[name] * math.exp(-z * s), self.values[name] * math.exp(z * s)

    def modulus(self, theta):
        """The fitted ``E(theta)`` (Pa)."""
        v = {**self.fixed, **self.values}
        return np.asarray(softened_modulus(np.asarray(theta, np.float64), v["E0"], v["theta_star"], v["rate"],
                                           v["E_min"]))

    def correlation(self) -> np.ndarray:
        s = np.sqrt(np.diag(self.log_covariance))
        return self.log_covariance / np.outer(s, s)


def ridge_combination(result: SofteningFit, exponent=-2.0 / 3.0):
    """``(value, relative stderr)`` of ``k E0^exponent``, what temperatures alone identify (default ``k E0^(-2/3)``)."""
    i, j = result.names.index("conductivity"), result.names.index("E0")
    grad = np.zeros(len(result.names))
    grad[i], grad[j] = 1.0, exponent
    value = result.values["conductivity"] * result.values["E0"] ** exponent
    return value, float(np.sqrt(grad @ result.log_covariance @ grad))


def _checked_sigma(sigma, channels) -> np.ndarray:
    """``sigma`` broadcast to ``[channels]``; ``ValueError`` unless every entry is finite and > 0."""
    sigma = np.broadcast_to(np.asarray(sigma, np.float64), (channels,))
    if not np.all(np.isfinite(sigma) & (sigma > 0)):
        raise ValueError(f"sigma (noise standard deviation per channel) must be finite and > 0; got {sigma.tolist()}")
    return sigma


def _check_values(values: Mapping, name):
    """``ValueError`` naming ``name[key]`` unless each of ``values`` is a quantity of :data:`FITTABLE` in its range:
    the mechanical ones in :data:`sintercond.sim.mechanics.PARAMETER_RANGES`, the conductivity finite and > 0 W/(m K)
    (readings at E0 < 0 or theta* = 0 ran)."""
    from sintercond.sim.mechanics import validate_mechanical_params

    for k, v in values.items():
        if k not in FITTABLE:
            raise ValueError(f"{name}[{k!r}] is not a quantity among {list(FITTABLE)}")
        if k == "conductivity":
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name}['conductivity'] must be finite and > 0 W/(m K); got {float(v)!r}")
        else:
            validate_mechanical_params({k: v}, names={k: f"{name}[{k!r}]"})


def _check_fit_inputs(experiment, data, sigma, fit, channels, start):
    if not isinstance(experiment, SofteningExperiment):
        raise ValueError(f"experiment must be a SofteningExperiment; got {type(experiment).__name__}")
    unknown = [k for k in fit if k not in FITTABLE]
    if unknown or not fit or len(set(fit)) != len(fit):
        raise ValueError(f"fit must name distinct quantities among {list(FITTABLE)}; got {list(fit)}")
    bad = [c for c in channels if c not in experiment.channels]
    if bad or not channels:
        raise ValueError(f"channels must be among {list(experiment.channels)}; got {list(channels)}")
    shape = (experiment.n_steps // experiment.save_every, len(experiment.channels))
    data = np.asarray(data, np.float64)
    if data.shape != shape:
        raise ValueError(f"data must be [n_saves, n_channels] = {list(shape)}; got shape {list(data.shape)}")
    if not np.all(np.isfinite(data)):
        raise ValueError("data must be finite")
    sigma = _checked_sigma(sigma, len(experiment.channels))
    for k, v in start.items():
        if k not in FITTABLE or not (np.isfinite(v) and v > 0):
            raise ValueError(f"start[{k!r}] must be a quantity among {list(FITTABLE)} with a finite value > 0; "
                             f"got {v!r}")
    missing = [k for k in fit if k == "E_min" and k not in start and experiment.nominal()["E_min"] <= 0]
    if missing:
        raise ValueError("fitting E_min needs start['E_min'] > 0 (the nominal floor is 0)")
    return data, sigma


def fit_softening(experiment: SofteningExperiment, data, sigma, fit=("E0", "theta_star", "rate"), channels=None,
                  start=None, method="levenberg_marquardt", **options) -> SofteningFit:
    """Fit softening (and optionally conductivity) parameters to readings through the coupled simulation.

    Args:
      experiment: the simulated run (:class:`SofteningExperiment`).
      data: ``[n_saves, n_channels]`` readings (K, m), at ``experiment.times``.
      sigma: noise standard deviation per channel (scalar or ``[n_channels]``; K, m): the weights ``1/sigma``.
      fit: quantities fitted (keys of :data:`FITTABLE`), each through its logarithm; the rest stay at the
        experiment's nominal values.
      channels: channels fitted (default all).
      start: starting values (natural units); defaults: the nominal values, except ``theta*`` started in the middle
        of the observed temperatures (a start above them all gives zero gradient in ``theta*`` and the rate).
      method: ``"levenberg_marquardt"`` (forward-mode Jacobians) or ``"adam"`` (reverse mode through the
        checkpointed rollout, then Gauss-Newton polish steps).
      options: further options of :func:`fitting.core.least_squares`.

    Returns:
      :class:`SofteningFit` (values, standard errors and intervals, identifiability flags and warnings).
    """
    channels = tuple(experiment.channels if channels is None else channels)
    fit = tuple(fit)
    start = dict(start or {})
    data, sigma = _check_fit_inputs(experiment, data, sigma, fit, channels, start)
    columns = np.array([experiment.channels.index(c) for c in channels])
    hot = experiment.temperature_channels()
    max_temperature = float(np.max(data[:, hot])) if hot.any() else math.nan
    nominal = experiment.nominal()
    if "theta_star" in fit and "theta_star" not in start and hot.any():
        start["theta_star"] = float(0.5 * (np.min(data[:, hot]) + max_temperature))
    start = {k: start.get(k, nominal[k]) for k in fit}
    weights = np.broadcast_to(1.0 / sigma[columns], (data.shape[0], len(columns))).ravel()
    logs0 = {f"log_{k}": math.log(start[k]) for k in fit}
    options = {"max_steps": 60 if method == "levenberg_marquardt" else 2000, "loss_tol": 1e-12, **options}
    # every evaluation of the fit (trial steps, Jacobians) reports whether its lists overflowed: a fit that would
    # have used a run that dropped pairs raises instead
    result = least_squares(experiment.log_model_and_overflow, jnp.asarray(columns), data[:, columns].ravel(), logs0,
                           {k: Free() for k in logs0}, weights=weights, method=method, invalid=True,
                           invalid_message="the contact lists overflowed (pairs were dropped); rebuild the experiment "
                                           "with more room (bed_experiment's capacity_multiplier)", **options)
    values = {k: math.exp(result.params[f"log_{k}"]) for k in fit}
    log_cov = np.asarray(result.covariance)
    stderr = {k: values[k] * float(np.sqrt(log_cov[i, i])) for i, k in enumerate(fit)}
    notes = []
    theta_star = values.get("theta_star", nominal["theta_star"])
    above = bool(hot.any() and max_temperature > theta_star)
    shape_fitted = [k for k in ("theta_star", "rate") if k in fit]
    determined = all(stderr[k] < values[k] for k in shape_fitted)  # False for inf or NaN
    observed = above and determined
    if shape_fitted and not above:
        notes.append(f"the readings never exceed theta* (hottest {max_temperature:.6g} K, theta* "
                     f"{theta_star:.6g} K): theta* and the rate are not identified; the data only say "
                     f"theta* >= {max_temperature:.6g} K")
    elif shape_fitted and not determined:
        notes.append(f"theta* and the rate are not determined by the readings (standard errors "
                     f"{', '.join(f'{k} {stderr[k]:.3g}' for k in shape_fitted)}): no softening is resolved up to "
                     f"{max_temperature:.6g} K (fitted rate {values.get('rate', nominal['rate']):.3g}); the data "
                     f"only say that E stays near E0 there")
    mechanical = any(not c.startswith("temperature") for c in channels)
    if {"conductivity", "E0"} <= set(fit) and not mechanical:
        notes.append("temperatures alone identify the conductivity and E0 only through k E0^(-2/3) "
                     "(see ridge_combination); add an overlap or settlement channel or fix one of them")
    if "E_min" in fit:
        v = {**nominal, **values}
        unfloored = float(np.min(softened_modulus(data[:, hot], v["E0"], v["theta_star"], v["rate"], 0.0))) \
            if hot.any() else math.inf
        if unfloored > values["E_min"]:
            notes.append(f"the floor E_min = {values['E_min']:.6g} Pa never binds in the data (E >= "
                         f"{unfloored:.6g} Pa): E_min is not identified")
    for note in notes:
        warnings.warn(note, UnidentifiedWarning, stacklevel=2)
    fixed = {k: v for k, v in nominal.items() if k not in fit}
    return SofteningFit(values, stderr, log_cov, fit, result, fixed, observed, max_temperature, tuple(notes))


class UnidentifiedWarning(UserWarning):
    """A fitted quantity the data do not determine (see the module docstring)."""


def synthetic_data(experiment: SofteningExperiment, truth: Mapping, sigma, seed=0):
    """``(clean, noisy)`` readings ``[n_saves, n_channels]`` for ``truth`` plus Gaussian noise of std ``sigma``."""
    sigma = _checked_sigma(sigma, len(experiment.channels))  # before the run
    clean = experiment.readings(truth)
    rng = np.random.default_rng(seed)
    return clean, clean + sigma * rng.standard_normal(clean.shape)


# --------------------------------------------------------------------------
# a settled bed heated from its floor


def _bed_readings(state, probes):
    """Probe temperatures (K) and the mean height of the particles' centres (m): the bed's settlement is its drop."""
    p = state.particles
    return jnp.concatenate([p.temperature[probes], jnp.mean(p.positions[:, 2])[None]])


def settled_bed():
    """The 62-sphere bed of :func:`bed_experiment`'s defaults, settled once: ``(centres [n, 3], radii [n])`` (m).

    Shipped as ``fitting/data/settled_bed_62.csv`` (see fitting/data/README.md)
    so that the notebook's bed fit does not depend on the chaotic settling of a
    loose pile (:func:`bed_experiment`).
    """
    import importlib.resources

    with importlib.resources.files("fitting.data").joinpath("settled_bed_62.csv").open() as f:
        rows = [line for line in f if not line.startswith("#")][1:]  # comments, then the header
    table = np.loadtxt(rows, delimiter=",", ndmin=2)
    return table[:, :3], table[:, 3]


def _fastest_sphere(sim, state, params):
    """:func:`bed_experiment`'s settling figure: the fastest sphere's speed (m/s); nothing overflows in it."""
    return jnp.max(jnp.linalg.norm(state.mechanics.velocity, axis=1)), jnp.zeros((), bool)


def bed_experiment(lateral_size=8e-3, height=6e-3, diameter_range=(1.6e-3, 2.4e-3), seed=0, specific_heat=0.2,
                   floor_temperature=700.0, initial_temperature=300.0, t_end=0.06, save_every=100, n_probes=3,
                   friction=True, mu=0.3, settle_time=0.3, speed_tol=1e-4, dt=None, E0=1e6, theta_star=400.0,
                   rate=1.0, capacity_multiplier=1.25, bed=None) -> SofteningExperiment:
    """A bed settled under gravity by the coupled simulation, then heated from its floor: probes and settlement.

    The spheres (density 3000 kg/m^3, k = 60 W/(m K), nu = 0.3, Example 5.1's
    material) are piled by :func:`sintercond.beds.packing.powder_bed` in a square
    box of side ``lateral_size`` (frictionless insulated side walls), then
    settled by the coupled simulation itself (Hertz contacts, friction ``mu``
    between particles, the floor at the bed's temperature: no heat flows)
    until every sphere moves slower than ``speed_tol`` (m/s), so the heating
    starts from the simulation's own equilibrium. The settling lists have
    room for twice the loose pile's pairs; the heating run's are then sized
    on the settled bed with ``capacity_multiplier`` spare room (half as many
    pair slots: the laws run on every slot, so the run, its gradient and the
    fits are faster; :meth:`SofteningExperiment.readings` and
    :func:`fit_softening` raise if they ran out). At ``t = 0`` the floor
    turns to ``floor_temperature``. Readings: ``n_probes`` particle
    temperatures from the bottom to the top of the bed's central column,
    and the mean height of the centres (its drop is the settlement).

    ``specific_heat`` (J/(kg K)) is scaled down from Example 5.1's 100 so the
    bed heats within a few thousand mechanical steps (the thermal time of a
    floor contact is ~0.035 c s against a contact period of ~2 ms); the
    softening law and the identifiability are unchanged by it.

    ``bed``: ``(centres [n, 3], radii [n])`` (m) to settle instead of the pile
    of ``powder_bed``; :func:`settled_bed` gives a bed settled once and shipped.
    Settling a loose pile is chaotic: round-off of another processor moves the
    settled spheres by up to a millimetre and the settlement over the heating
    by about 2 %. Spheres that start at rest in a settled bed only readjust
    their friction springs (perturbations decay there), so experiments built
    on the shipped bed give the same readings on any machine to round-off
    (tests/test_fit_softening.py).

    Raises:
      ValueError: the bed did not settle within ``settle_time`` (s), or the neighbour list overflowed.
    """
    from sintercond.beds import packing
    from sintercond.rollout import ListOverflow, advance
    from sintercond.state import particle_state
    from sintercond.laws.walls import PlaneWall

    if not capacity_multiplier >= 1.0:
        raise ValueError(f"capacity_multiplier (spare room of the heating run's contact lists) must be >= 1; got "
                         f"{capacity_multiplier!r}")
    if bed is None:
        pile = packing.powder_bed(lateral_size, height, diameter_range, seed=seed, method="relax")
        x, r = pile.centres, pile.radii
    else:
        x, r = (np.asarray(v, dtype=np.float64) for v in bed)
        if x.ndim != 2 or x.shape[1] != 3 or r.shape != (x.shape[0],):
            raise ValueError(f"bed must be (centres [n, 3], radii [n]); got shapes {x.shape} and {r.shape}")
    particles = particle_state(x, r, initial_temperature, 3000.0)
    side = (PlaneWall((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)), PlaneWall((lateral_size, 0.0, 0.0), (-1.0, 0.0, 0.0)),
            PlaneWall((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)), PlaneWall((0.0, lateral_size, 0.0), (0.0, -1.0, 0.0)))

    def physics(floor):
        walls = (PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), "conducting", float(floor)),) + side
        # mu_wall = 0: the walls' tangential law is skipped
        return simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted",
                                       contacts="dynamic", mechanics=True, walls=walls, softening=True,
                                       friction=friction, wall_friction=False)

    contacts, fns = simulate.dynamic_contacts(x, particles.radii, 0.1 * float(np.mean(r)), capacity_multiplier=2.0)
    f64 = lambda v: jnp.asarray(float(v), jnp.float64)  # noqa: E731
    params = simulate.Params(conductivity=jnp.asarray([60.0]), specific_heat=jnp.asarray([float(specific_heat)]),
                             mechanics=mechanics.MechanicalParams(
                                 E0=f64(E0), nu=f64(0.3), xi_con=f64(1.0), xi_fric=f64(1.0), xi_rol=f64(0.0),
                                 mu=f64(mu), mu_r=f64(0.0), mu_wall=f64(0.0), mu_r_wall=f64(0.0),
                                 theta_star=f64(theta_star), rate=f64(rate), E_min=f64(0.0)))
    settle = physics(initial_temperature)
    limit = float(mechanics.mechanical_time_step(settle.mechanics, particles, contacts.neighbors, params.mechanics, 0.05))
    dt = 0.8 * limit if dt is None else float(dt)
    mechanics.check_mechanical_time_step(dt, settle.mechanics, particles, contacts.neighbors, params.mechanics, 0.05)
    state = simulate.init_state(particles, contacts, dt,
                                mechanics=mechanics.mechanical_state(settle.mechanics, x, contacts))
    chunk = 500
    speed = [math.inf]

    def settled(s, fastest):
        speed[0] = float(fastest)
        return speed[0] < speed_tol

    try:
        state, _ = advance(simulate.simulator(settle, fns), state, params,
                           chunk * max(1, int(math.ceil(settle_time / (chunk * dt)))), chunk, settled,
                           measure=_fastest_sphere)
    except ListOverflow:  # the settling lists have twice the loose pile's room; no reallocation
        raise ValueError("the neighbour list overflowed while the bed settled; raise capacity_multiplier") from None
    if not speed[0] < speed_tol:
        raise ValueError(f"the bed did not settle within settle_time = {settle_time:g} s (fastest sphere "
                         f"{speed[0]:.3g} m/s, allowed < {speed_tol:g} m/s)")
    state = dataclasses.replace(state, step=jnp.zeros_like(state.step))
    contacts, fns = simulate.dynamic_contacts(state.particles.positions, particles.radii, 0.1 * float(np.mean(r)),
                                              capacity_multiplier=capacity_multiplier)
    state = dataclasses.replace(
        state, contacts=contacts,
        mechanics=mechanics.remap_history(state.mechanics, state.contacts.pairs.pairs, contacts.pairs.pairs))
    # probes: the spheres nearest the box's vertical axis, spread from the bottom to the top
    centre = np.asarray(state.particles.positions)
    axis = np.linalg.norm(centre[:, :2] - 0.5 * lateral_size, axis=1)
    column = np.argsort(axis)[:max(3 * n_probes, 8)]
    column = column[np.argsort(centre[column, 2])]
    probes = column[np.round(np.linspace(0, len(column) - 1, n_probes)).astype(int)]
    n_steps = int(round(t_end / dt / save_every)) * save_every
    observe = simulate.Observable(_bed_readings, jnp.asarray(probes))
    channels = tuple(f"temperature_{k}" for k in range(n_probes)) + ("height",)
    return SofteningExperiment(simulate.simulator(physics(floor_temperature), fns), state, params, n_steps,
                               int(save_every), observe, channels)
