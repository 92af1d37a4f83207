"""Fits of sintering kinetics to neck-against-time data, and the conductivity that follows.

Data: Rizza & Galati (2024)'s phase-field necks along their PBF-EB preheating
ramp (Eq. 6 with its erratum: :func:`sintercond.laws.sintering.preheating_history`):

* ``"80-80"``: Table 2 / Table 3 couple 1 (two 80 um spheres, the SC cell's and
  the BCC corners' neck; the two tables print the same series);
* ``"80-58.6"``: Table 3 couple 2 (an 80 um corner and the 58.6 um BCC centre);
* ``"bed"``: Table 8, the 13-particle powder bed's 21 couples at 0.5, 3.5, 6.5
  and 9.5 s. Its noise is handled by a stated choice: the diameters are
  Table 7's (the couple names disagree with it for particles 3, 4, 10 and 11),
  couple 2-3 is dropped (its row repeats couple 1-6's), and the 3.5 s column is
  left out by default (15 of the 21 couples shrink between 3.5 and 6.5 s, which
  no diffusion law does).

The model is :func:`sintercond.laws.sintering.grow_neck` from point contacts along
the ramp. Fitted in the logarithm of the rate at a reference temperature
``T_ref`` (the ramp's mean by default), which decorrelates it from the
activation energy ``Q``:

* grain boundary: ``rate_ref = (A / T_ref) exp(-Q / (R T_ref))`` (m^4/s), so
  ``A = rate_ref T_ref exp(Q / (R T_ref))``;
* power law: ``rate_ref = K0 exp(-Q / (R T_ref))`` (m^n/s) with the exponent
  ``n`` fixed by choice and, for the bed, the size exponent ``p`` fitted.

What neck data along one heating schedule identify (the warnings of
:class:`SinteringFit` say it on each fit): the rate near ``T_ref`` well, ``Q``
poorly, and only as an *apparent* activation energy of these phase-field data
(a second ramp rate or an isothermal hold would pin it); ``n`` and ``Q`` trade
off along a valley (:func:`exponent_valley`), so ``n`` is fixed by mechanism.
The residuals are model misfit, not measurement noise: the Gauss-Newton
intervals scale with the residual standard deviation (``s^2 (J^T J)^-1``).

Conductivity along the ramp (:func:`conductivity_along_ramp`): the fitted
necks feed Rizza & Galati's tortuosity model on sintercond's SC and BCC cells
and the steady network solve of those lattices (necks coupled through their
spheres, and the isolated pipe network beside it) with the Rojek and the
FE-fitted neck laws, the bulk conductivity from their Table 1.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from fitting.core import FitResult, least_squares
from fitting.reference import rizza_galati_table
from sintercond.laws import conductance as cd
from sintercond.laws import geometry
from sintercond.laws import sintering as st
from sintercond.laws import tortuosity as tt
from sintercond.contacts.network import ContactPairs, contact_pairs
from sintercond.sim.steady import steady_state_network_conductivity

UM = 1e-6
SERIES = ("80-80", "80-58.6", "bed")


class IdentifiabilityWarning(UserWarning):
    """What the data cannot determine (see :attr:`SinteringFit.warnings`)."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class NeckSeries:
    """Necks of several couples read at several times along one temperature history.

    Attributes:
      r_i, r_j: ``[c]`` couple radii (m).
      durations, temperatures: the history (``[n]`` s, ``[n]`` K) of
        :func:`sintercond.laws.sintering.grow_neck`.
      interval, couple: ``[m]`` for each observation, the history row and the couple it reads.
      times: ``[m]`` observation times (s).
      necks_um: ``[m]`` observed neck radii (um).
      name: the series' name (static).
    """

    r_i: np.ndarray
    r_j: np.ndarray
    durations: np.ndarray
    temperatures: np.ndarray
    interval: np.ndarray = dataclasses.field(metadata={"static": False})
    couple: np.ndarray = dataclasses.field(metadata={"static": False})
    times: np.ndarray = dataclasses.field(metadata={"static": False})
    necks_um: np.ndarray = dataclasses.field(metadata={"static": False})
    name: str = dataclasses.field(default="", metadata={"static": True})

    def with_necks(self, necks_um) -> NeckSeries:
        """The same series with other observed necks (synthetic data)."""
        return dataclasses.replace(self, necks_um=np.asarray(necks_um, dtype=np.float64))


def neck_series(name: str, *, leave_out_times=(3.5,)) -> NeckSeries:
    """One of Rizza & Galati (2024)'s neck series (module docstring), on the Eq. 6 ramp.

    Args:
      name: ``"80-80"``, ``"80-58.6"`` or ``"bed"``.
      leave_out_times: for ``"bed"``, Table 8 columns (s) not used; ``()`` keeps all four.
    """
    if name == "80-80" or name == "80-58.6":
        t3 = rizza_galati_table(3)
        times = t3["time_s"]
        necks = t3["x_couple1_um"] if name == "80-80" else t3["x_couple2_um"]
        r_j = 40.0 if name == "80-80" else 58.6 / 2
        radii = (np.array([40.0]) * UM, np.array([r_j]) * UM)
        couple = np.zeros(len(times), dtype=np.int64)
    elif name == "bed":
        t7, t8 = rizza_galati_table(7), rizza_galati_table(8)
        diameter = dict(zip(t7["particle"].astype(int), t7["diameter_um"]))
        keep = ~((t8["particle_1"] == 2) & (t8["particle_2"] == 3))  # repeats couple 1-6 row for row
        p1, p2 = t8["particle_1"][keep].astype(int), t8["particle_2"][keep].astype(int)
        radii = (np.array([diameter[p] for p in p1]) / 2 * UM, np.array([diameter[p] for p in p2]) / 2 * UM)
        columns = [t for t in (0.5, 3.5, 6.5, 9.5) if not any(math.isclose(t, s) for s in leave_out_times)]
        times = np.repeat(np.array(columns), keep.sum())
        necks = np.concatenate([t8[f"x_{t}"][keep] for t in columns])
        couple = np.tile(np.arange(keep.sum()), len(columns))
    else:
        raise ValueError(f"name must be one of {SERIES}; got {name!r}")
    durations, temperatures, index = st.preheating_history(np.unique(times))
    interval = index[np.searchsorted(np.unique(times), times)]
    return NeckSeries(radii[0], radii[1], durations, temperatures, interval, couple, np.asarray(times, float),
                      np.asarray(necks, float), name)


TIME_COLUMNS = ("time_s", "time", "t")
NECK_COLUMNS = {"neck_um": UM, "neck_m": 1.0, "neck_ratio": None}
"""Columns of :func:`read_neck_series`: the neck in um, in m, or over the smaller radius of the couple."""
TEMPERATURE_STEPS = 400
"""Steps a temperature table is held over in :func:`read_neck_series` (each at the table's value at its middle)."""


def read_neck_series(path, r_i, r_j=None, *, temperature, name=None) -> NeckSeries:
    """One couple's necks over time from a CSV file, as a :class:`NeckSeries` for :func:`fit_kinetics`.

    The file: a header naming the time (``time_s``, ``time`` or ``t``; s) and the neck (``neck_um``, ``neck_m`` or
    ``neck_ratio``, the neck radius over ``min(r_i, r_j)``), and with ``temperature="column"`` a ``temperature_K``
    column; commas or whitespace, ``#`` comments. Rows at ``t = 0`` give the start (a point contact) and are not
    readings.

    Args:
      path: the CSV file.
      r_i, r_j: the couple's radii (m); ``r_j`` defaults to ``r_i``.
      temperature: the history the couple went through: a number (K, isothermal); a table ``[[t, T], ...]``
        (s, K), linear between its points and held beyond them (a ramp is two points), held in
        :data:`TEMPERATURE_STEPS` equal steps each at its middle's value; or ``"column"``: the file's
        ``temperature_K`` read as such a table.
      name: the series' name (default the file's stem).
    """
    from pathlib import Path

    path = Path(path)
    lines = [line.split("#", 1)[0].replace(",", " ").split() for line in path.read_text().splitlines()]
    lines = [fields for fields in lines if fields]
    if not lines:
        raise ValueError(f"{path}: no header and no rows")
    header = [h.lower() for h in lines[0]]
    time_name = next((c for c in TIME_COLUMNS if c in header), None)
    neck_name = next((c for c in NECK_COLUMNS if c in header), None)
    if time_name is None or neck_name is None:
        raise ValueError(f"{path}: the header {lines[0]} must name a time column (one of {list(TIME_COLUMNS)}) and "
                         f"a neck column (one of {list(NECK_COLUMNS)})")
    try:
        table = np.array([[float(v) for v in fields] for fields in lines[1:]], np.float64).reshape(-1, len(header))
    except ValueError:
        raise ValueError(f"{path}: every row must hold {len(header)} numbers ({' '.join(lines[0])})") from None
    column = {h: table[:, k] for k, h in enumerate(header)}
    times, necks = column[time_name], column[neck_name]
    r_i = float(r_i)
    r_j = r_i if r_j is None else float(r_j)
    if not (np.all(np.isfinite(table)) and np.all(np.diff(times) > 0) and times[0] >= 0 and np.all(necks >= 0)):
        raise ValueError(f"{path}: times must be finite, >= 0 and strictly increasing, necks finite and >= 0")
    if not (math.isfinite(r_i) and math.isfinite(r_j) and r_i > 0 and r_j > 0):
        raise ValueError(f"r_i and r_j must be finite and > 0 (m); got {r_i!r}, {r_j!r}")
    scale = NECK_COLUMNS[neck_name]
    necks_um = necks * (min(r_i, r_j) if scale is None else scale) / UM
    if isinstance(temperature, str):
        if temperature != "column" or "temperature_k" not in column:
            raise ValueError(f"temperature must be a number (K), a table [[t, T], ...] or \"column\" with a "
                             f"temperature_K column in {path}; got {temperature!r} (columns {lines[0]})")
        temperature = np.column_stack([times, column["temperature_k"]])
    history = np.atleast_2d(np.asarray(temperature, np.float64))
    if history.shape == (1, 1):
        history = np.array([[0.0, history[0, 0]]])
    if history.ndim != 2 or history.shape[1] != 2 or not np.all(np.isfinite(history)) or \
            np.any(history[:, 1] <= 0) or np.any(np.diff(history[:, 0]) <= 0):
        raise ValueError(f"temperature must be a number (K) or [[t, T], ...] pairs, t increasing, T > 0 K; "
                         f"got {np.asarray(temperature).tolist()}")
    readings = times > 0
    ends = np.linspace(0.0, times[-1], TEMPERATURE_STEPS + 1)[1:]
    middles = ends - 0.5 * times[-1] / TEMPERATURE_STEPS
    durations, temperatures, interval = st.piecewise_history(ends, np.interp(middles, *history.T), times[readings])
    return NeckSeries(np.array([r_i]), np.array([r_j]), durations, temperatures, interval,
                      np.zeros(int(readings.sum()), np.int64), times[readings], necks_um[readings],
                      path.stem if name is None else name)


def ramp_temperature_mean(series: NeckSeries) -> float:
    """Time-weighted mean temperature of the series' history up to its last reading (K)."""
    end = int(np.max(series.interval)) + 1
    return float(np.sum(series.durations[:end] * series.temperatures[:end]) / np.sum(series.durations[:end]))


def _law_params(fit_params, law, reference_temperature, fixed):
    """The kinetic law's parameters from the fit-space ones (``log_rate_ref``, ``activation_energy``, ...)."""
    q = fit_params["activation_energy"]
    arrhenius_ref = jnp.exp(1e3 * q / (st.GAS_CONSTANT * reference_temperature))
    rate_ref = jnp.exp(fit_params["log_rate_ref"])
    out = dict(fixed)
    if law == "grain_boundary":
        out["A"] = rate_ref * reference_temperature * arrhenius_ref
    else:
        out["K0"] = rate_ref * arrhenius_ref
    out["activation_energy"] = q
    for name in ("size_exponent", "exponent"):
        if name in fit_params:
            out[name] = fit_params[name]
    return out


@dataclasses.dataclass(frozen=True)
class _Model:
    """Static description of a neck model (hashable: the compiled fit is cached per model)."""

    law: str
    reference_temperature: float
    fixed: tuple

    def params(self, fit_params):
        return _law_params(fit_params, self.law, self.reference_temperature, dict(self.fixed))

    def necks_um(self, fit_params, series: NeckSeries):
        history = st.grow_neck(self.law, 0.0, series.r_i, series.r_j, series.temperatures[:, None],
                               series.durations, self.params(fit_params))
        return history[series.interval, series.couple] / UM

    def __call__(self, fit_params, series):
        return self.necks_um(fit_params, series)


def _model(law, reference_temperature, exponent, size_exponent, dihedral_angle):
    if law == "grain_boundary":
        fixed = {"dihedral_angle": float(dihedral_angle)}
    elif law == "power_law":
        fixed = {"exponent": float(exponent), "reference_radius": 40.0 * UM}
        if size_exponent is not None:
            fixed["size_exponent"] = float(size_exponent)
    else:
        raise ValueError(f"law must be 'grain_boundary' or 'power_law' (neck data of diffusion); got {law!r}")
    return _Model(law, float(reference_temperature), tuple(sorted(fixed.items())))


@dataclasses.dataclass(frozen=True)
class SinteringFit:
    """A kinetic fit with what it determines.

    Attributes:
      law: the kinetic law's name.
      series: the data.
      values: the law's parameters at the optimum (units of the law, Q in kJ/mol), including the fixed ones.
      fit: the :class:`fitting.core.FitResult` in fit space (``log_rate_ref`` in ln(m^n/s), Q in kJ/mol, ...).
      reference_temperature: ``T_ref`` (K).
      predicted_um, residuals_um: model necks at the observations and data minus model (um).
      warnings: identifiability statements.
    """

    law: str
    series: NeckSeries
    values: dict
    fit: FitResult
    reference_temperature: float
    predicted_um: np.ndarray
    residuals_um: np.ndarray
    warnings: tuple

    @property
    def rmse_um(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_um**2)))

    @property
    def stderr(self) -> dict:
        return self.fit.stderr

    def correlation(self) -> np.ndarray:
        s = np.sqrt(np.diag(self.fit.covariance))
        return self.fit.covariance / np.outer(s, s)

    def log_prefactor(self) -> tuple[float, float]:
        """``(ln A, its stderr)`` for the grain-boundary law, ``(ln K0, stderr)`` for the power law.

        ``ln A = log_rate_ref + ln T_ref + Q / (R T_ref)``: its error includes Q's,
        which is why the fit works in ``log_rate_ref``.
        """
        names = self.fit.names
        gradient = np.zeros(len(names))
        gradient[names.index("log_rate_ref")] = 1.0
        gradient[names.index("activation_energy")] = 1e3 / (st.GAS_CONSTANT * self.reference_temperature)
        key = "A" if self.law == "grain_boundary" else "K0"
        return float(np.log(self.values[key])), float(np.sqrt(gradient @ self.fit.covariance @ gradient))


def _setup(series, law, exponent, size_exponent, dihedral_angle, reference_temperature, start):
    """``(T_ref, model, fit-space starting values)`` of a kinetic fit (:func:`fit_kinetics`)."""
    t_ref = ramp_temperature_mean(series) if reference_temperature is None else float(reference_temperature)
    model = _model(law, t_ref, exponent, size_exponent, dihedral_angle)
    params0 = {"log_rate_ref": 0.0, "activation_energy": 100.0}
    if law == "power_law" and size_exponent is None:
        params0["size_exponent"] = 0.0
    if start is None:
        # the rate that grows the mean last neck in the ramp's time at T_ref, ignoring the shape of the law
        last = series.times == series.times.max()
        n = 6.0 if law == "grain_boundary" else float(exponent)
        u = (np.mean(series.necks_um[last]) * UM) ** n
        r_star = float(np.mean(2 * series.r_i * series.r_j / (series.r_i + series.r_j)))
        # the point-contact shape 48 r* 4 r* (1 - cos(psi/2)) of the grain-boundary law
        scale = 192.0 * r_star**2 * (1 - math.cos(math.radians(dihedral_angle) / 2)) if law == "grain_boundary" \
            else 1.0
        params0["log_rate_ref"] = float(np.log(u / series.times.max() / scale))
    else:
        params0.update({k: float(v) if isinstance(v, numbers.Integral) else v for k, v in start.items()})
    return t_ref, model, params0


@dataclasses.dataclass(frozen=True)
class KineticsPosterior:
    """The posterior of a kinetic law's parameters (:func:`kinetics_posterior`).

    Attributes:
      posterior: the :class:`fitting.posterior.PosteriorResult` in fit space (``log_rate_ref``,
        ``activation_energy`` in kJ/mol, ...).
      reference_temperature: ``T_ref`` (K).
      log_prefactor: ``[draws]`` ``ln A`` (grain boundary, A in m^4 K/s) or ``ln K0`` (power law) of each draw:
        ``log_rate_ref + ln T_ref + Q / (R T_ref)`` (the module docstring's relation, per draw: no linearisation).
    """

    law: str
    series: NeckSeries
    posterior: object
    reference_temperature: float
    log_prefactor: np.ndarray
    model: object = dataclasses.field(repr=False, default=None)

    def necks_um(self, times, r_i=40.0 * UM, r_j=40.0 * UM, every=1) -> np.ndarray:
        """Necks (um) of one couple (radii m) at ramp ``times`` (s) for every ``every``-th draw: ``[draws, times]``
        (the posterior predictive mean curve's draws; add the noise for a predictive band of readings)."""
        durations, temperatures, index = st.preheating_history(np.asarray(times, dtype=np.float64))
        names = [n for n in self.posterior.names if n != "sigma"]
        draws = self.posterior.draws[::every, :len(names)]

        @jax.jit
        @jax.vmap
        def one(row):
            params = self.model.params(dict(zip(names, row)))
            return st.grow_neck(self.law, 0.0, jnp.atleast_1d(r_i), jnp.atleast_1d(r_j), temperatures[:, None],
                                durations, params)[index, 0] / UM

        return np.asarray(one(jnp.asarray(draws)))


def kinetics_posterior(series: NeckSeries, law="grain_boundary", *, priors=None, sigma=None, sigma_prior=None,
                       exponent=6.0, size_exponent=0.0, dihedral_angle=150.0, reference_temperature=None, start=None,
                       **sampler) -> KineticsPosterior:
    """The posterior of a kinetic law's parameters given a neck series (NUTS through :func:`sintercond.laws.sintering.grow_neck`).

    The model and fit space of :func:`fit_kinetics`; ``priors`` per fit-space parameter (default: ``Q`` uniform on
    (1, 1000) kJ/mol, ``log_rate_ref`` flat); ``sigma`` the necks' noise (um), or None: sampled (the residuals of
    phase-field data are model misfit, their size unknown). ``sampler`` goes to
    :func:`fitting.posterior.sample_posterior`.
    """
    from fitting.posterior import Uniform, sample_posterior

    t_ref, model, params0 = _setup(series, law, exponent, size_exponent, dihedral_angle, reference_temperature, start)
    priors = {"activation_energy": Uniform(1.0, 1000.0)} if priors is None else priors
    post = sample_posterior(model, series, jnp.asarray(series.necks_um), params0, priors=priors, sigma=sigma,
                            sigma_prior=sigma_prior, **sampler)
    draws = post.draws
    names = post.names
    log_prefactor = (draws[:, names.index("log_rate_ref")] + math.log(t_ref)
                     + 1e3 * draws[:, names.index("activation_energy")] / (st.GAS_CONSTANT * t_ref))
    return KineticsPosterior(law, series, post, t_ref, log_prefactor, model)


def fit_kinetics(series: NeckSeries, law="grain_boundary", *, exponent=6.0, size_exponent=0.0,
                 dihedral_angle=150.0, reference_temperature=None, start=None, max_steps=200) -> SinteringFit:
    """Least-squares fit of a kinetic law to a neck series (Levenberg-Marquardt, Gauss-Newton intervals).

    Args:
      series: from :func:`neck_series` (or synthetic, :meth:`NeckSeries.with_necks`).
      law: ``"grain_boundary"`` (n = 6) or ``"power_law"``.
      exponent: the power law's ``n`` (fixed).
      size_exponent: the power law's ``p``: a number (fixed) or ``None`` (fitted with the rest).
      dihedral_angle: psi of the grain-boundary law (degrees, fixed).
      reference_temperature: ``T_ref`` (K); default the ramp's time-weighted mean.
      start: fit-space starting values (default: Q = 100 kJ/mol and the rate that matches the last reading).
    """
    t_ref, model, params0 = _setup(series, law, exponent, size_exponent, dihedral_angle, reference_temperature,
                                   start)
    fit = least_squares(model, series, jnp.asarray(series.necks_um), params0, method="levenberg_marquardt",
                        max_steps=max_steps)
    values = {k: float(v) for k, v in model.params(fit.params).items()}
    predicted = np.asarray(model(fit.params, series))
    notes = _identifiability_notes(fit, series, law, t_ref)
    for note in notes:
        warnings.warn(note, IdentifiabilityWarning, stacklevel=2)
    return SinteringFit(law, series, values, fit, t_ref, predicted, series.necks_um - predicted, tuple(notes))


def _identifiability_notes(fit: FitResult, series: NeckSeries, law: str, t_ref: float) -> list[str]:
    notes = [
        f"one heating schedule ({series.name or 'this series'}: {series.temperatures.min():.0f}-"
        f"{series.temperatures.max():.0f} K): the activation energy {fit.params['activation_energy']:.3g} "
        f"+- {fit.stderr['activation_energy']:.2g} kJ/mol is an apparent one of these data; a second ramp rate or an "
        "isothermal hold is needed to pin it, and phase-field necks give the model's, not the material's, energy",
    ]
    if law == "power_law":
        notes.append("the exponent n and the activation energy trade off along a valley (exponent_valley); n is "
                     "fixed by choice, not identified")
    if not fit.converged:
        notes.append(f"the fit stopped at max_steps ({fit.steps}) before its tolerance: it may not be at the optimum")
    return notes


def exponent_valley(series: NeckSeries, exponents=(3.0, 4.0, 5.0, 6.0, 7.0), **options):
    """Power-law fits at fixed exponents: ``(exponents, Q kJ/mol, Q stderr, rmse um)`` arrays.

    Shows the n-Q valley: each ``n`` has its own best ``Q``, at nearly the same misfit near the best ``n``.
    """
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        for n in exponents:
            f = fit_kinetics(series, "power_law", exponent=n, **options)
            rows.append((n, f.values["activation_energy"], f.stderr["activation_energy"], f.rmse_um))
    return tuple(np.array(column) for column in zip(*rows))


def synthetic_series(series: NeckSeries, law, fit_params, sigma_um, seed=0, **model_options) -> tuple:
    """``(clean necks um, noisy series)``: the model at ``fit_params`` (fit space) plus Gaussian noise."""
    t_ref = model_options.pop("reference_temperature", None)
    t_ref = ramp_temperature_mean(series) if t_ref is None else t_ref
    model = _model(law, t_ref, model_options.get("exponent", 6.0), model_options.get("size_exponent", 0.0),
                   model_options.get("dihedral_angle", 150.0))
    clean = np.asarray(model(fit_params, series))
    noise = np.random.default_rng(seed).normal(0.0, sigma_um, clean.shape)
    return clean, series.with_necks(clean + noise)


def grown_necks(fit: SinteringFit, r_i, r_j, times) -> np.ndarray:
    """Necks (m) of couples ``(r_i, r_j)`` (m) at ``times`` (s) of the ramp, with the fitted law: ``[times, c]``."""
    durations, temperatures, index = st.preheating_history(np.asarray(times, dtype=np.float64))
    r_i, r_j = np.atleast_1d(r_i), np.atleast_1d(r_j)
    history = st.grow_neck(fit.law, 0.0, r_i, r_j, temperatures[:, None], durations, fit.values)
    return np.asarray(history)[index]


# --------------------------------------------------------------------------
# conductivity along the ramp


def lattice_conductivity(centres, radii, box, necks, kappa, law="rojek", axis=0, cells=2, coupling="sphere"):
    """``k*`` (W/(m K)) of a lattice whose contacts have the given necks (first stage: centres fixed).

    The unit cell (``centres``, ``radii``, ``box``: touching spheres, as
    :func:`sintercond.laws.geometry.simple_cubic_cell` and ``bcc_cell`` give) is
    repeated ``cells`` times along ``axis`` and made periodic across it (three
    cells wide); each contact's conductance comes from its neck
    ``necks(r_i, r_j)`` (m) through ``law`` at the overlap ``H(a)``
    (:func:`sintercond.laws.sintering.neck_overlap`); the steady pipe-network solve
    holds the first plane of spheres at 1 K and the last at 0 K
    (:func:`sintercond.sim.steady.steady_state_network_conductivity`) on the
    network ``coupling``: ``"sphere"`` (default), the necks that share a sphere
    coupled through its surface, or ``"none"``, the isolated pipe network. For SC
    and BCC (every site a centre of inversion symmetry) the isolated network's
    linear field is then the exact solution, so this is the infinite lattice's
    conductivity (the coupled network's held planes carry mirror images, exact
    for such a lattice). The approach ``H(a)`` (at most 2 % of the spacing on the
    ramp) is left out of the lattice's size: the first stage of sintering, without
    shrinkage. A sphere whose necks' discs overlap keeps its pair laws' halves.
    """
    centres, radii = np.asarray(centres, float), np.asarray(radii, float)
    lo, hi = (np.asarray(b, float) for b in box)
    key = (centres.tobytes(), radii.tobytes(), lo.tobytes(), hi.tobytes(), int(axis), int(cells))
    pairs, solve = _lattice(key, centres.shape[0], coupling)
    a = jnp.stack([jnp.asarray(necks(ri, rj)) for ri, rj in zip(pairs.r_i, pairs.r_j)])
    h = st.neck_overlap(a, pairs.r_i, pairs.r_j)
    k_pairs = cd.conductance_from_neck(law, a, jnp.asarray(pairs.r_i), jnp.asarray(pairs.r_j), h, kappa, kappa)
    return solve(k_pairs, kappa=kappa, neck_radii=a) if coupling == "sphere" else solve(k_pairs)


@functools.lru_cache(maxsize=16)
def _lattice(key, n, coupling):
    """The periodic block of a cell and its compiled steady solve ``K_ij -> k*`` on the network ``coupling`` (the
    geometry never changes; with ``"sphere"`` the solve takes ``kappa`` and ``neck_radii`` too)."""
    centres = np.frombuffer(key[0]).reshape(n, 3)
    radii, lo, hi = (np.frombuffer(b) for b in key[1:4])
    axis, cells = key[4], key[5]
    size = hi - lo
    lateral = np.arange(3) != axis
    shifts = np.array([[i, j, k] for i in range(cells) for j in range(3) for k in range(3)], float)
    shifts[:, [axis, 0]] = shifts[:, [0, axis]]  # the cells counter along the axis
    block = (centres[None, :, :] - lo + shifts[:, None, :] * size).reshape(-1, 3)
    block_radii = np.tile(radii, len(shifts))
    period = np.where(lateral, 3 * size, 0.0)
    block[:, lateral] = np.mod(block[:, lateral] + 1e-9 * size[lateral], period[lateral]) - 1e-9 * size[lateral]
    _, unique = np.unique(np.round(block / size.min(), 9), axis=0, return_index=True)
    block, block_radii = block[unique], block_radii[unique]
    periodic_box = np.where(lateral, 3 * size, 100.0 * cells * size)  # no wrap along the axis
    pairs = contact_pairs(block, block_radii, periodic_box=periodic_box)
    faces_lo = np.where(lateral, 0.0, np.min(block[:, axis] - block_radii))
    faces_hi = np.where(lateral, 3 * size, np.max(block[:, axis] + block_radii))
    extra = {"coupling": coupling} if coupling == "none" else {"beyond_domain": "isolated", "periodic_box": periodic_box}
    solve = jax.jit(functools.partial(steady_state_network_conductivity, block, block_radii, pairs, axis=axis,
                                      box=(faces_lo, faces_hi), **extra))
    return pairs, solve


def conductivity_along_ramp(fits: dict, times=None) -> dict:
    """Conductivities of the SC and BCC cells along the ramp from the fitted necks.

    Args:
      fits: ``{"80-80": SinteringFit, "80-58.6": SinteringFit}``.
      times: ramp times (s); default Table 2's (0.5, 1.5, ..., 9.5).

    Returns:
      ``time_s``, ``temperature_K``, ``lambda0`` (Table 1, W/(m K)), the fitted necks ``x_80_80_um`` and
      ``x_80_58_um``, ``lambda_pow_sc`` (tortuosity model, phi = 3), ``lambda_pow_bcc`` (mean of the two
      couples, phi = 8, as their Table 6) and ``k_star_sc_rojek``, ``k_star_sc_fitted``,
      ``k_star_bcc_rojek``, ``k_star_bcc_fitted`` (the coupled network, :func:`lattice_conductivity`), and
      ``k_star_bcc_rojek_isolated``, ``k_star_bcc_fitted_isolated`` (the isolated pipe network; on SC the two are
      equal), all ``[times]``.
    """
    t_table, temperature_table, lambda0_table = tt.ti6al4v_conductivity_table()
    times = t_table if times is None else np.asarray(times, float)
    lambda0 = np.interp(times, t_table, lambda0_table)
    temperature = np.interp(times, t_table, temperature_table)
    corner, centre = 40.0 * UM, geometry.bcc_cell(80.0)[1][-1] * UM
    x1 = grown_necks(fits["80-80"], corner, corner, times)[:, 0]
    x2 = grown_necks(fits["80-58.6"], corner, centre, times)[:, 0]
    out = {"time_s": times, "temperature_K": temperature, "lambda0": lambda0, "x_80_80_um": x1 / UM,
           "x_80_58_um": x2 / UM}
    sc_cell, bcc_cell = geometry.simple_cubic_cell(80.0 * UM), geometry.bcc_cell(80.0 * UM)
    lam_sc, lam_bcc = [], []
    k = {f"k_star_{cell}_{law}{net}": [] for cell in ("sc", "bcc") for law in ("rojek", "fitted")
         for net in ("", "_isolated") if cell == "bcc" or not net}
    for a1, a2, kappa in zip(x1, x2, lambda0):
        m_sc = geometry.rev_measures(*geometry.simple_cubic_cell(80.0), necks=a1 / UM)
        tau2 = tt.tortuosity_squared(m_sc.sss_over_s0, m_sc.gamma.max(), m_sc.n, 3.0)
        lam_sc.append(float(tt.powder_conductivity(m_sc.n, tau2, kappa)))
        m_bcc = geometry.rev_measures(*geometry.bcc_cell(80.0), necks=lambda i, j, a1=a1, a2=a2:
                                      (a1 if i == j else a2) / UM)
        gammas = tt.gamma_factor(np.array([a1, a2]) / UM, 80.0)
        tau2 = tt.tortuosity_squared(m_bcc.sss_over_s0, gammas, m_bcc.n, 8.0)
        lam_bcc.append(float(np.mean(tt.powder_conductivity(m_bcc.n, tau2, kappa))))

        def necks(ri, rj, a1=a1, a2=a2):
            return a1 if math.isclose(ri, rj) else a2

        for law in ("rojek", "fitted"):
            k[f"k_star_sc_{law}"].append(float(lattice_conductivity(*sc_cell, necks, kappa, law)))
            k[f"k_star_bcc_{law}"].append(float(lattice_conductivity(*bcc_cell, necks, kappa, law)))
            k[f"k_star_bcc_{law}_isolated"].append(float(lattice_conductivity(*bcc_cell, necks, kappa, law,
                                                                              coupling="none")))
    out["lambda_pow_sc"], out["lambda_pow_bcc"] = np.array(lam_sc), np.array(lam_bcc)
    out.update({key: np.array(v) for key, v in k.items()})
    return out


def bed_conductivity_along_ramp(fit: SinteringFit, times=(0.5, 3.5, 6.5, 9.5)) -> dict:
    """``lambda_pow`` of a powder-bed REV along the ramp, each contact's neck grown by ``fit`` (the bed fit).

    The bed: :func:`fitting.reference.powder_bed_450` (45-150 um spheres, settled once), the 150 um cube of
    :func:`sintercond.beds.packing.rev_box` (Rizza & Galati's PB case on a bed of our own); each contact of the
    cube grows its own neck from a point contact with its own radii; ``n``, ``S_ss/S_0``, ``phi`` and the
    per-pair ``gamma`` (``D`` the larger diameter) from :func:`sintercond.laws.geometry.rev_measures`; ``lambda_0``
    from their Table 1 at each time.

    Returns:
      ``time_s``, ``mean_neck_um``, ``lambda_mean``, ``lambda_std`` (over the cube's contacts, W/(m K)),
      ``n``, ``sss_over_s0``, ``phi`` and ``pairs``.
    """
    from fitting.reference import powder_bed_450
    from sintercond.beds import packing

    times = np.asarray(times, float)
    centres, radii, box = packing.rev_box(powder_bed_450(), 150.0)
    t_table, _, lambda0_table = tt.ti6al4v_conductivity_table()
    grown = functools.lru_cache(maxsize=None)(
        lambda r_i, r_j: grown_necks(fit, r_i * UM, r_j * UM, times)[:, 0] / UM)  # radii in um
    out = {k: [] for k in ("mean_neck_um", "lambda_mean", "lambda_std", "n", "sss_over_s0", "phi", "pairs")}
    for k, time in enumerate(times):
        m = geometry.rev_measures(centres, radii, box, necks=lambda r_i, r_j, k=k: float(grown(r_i, r_j)[k]))
        tau2 = tt.tortuosity_squared(m.sss_over_s0, m.gamma, m.n, m.phi)
        lam = np.asarray(tt.powder_conductivity(m.n, tau2, np.interp(time, t_table, lambda0_table)))
        for key, value in (("mean_neck_um", np.mean(m.neck_radii)), ("lambda_mean", lam.mean()), ("lambda_std", lam.std()),
                           ("n", m.n), ("sss_over_s0", m.sss_over_s0), ("phi", m.phi), ("pairs", len(m.pairs))):
            out[key].append(value)
    return {"time_s": times, **{k: np.array(v) for k, v in out.items()}}


def preheat_conductivity_model(scene, saves: int, *, centres=None, radii=None):
    """``(k_star, model)``: a sintering scene's bed along its preheat, stepped adaptively, as a function of its
    kinetics, for fits of them to k*(t).

    ``k_star(theta) -> (k [saves] W/(m K), failed)``: the scene's ``run.duration`` cut into ``saves`` equal
    intervals; the run stepped by TR-BDF2 within ``run.rtol`` / ``run.atol``
    (:func:`sintercond.sim.adaptive.rollout`; ``run.integrator`` is taken as ``"implicit"``) with the scene's
    ``[sintering]`` law at ``A = exp(theta["log_A"])`` (m^4 K/s) and ``Q = theta["Q"]`` (kJ/mol); at the end of
    each interval the k* of the bed along ``sintering.k_star_axis`` on the necks it has then (the steady solve,
    network (``sintering.k_star_coupling``, default the necks coupled through their sphere) and box of a run's
    ``k_star_W_mK``, :func:`sintercond.output.observe.sintered_conductivity`, each particle at its conductivity at
    its temperature there). ``failed`` is set when any adaptive interval did not finish: then
    none of the values is to be used (``least_squares(..., invalid=True)`` raises on it). Forward mode
    (``jax.jvp``, Levenberg-Marquardt in :func:`fitting.core.least_squares`) goes through the adaptive loop; jit
    ``k_star`` once and call it for any ``theta``. The law must be ``"grain_boundary"`` (its ``A`` and ``Q``).

    ``model``: the :class:`sintercond.scene.build.Model` (packing, state, parameters) the function runs on;
    ``centres``, ``radii``: a packing to use instead of building the scene's (m).
    """
    from sintercond.output import observe
    from sintercond.scene import validate_scene
    from sintercond.scene.typed import typed_scene
    from sintercond.scene.build import build_model
    from sintercond.sim import adaptive, rollout
    from sintercond.sim.contacts import pair_neck_conductance, particle_conductivity

    if not (isinstance(saves, numbers.Integral) and saves >= 1):
        raise ValueError(f"saves must be an integer >= 1 (the k* values along the run); got {saves!r}")
    scene = validate_scene({**scene, "run": {**scene.get("run", {}), "integrator": "implicit"}})
    typed = typed_scene(scene)
    if typed.sintering is None or typed.sintering.k_star_axis is None:
        raise ValueError("the scene needs [sintering] with k_star_axis (the axis of k*)")
    if typed.sintering.law != "grain_boundary":
        raise ValueError("preheat_conductivity_model fits (ln A, Q) of sintering.law = \"grain_boundary\"; the scene "
                         f"has {typed.sintering.law!r}")
    model = build_model(scene, centres, radii)
    sim, state, params = model.sim, model.state, model.params
    state = dataclasses.replace(state, dt=jnp.asarray(typed.run.duration / saves, state.dt.dtype))
    x, r = model.centres, model.radii
    i, j = np.asarray(state.contacts.pairs, np.int64).T
    pairs = ContactPairs(i, j, np.asarray(state.contacts.overlap), r[i], r[j], len(r))
    box = observe.k_star_box(model, x)
    axis, coupling = typed.sintering.k_star_axis, typed.sintering.k_star_coupling
    saveat = rollout.SaveAt(every=1, fn=lambda s: (s.contacts, s.particles.temperature))

    def k_star(theta):
        p = dataclasses.replace(params, sintering={**params.sintering, "A": jnp.exp(theta["log_A"]),
                                                   "activation_energy": theta["Q"]})
        _, (contacts, temperature), stats = adaptive.rollout(sim, state, p, saves, saveat)

        def conductivity(c, t):
            there = dataclasses.replace(state, contacts=c, particles=dataclasses.replace(state.particles,
                                                                                          temperature=t))
            return steady_state_network_conductivity(x, r, pairs, pair_neck_conductance(sim.physics, there, p),
                                                     axis=axis, box=box, coupling=coupling,
                                                     kappa=particle_conductivity(sim.physics, p, there.particles),
                                                     neck_radii=c.neck, beyond_domain="isolated")

        return jax.vmap(conductivity)(contacts, temperature), stats.failed

    return k_star, model


__all__ = [
    "IdentifiabilityWarning", "KineticsPosterior", "NeckSeries", "SERIES", "SinteringFit", "bed_conductivity_along_ramp",
    "conductivity_along_ramp", "exponent_valley",
    "fit_kinetics", "grown_necks", "kinetics_posterior", "lattice_conductivity", "neck_series", "preheat_conductivity_model",
    "ramp_temperature_mean",
    "synthetic_series",
]
