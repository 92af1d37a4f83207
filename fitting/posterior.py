"""Bayesian calibration: the posterior of a model's parameters by NUTS (blackjax), from the least-squares optimum.

The model is the one :func:`fitting.core.least_squares` fits, ``y = model(params, x) + e`` with Gaussian noise
``e_i ~ N(0, sigma_i^2)`` (``sigma_i`` relative to ``|y_i|`` with ``relative=True``), so the log posterior of the
constrained parameters ``theta`` is (Gelman et al. 2013, BDA3, Eq. 1.1 and 14.4)

    ln p(theta | y) = -1/2 sum_i r_i^2 - sum_i ln sigma_i + ln p(theta) + const,   r_i = (model_i - y_i) / sigma_i,

with ``sigma`` known, or a parameter of its own (one ``sigma`` for every observation, with its prior, default
Jeffreys' ``p(sigma) ~ 1/sigma``). The sampler works on the unconstrained variables ``u`` of the same transforms
as the fit (:class:`fitting.core.Free`, ``Positive``, ``Bounded``), whose density carries the change of variables
``ln p(u) = ln p(theta(u)) + sum ln |dtheta/du|`` (BDA3, Eq. 1.8). Priors are per parameter: named distributions
(:class:`Normal`, :class:`LogNormal`, :class:`Uniform`, :class:`HalfNormal`, :class:`Jeffreys`) or a callable
``value -> log density``; a parameter without a prior has a flat one (in the constrained variable). A parameter
whose transform is not given takes the one its prior's support calls for (``Uniform(a, b)``: ``Bounded(a, b)``;
``LogNormal``, ``HalfNormal``, ``Jeffreys``: ``Positive``).

The chains start at the least-squares optimum (:func:`fitting.core.least_squares`): there the Laplace
approximation ``theta ~ N(theta_hat, (J^T J + H_prior)^-1)`` (``J`` the Jacobian of ``r``, ``H_prior`` minus the
Hessian of the log prior; BDA3 Sec. 4.1) is the cheap answer, and it also gives NUTS (Hoffman & Gelman 2014) its
dense inverse mass matrix, mapped to ``u``; each chain starts from a draw of it, and a short warmup adapts the
step size (dual averaging, Hoffman & Gelman 2014, Alg. 5) or, with ``warmup="window"``, the mass matrix too
(blackjax's Stan windows). Diagnostics: split R-hat over the chains (BDA3 Sec. 11.4), the effective sample size
(Geyer's initial monotone sequence, blackjax.diagnostics), the divergent transitions; :class:`PosteriorWarning`
says when they fail. :attr:`PosteriorResult.laplace_ratio` says how far the Laplace standard deviations are from
the posterior's.

blackjax is the ``posterior`` extra (pyproject.toml); it is imported when a posterior is sampled.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from fitting.core import (Bounded, FitResult, Free, Positive, _check_fit_inputs, _children, _fit_program, _Layout,
                          _leaf_transforms, _per_leaf, _walk, least_squares)


class PosteriorWarning(UserWarning):
    """The sampler's diagnostics failed: R-hat above its limit, too few effective draws, or divergent transitions."""


def _positive_finite(where, value):
    if not (isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise ValueError(f"{where} must be a finite number > 0; got {value!r}")


def _finite(where, value):
    if not (isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)):
        raise ValueError(f"{where} must be a finite number; got {value!r}")


@dataclasses.dataclass(frozen=True)
class Normal:
    """``N(mean, sd^2)`` (units of the parameter)."""

    mean: float
    sd: float

    def check(self, where):
        _finite(f"{where}.mean", self.mean)
        _positive_finite(f"{where}.sd", self.sd)

    def support(self):
        return (-math.inf, math.inf)

    def log_density(self, x):
        z = (x - self.mean) / self.sd
        return -0.5 * z**2 - math.log(self.sd) - 0.5 * math.log(2 * math.pi)


@dataclasses.dataclass(frozen=True)
class LogNormal:
    """``ln x ~ N(mu, sigma^2)``: ``mu`` the log of the median, ``sigma`` the sd of ``ln x``."""

    mu: float
    sigma: float

    def check(self, where):
        _finite(f"{where}.mu", self.mu)
        _positive_finite(f"{where}.sigma", self.sigma)

    def support(self):
        return (0.0, math.inf)

    def log_density(self, x):
        log_x = jnp.log(x)
        return (-0.5 * ((log_x - self.mu) / self.sigma) ** 2 - log_x - math.log(self.sigma)
                - 0.5 * math.log(2 * math.pi))


@dataclasses.dataclass(frozen=True)
class Uniform:
    """Uniform on ``(low, high)``."""

    low: float
    high: float

    def check(self, where):
        _finite(f"{where}.low", self.low)
        _finite(f"{where}.high", self.high)
        if not self.low < self.high:
            raise ValueError(f"{where} must have low < high; got {self!r}")

    def support(self):
        return (float(self.low), float(self.high))

    def log_density(self, x):
        inside = (x > self.low) & (x < self.high)
        return jnp.where(inside, -math.log(self.high - self.low), -jnp.inf)


@dataclasses.dataclass(frozen=True)
class HalfNormal:
    """``|N(0, sd^2)|`` on ``x > 0``."""

    sd: float

    def check(self, where):
        _positive_finite(f"{where}.sd", self.sd)

    def support(self):
        return (0.0, math.inf)

    def log_density(self, x):
        return -0.5 * (x / self.sd) ** 2 - math.log(self.sd) + 0.5 * math.log(2 / math.pi)


@dataclasses.dataclass(frozen=True)
class Jeffreys:
    """Jeffreys' prior of a scale, ``p(x) ~ 1/x`` on ``x > 0`` (improper: the likelihood must make it proper)."""

    def check(self, where):
        pass

    def support(self):
        return (0.0, math.inf)

    def log_density(self, x):
        return -jnp.log(x)


_PRIORS = (Normal, LogNormal, Uniform, HalfNormal, Jeffreys)
_NATURAL = {Uniform: lambda p: Bounded(p.low, p.high), LogNormal: lambda p: Positive(),
            HalfNormal: lambda p: Positive(), Jeffreys: lambda p: Positive()}


class _Flat:
    """No prior given: flat in the constrained variable."""

    def support(self):
        return (-math.inf, math.inf)

    def log_density(self, x):
        return jnp.zeros_like(x)


class _Callable:
    """A user's ``value -> log density`` on one leaf (its support: the transform's range)."""

    def __init__(self, fn):
        self.fn = fn

    def support(self):
        return (-math.inf, math.inf)

    def log_density(self, x):
        return jnp.sum(jnp.asarray(self.fn(x), x.dtype))

    def __eq__(self, other):
        return isinstance(other, _Callable) and other.fn is self.fn

    def __hash__(self):
        return hash(self.fn)


_UNSET = object()


@dataclasses.dataclass(frozen=True)
class PosteriorResult:
    """Outcome of :func:`sample_posterior`.

    Attributes:
      samples: draws in ``params0``'s structure, each leaf with a leading draw axis (chains concatenated).
      sigma_samples: ``[draws]`` the noise standard deviation when it was a parameter (``sigma=None``), else None.
      chains: ``[chains, draws, p]`` the draws of the ``p`` fitted scalars (``sigma`` last when it was sampled).
      names: one per column of ``chains`` (``names`` of the fit, then ``"sigma"`` when sampled).
      fit: the least-squares optimum the chains started from (:class:`fitting.core.FitResult`).
      laplace_covariance: ``[p, p]`` ``(J^T J + H_prior)^-1`` at the optimum over the model's parameters
        (``sigma`` known, or fixed at the fit's residual standard deviation).
      rhat, ess: per name, split R-hat and the effective sample size over all chains.
      divergences: divergent transitions after warmup (all chains).
      evaluations: model evaluations with their derivatives: ``least_squares`` (each a value and a forward-mode
        Jacobian: the optimiser's steps plus its start, and at most two per polish step, an upper bound), ``warmup``
        and ``sampling`` (each a value and a reverse-mode gradient: one per leapfrog step, and one per chain to start).
      step_size: per chain, after warmup (in the whitened ``u`` of the mass matrix).
      warnings: the diagnostics that failed (also issued as :class:`PosteriorWarning`).
    """

    samples: object
    sigma_samples: np.ndarray | None
    chains: np.ndarray
    names: tuple
    fit: FitResult
    laplace_covariance: np.ndarray
    rhat: dict
    ess: dict
    divergences: int
    evaluations: dict
    step_size: np.ndarray
    warnings: tuple

    @property
    def draws(self) -> np.ndarray:
        """``[chains * draws, p]``: every chain's draws, one row each."""
        return self.chains.reshape(-1, self.chains.shape[-1])

    def median(self) -> dict:
        """``name -> posterior median``."""
        return dict(zip(self.names, np.median(self.draws, axis=0).tolist()))

    def interval(self, level=0.9) -> dict:
        """``name -> (low, high)``: the central credible interval of probability ``level``."""
        lo, hi = np.quantile(self.draws, [(1 - level) / 2, (1 + level) / 2], axis=0)
        return {n: (float(a), float(b)) for n, a, b in zip(self.names, lo, hi)}

    def sd(self) -> dict:
        """``name -> posterior standard deviation``."""
        return dict(zip(self.names, np.std(self.draws, axis=0, ddof=1).tolist()))

    def correlation(self) -> np.ndarray:
        """``[p, p]`` posterior correlation of the columns of ``chains``."""
        return np.corrcoef(self.draws, rowvar=False)

    @property
    def laplace_sd(self) -> dict:
        """``name -> sd`` of the Laplace approximation at the optimum (model parameters)."""
        return dict(zip(self.fit.names, np.sqrt(np.diag(self.laplace_covariance)).tolist()))

    @property
    def laplace_ratio(self) -> dict:
        """``name -> Laplace sd / posterior sd``: 1 where the cheap path is right, far from 1 where it is not."""
        sd = self.sd()
        return {n: s / sd[n] for n, s in self.laplace_sd.items()}

    @property
    def total_evaluations(self) -> int:
        return int(sum(self.evaluations.values()))

    def summary(self, level=0.9) -> str:
        """A table: per name, median, the ``level`` interval, sd, the Laplace ratio, R-hat and ESS."""
        med, ci, sd, ratio = self.median(), self.interval(level), self.sd(), self.laplace_ratio
        lines = [f"{'':>20} {'median':>11} {f'{level:.0%} low':>11} {f'{level:.0%} high':>11} {'sd':>10} "
                 f"{'Laplace/sd':>10} {'R-hat':>6} {'ESS':>6}"]
        for n in self.names:
            r = f"{ratio[n]:10.3f}" if n in ratio else f"{'':>10}"
            lines.append(f"{n:>20} {med[n]:11.4g} {ci[n][0]:11.4g} {ci[n][1]:11.4g} {sd[n]:10.3g} {r} "
                         f"{self.rhat[n]:6.3f} {self.ess[n]:6.0f}")
        return "\n".join(lines)


def sample_posterior(model: Callable, x, y, params0, *, priors=None, sigma=None, sigma_prior=None, transforms=None,
                     relative=False, num_samples=1000, num_chains=4, num_warmup=300, warmup="step_size", seed=0,
                     target_acceptance=0.8, max_doublings=8, jacobian_model: Callable | None = None,
                     fit_options=None, rhat_max=1.01, min_ess=None) -> PosteriorResult:
    """The posterior of ``params`` given ``y ~ model(params, x)`` with Gaussian noise, by NUTS from the optimum.

    Args:
      model, x, y, params0, transforms, relative, jacobian_model: as for :func:`fitting.core.least_squares`
        (``model`` also differentiated in reverse mode here). A parameter without a transform takes its prior's
        (module docstring).
      priors: per parameter, in ``params0``'s structure or a prefix of it (a dict may leave keys out: flat): a
        :class:`Normal`, :class:`LogNormal`, :class:`Uniform`, :class:`HalfNormal`, :class:`Jeffreys`, or a
        callable ``value -> log density`` (summed over an array leaf); or one callable ``params -> log density``
        of the whole tree. A named prior's support must hold its transform's range.
      sigma: the noise standard deviation (units of ``y``; relative with ``relative=True``): a number or an array
        broadcasting to ``y``, known; or None: one unknown ``sigma``, sampled with the rest.
      sigma_prior: ``sigma``'s prior when it is sampled (default :class:`Jeffreys`).
      num_samples, num_chains, num_warmup: draws per chain after warmup, chains (at least 2: R-hat), warmup steps.
      warmup: ``"step_size"`` (dual averaging, the Laplace mass matrix kept) or ``"window"`` (the mass matrix
        adapted too, Stan's windows).
      seed: the random seed (the draws are a deterministic function of it).
      target_acceptance, max_doublings: NUTS settings (tree depth at most ``max_doublings``).
      fit_options: keyword arguments of the least-squares start (default ``method="levenberg_marquardt"``).
      rhat_max, min_ess: :class:`PosteriorWarning` when an R-hat exceeds ``rhat_max`` or an ESS falls below
        ``min_ess`` (default 100 per chain, Vehtari et al. 2021).

    Returns:
      :class:`PosteriorResult`.

    Raises:
      ValueError: input that cannot be sampled (named: the argument, or the parameter's path), before compiling.
    """
    problem = _problem(model, x, y, params0, priors, sigma, sigma_prior, transforms, relative, jacobian_model,
                       fit_options)
    _check_sampler_settings(num_samples, num_chains, num_warmup, warmup, seed, target_acceptance, max_doublings)
    min_ess = 100 * num_chains if min_ess is None else min_ess
    fit = least_squares(model, x, y, params0, transforms=problem.transforms_tree, weights=problem.weights,
                        relative=relative, jacobian_model=jacobian_model, **problem.fit_options)
    lsq_evaluations = fit.steps + 2 * problem.fit_options.get("polish_steps", 3) + 2
    program = problem.program()
    theta_hat = jnp.asarray(_Layout.of(fit.params)[1])
    sigma_hat = fit.residual_std if problem.estimate_sigma else 1.0
    y_j, w = jnp.asarray(y, jnp.float64), problem.w(y)
    cov_theta = np.asarray(program.laplace(theta_hat, x, y_j, w / sigma_hat))
    u_hat, cov_u = program.start(theta_hat, jnp.asarray(cov_theta), sigma_hat, int(np.size(y)))
    keys = jax.random.split(jax.random.PRNGKey(int(seed)), num_chains)
    draws, steps, divergent, warm_steps, step_size = program.sample(keys, u_hat, cov_u, x, y_j, w, num_warmup,
                                                                    num_samples, warmup, float(target_acceptance),
                                                                    int(max_doublings))
    chains = np.asarray(program.constrained_all(draws), dtype=np.float64)
    names = problem.names
    if not np.all(np.isfinite(chains)):
        raise FloatingPointError("the sampler produced non-finite draws; check the priors, sigma and params0")
    rhat, ess = _diagnostics(chains)
    rhat, ess = dict(zip(names, rhat.tolist())), dict(zip(names, ess.tolist()))
    notes = []
    bad_rhat = {n: round(v, 3) for n, v in rhat.items() if not v <= rhat_max}
    if bad_rhat:
        notes.append(f"R-hat above {rhat_max}: {bad_rhat}: the chains disagree; run longer (num_warmup, num_samples)")
    low_ess = {n: round(v) for n, v in ess.items() if not v >= min_ess}
    if low_ess:
        notes.append(f"effective sample size below {min_ess}: {low_ess}; raise num_samples")
    n_div = int(np.sum(np.asarray(divergent)))
    if n_div:
        notes.append(f"{n_div} divergent transitions: the posterior has regions the step size cannot follow; "
                     "raise target_acceptance or reparameterise")
    for note in notes:
        warnings.warn(note, PosteriorWarning, stacklevel=2)
    p = len(problem.layout.names)
    samples = _draws_tree(problem.layout, chains[..., :p].reshape(-1, p))
    evaluations = {"least_squares": int(lsq_evaluations), "warmup": int(np.sum(np.asarray(warm_steps)) + num_chains),
                   "sampling": int(np.sum(np.asarray(steps)))}
    return PosteriorResult(samples, chains[..., p].reshape(-1) if problem.estimate_sigma else None, chains, names,
                           fit, cov_theta, rhat, ess, n_div, evaluations, np.asarray(step_size), tuple(notes))


def _draws_tree(layout, flat):
    """``[draws, p]`` in the parameters' structure, each leaf ``[draws, *shape]``."""
    return layout.unflatten(np.arange(flat.shape[1]), lambda index: flat[:, index.ravel()].reshape(flat.shape[0],
                                                                                                  *index.shape))


def _diagnostics(chains):
    """``(split R-hat, ESS)`` per column of ``[chains, draws, p]``, in NumPy (host arrays; blackjax's diagnostics run
    op by op in JAX, compiling each).

    R-hat: BDA3 Sec. 11.4, Eqs. 11.3-11.4, on the chains split in halves. ESS: BDA3 Eq. 11.8 with the
    autocorrelation from the variogram (Eq. 11.7) and Geyer's initial monotone sequence (sums of adjacent pairs
    kept while positive, made non-increasing), as Stan computes it.
    """
    m, n = chains.shape[:2]
    half = n // 2
    split = np.concatenate([chains[:, :half], chains[:, n - half:]], axis=0)
    means, variances = split.mean(axis=1), split.var(axis=1, ddof=1)
    within, between = variances.mean(axis=0), half * means.var(axis=0, ddof=1)
    var_plus = (half - 1) / half * within + between / half
    rhat = np.sqrt(var_plus / within)
    # ESS on the whole chains
    x = chains - chains.mean(axis=1, keepdims=True)
    size = 1 << (2 * n - 1).bit_length()
    spectrum = np.fft.rfft(x, n=size, axis=1)
    acov = np.fft.irfft(spectrum * np.conj(spectrum), n=size, axis=1)[:, :n] / n  # [m, lag, p]
    chain_var = acov[:, 0] * n / (n - 1)
    w = chain_var.mean(axis=0)
    var_hat = (n - 1) / n * w + (chains.mean(axis=1).var(axis=0, ddof=1) if m > 1 else 0.0)
    rho = 1 - (w - acov.mean(axis=0)) / var_hat  # [lag, p]
    rho[0] = 1.0
    ess = np.empty(chains.shape[2])
    for j in range(chains.shape[2]):
        pairs = rho[: 2 * (n // 2), j].reshape(-1, 2).sum(axis=1)
        positive = np.argmax(pairs <= 0) if np.any(pairs <= 0) else len(pairs)
        monotone = np.minimum.accumulate(pairs[:positive])
        tau = -1.0 + 2.0 * np.sum(monotone)
        ess[j] = m * n / max(tau, 1.0 / np.log10(m * n))
    return rhat, ess


def sample_posterior_replicates(model: Callable, x, ys, params0, *, priors=None, sigma=None, sigma_prior=None,
                                transforms=None, relative=False, num_samples=200, num_chains=2, num_warmup=200,
                                warmup="step_size", seed=0, target_acceptance=0.8, max_doublings=8,
                                jacobian_model: Callable | None = None, fit_options=None) -> np.ndarray:
    """The posterior draws of :func:`sample_posterior` for many data sets at once (one compiled, vmapped run).

    For simulation-based calibration (Talts et al. 2018): ``ys`` is ``[replicates, *y.shape]``; each replicate is
    fitted (the optimiser's loop, without the Gauss-Newton polish) and sampled as :func:`sample_posterior` does,
    without its diagnostics or warnings. Returns ``[replicates, chains * draws, p]`` in the order of the fit's
    names (``sigma`` last when it is sampled).
    """
    ys = np.asarray(ys, dtype=np.float64)
    if ys.ndim < 2:
        raise ValueError(f"ys must be [replicates, *y.shape]; got shape {ys.shape}")
    problem = _problem(model, x, ys[0], params0, priors, sigma, sigma_prior, transforms, relative, jacobian_model,
                       fit_options)
    for k in range(ys.shape[0]):
        if not np.all(np.isfinite(ys[k])):
            raise ValueError(f"ys[{k}] must be finite")
    _check_sampler_settings(num_samples, num_chains, num_warmup, warmup, seed, target_acceptance, max_doublings)
    program = problem.program()
    run = _replicates_program(program, problem.estimate_sigma, len(problem.layout.names), int(np.prod(ys.shape[1:])),
                              num_chains, num_warmup, num_samples, warmup, float(target_acceptance), int(max_doublings),
                              problem.sigma is None or problem.sigma.ndim)
    keys = jax.random.split(jax.random.PRNGKey(int(seed)), ys.shape[0])
    w = problem.w(jnp.asarray(ys[0]))
    with jax.numpy_dtype_promotion("standard"):
        out = run(keys, program.initial_u(params0), x, jnp.asarray(ys), w)
    return np.asarray(out, dtype=np.float64)


@functools.lru_cache(maxsize=8)
def _replicates_program(program, estimate_sigma, p, m, num_chains, num_warmup, num_samples, warmup, target,
                        doublings, _):
    """The compiled, vmapped fit-and-sample of :func:`sample_posterior_replicates` (cached: one compilation)."""

    def one(key, u0, x, y, w):
        u, _, _, _ = program.fit.run(u0, x, y, w)
        theta_hat = program.fit.constrained(u)
        if estimate_sigma:
            r, _ = program.fit.residuals(theta_hat, x, y, w)
            sigma_hat = jnp.sqrt(jnp.sum(r**2) / max(m - p, 1))
        else:
            sigma_hat = 1.0
        cov = program.laplace(theta_hat, x, y, w / sigma_hat)
        u_hat, cov_u = program.start(theta_hat, cov, sigma_hat, m)
        draws, *_ = program.sample(jax.random.split(key, num_chains), u_hat, cov_u, x, y, w, num_warmup,
                                   num_samples, warmup, target, doublings)
        return program.constrained_all(draws).reshape(-1, draws.shape[-1])

    return jax.jit(jax.vmap(one, in_axes=(0, None, None, 0, None)))


def _check_sampler_settings(num_samples, num_chains, num_warmup, warmup, seed, target_acceptance, max_doublings):
    for name, value, low in (("num_samples", num_samples, 2), ("num_chains", num_chains, 2),
                             ("num_warmup", num_warmup, 0), ("max_doublings", max_doublings, 1)):
        if not (isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= low):
            raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
    if warmup not in ("step_size", "window"):
        raise ValueError(f"warmup must be 'step_size' or 'window'; got {warmup!r}")
    if not (isinstance(seed, numbers.Integral) and not isinstance(seed, bool) and 0 <= seed < 2**32):
        raise ValueError(f"seed must be an integer in [0, 2**32); got {seed!r}")
    if not (isinstance(target_acceptance, numbers.Real) and 0 < target_acceptance < 1):
        raise ValueError(f"target_acceptance must be in (0, 1); got {target_acceptance!r}")


@dataclasses.dataclass(frozen=True)
class _Problem:
    """A checked posterior problem: the fit's layout and transforms, each leaf's prior, the noise model."""

    model: Callable
    jacobian_model: Callable | None
    layout: _Layout
    transforms: tuple  # per leaf
    transforms_tree: object  # for least_squares
    priors: tuple  # per leaf
    joint_prior: Callable | None
    sigma: object  # np array (known) or None
    sigma_prior: object
    relative: bool
    fit_options: dict

    @property
    def estimate_sigma(self):
        return self.sigma is None

    @property
    def names(self):
        return self.layout.names + (("sigma",) if self.estimate_sigma else ())

    @property
    def weights(self):
        return None if self.sigma is None else 1.0 / self.sigma

    def w(self, y):
        return jnp.ones_like(y) if self.sigma is None else jnp.broadcast_to(jnp.asarray(1.0 / self.sigma), y.shape)

    def program(self):
        options = {k: v for k, v in self.fit_options.items() if k in ("learning_rate", "max_steps", "grad_tol",
                                                                      "loss_tol", "method")}
        fit = _fit_program(self.model, self.model if self.jacobian_model is None else self.jacobian_model,
                           self.layout, self.transforms, self.relative, options.get("method", "adam"),
                           float(options.get("learning_rate", 0.05)), int(options.get("max_steps", 5000)),
                           float(options.get("grad_tol", 1e-10)), float(options.get("loss_tol", 1e-14)), 0, False)
        return _posterior_program(fit, self.layout, self.transforms, self.priors, self.joint_prior,
                                  self.estimate_sigma, self.sigma_prior, self.relative)


def _problem(model, x, y, params0, priors, sigma, sigma_prior, transforms, relative, jacobian_model, fit_options):
    """Check everything :func:`sample_posterior` is given (ValueError naming the argument or path); a _Problem."""
    fit_options = {"method": "levenberg_marquardt", "max_steps": 200} | dict(fit_options or {})
    unknown = set(fit_options) - {"method", "learning_rate", "max_steps", "grad_tol", "loss_tol", "polish_steps"}
    if unknown:
        raise ValueError(f"fit_options has keys least_squares does not take here: {sorted(unknown)}")
    y_np = np.asarray(y, dtype=np.float64)
    if sigma is not None:
        try:
            s = np.broadcast_to(np.asarray(sigma, dtype=np.float64), y_np.shape)
        except (ValueError, TypeError):
            raise ValueError(f"sigma must be a number > 0 or an array broadcasting to y's shape {y_np.shape}, or "
                             f"None (sampled); got {sigma!r}") from None
        bad = np.argwhere(~(np.isfinite(s) & (s > 0)))
        if bad.size:
            raise ValueError(f"sigma must be finite and > 0 (units of y); got {s[tuple(bad[0])]!r} at index "
                             f"{tuple(int(i) for i in bad[0])}")
        sigma = np.array(s)
    # params0 and y first (every transform Free: nothing about ranges yet), then the priors per leaf (or one joint
    # callable), then the transforms: a leaf without one takes its prior's (Uniform: Bounded, on x > 0: Positive)
    _check_fit_inputs(model, x, y, params0, Free(), None, relative, fit_options["method"])
    leaf_priors = None
    if callable(priors) and not isinstance(priors, _PRIORS + (dict,)):
        joint = priors
    else:
        joint = None
        leaf_priors = (_Flat(),) * len(_walk(params0)[1]) if priors is None else _per_leaf(params0, priors, "priors",
                                lambda p: isinstance(p, _PRIORS) or (callable(p) and not isinstance(p, dict)),
                                "Normal, LogNormal, Uniform, HalfNormal, Jeffreys or a callable value -> log density",
                                lambda where, p: p.check(where) if isinstance(p, _PRIORS) else None, _Flat())
        leaf_priors = tuple(p if isinstance(p, _PRIORS + (_Flat,)) else _Callable(p) for p in leaf_priors)
    given = (_UNSET,) * len(_walk(params0)[1]) if transforms is None else _leaf_transforms(params0, transforms,
                                                                                           default=_UNSET)
    if leaf_priors is not None:
        given = tuple(_NATURAL.get(type(p), lambda p: Free())(p) if t is _UNSET else t
                      for t, p in zip(given, leaf_priors))
    transforms_tree = _leaves_as_tree(params0, tuple(Free() if t is _UNSET else t for t in given))
    layout, starts, leaf_transforms = _check_fit_inputs(model, x, y, params0, transforms_tree, None, relative,
                                                        fit_options["method"])
    if leaf_priors is None:
        leaf_priors = tuple(_Flat() for _ in leaf_transforms)
    for path, t, p in zip(layout.paths, leaf_transforms, leaf_priors):
        low, high = p.support()
        t_low, t_high = t.range()
        if t_low < low or t_high > high:
            raise ValueError(f"priors{path} is {p!r}, on ({low:g}, {high:g}), but transforms{path} is {t!r}, which "
                             f"reaches ({t_low:g}, {t_high:g}): give a transform inside the prior's support (or "
                             "none: the prior's own)")
    if sigma is None:
        sigma_prior = Jeffreys() if sigma_prior is None else sigma_prior
        if not isinstance(sigma_prior, (Jeffreys, HalfNormal, LogNormal, Uniform)):
            raise ValueError(f"sigma_prior must be Jeffreys(), HalfNormal, LogNormal or Uniform (sigma > 0); got "
                             f"{sigma_prior!r}")
        sigma_prior.check("sigma_prior")
        if sigma_prior.support()[0] < 0:
            raise ValueError(f"sigma_prior must be on sigma > 0; got {sigma_prior!r}")
        if "sigma" in layout.names:
            raise ValueError("params0 has a parameter named 'sigma', the sampled noise's name: rename it, or give "
                             "sigma")
        if y_np.size <= len(layout.names):
            raise ValueError(f"y has {y_np.size} observations for {len(layout.names)} parameters and an unknown "
                             "sigma: give sigma, or more observations")
    elif sigma_prior is not None:
        raise ValueError("sigma_prior is for a sampled sigma (sigma=None); sigma is given")
    return _Problem(model, jacobian_model, layout, leaf_transforms, transforms_tree, leaf_priors, joint, sigma,
                    sigma_prior, bool(relative), fit_options)


def _leaves_as_tree(node, per_leaf):
    """Per-leaf items (reading order) in ``node``'s structure: a transforms tree for least_squares."""
    items = iter(per_leaf)

    def build(node):
        kids = _children(node)
        if kids is None:
            return next(items)
        built = [build(child) for _, child in kids]
        if type(node) is dict:
            return dict(zip(node.keys(), built))
        return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(node, is_leaf=lambda c: c is not node), built)

    return build(node)


@dataclasses.dataclass(frozen=True)
class _PosteriorProgram:
    fit: object  # the _FitProgram
    laplace: Callable  # (theta_hat, x, y, w) -> [p, p] covariance in theta
    start: Callable  # (theta_hat, cov_theta, sigma_hat, n) -> (u_hat, cov_u)
    sample: Callable  # (keys, u_hat, cov_u, x, y, w, num_warmup, num_samples, warmup, target, doublings) -> ...
    constrained_all: Callable  # u draws [..., d] -> theta (and sigma) draws
    initial_u: Callable  # params0 -> u0


@functools.lru_cache(maxsize=16)
def _posterior_program(fit, layout, transforms, priors, joint_prior, estimate_sigma, sigma_prior, relative):
    import blackjax
    from blackjax.adaptation.step_size import dual_averaging_adaptation

    p = len(layout.names)
    sigma_transform = Positive()

    def log_prior(theta):
        if joint_prior is not None:
            return jnp.asarray(joint_prior(layout.unflatten(theta)), theta.dtype)
        return sum(jnp.sum(prior.log_density(theta[a:b])) for (a, b), prior in zip(layout.bounds, priors))

    def constrained_all(u):
        theta = jnp.concatenate([t.forward(u[..., a:b]) for (a, b), t in zip(layout.bounds, transforms)], axis=-1)
        if estimate_sigma:
            theta = jnp.concatenate([theta, sigma_transform.forward(u[..., p:])], axis=-1)
        return theta

    def log_jacobian(u):
        total = sum(jnp.sum(t.log_det_jacobian(u[a:b])) for (a, b), t in zip(layout.bounds, transforms))
        if estimate_sigma:
            total = total + jnp.sum(sigma_transform.log_det_jacobian(u[p:]))
        return total

    def log_posterior(u, x, y, w):
        """ln p(u | y) + const: the Gaussian likelihood of the weighted residuals, the priors, the Jacobian."""
        theta_all = constrained_all(u)
        theta = theta_all[:p]
        r, _ = fit.residuals(theta, x, y, w)
        scale = jnp.abs(y) if relative else 1.0
        log_sigma_i = -jnp.log(jnp.ravel(jnp.broadcast_to(w / scale, y.shape)))
        if estimate_sigma:
            s = theta_all[p]
            log_lik = -0.5 * jnp.sum((r / s) ** 2) - r.shape[0] * jnp.log(s) - jnp.sum(log_sigma_i)
            log_prior_sigma = sigma_prior.log_density(s)
        else:
            log_lik = -0.5 * jnp.sum(r**2) - jnp.sum(log_sigma_i)
            log_prior_sigma = 0.0
        value = log_lik + log_prior(theta) + log_prior_sigma + log_jacobian(u)
        return jnp.where(jnp.isfinite(value), value, -jnp.inf)

    @jax.jit
    def laplace(theta_hat, x, y, w):
        r, jac, _ = fit.residuals_and_jacobian(theta_hat, x, y, w)
        precision = jac.T @ jac - jax.hessian(log_prior)(theta_hat)
        return jnp.linalg.inv(precision)

    @jax.jit
    def start(theta_hat, cov_theta, sigma_hat, n):
        u_hat = jnp.concatenate([jnp.ravel(t.inverse(theta_hat[a:b])) for (a, b), t in zip(layout.bounds, transforms)])
        slope = jnp.exp(jnp.concatenate([jnp.ravel(t.log_det_jacobian(u_hat[a:b]))
                                         for (a, b), t in zip(layout.bounds, transforms)]))
        cov_u = cov_theta / jnp.outer(slope, slope)
        if estimate_sigma:
            u_s = sigma_transform.inverse(jnp.asarray(sigma_hat, u_hat.dtype))
            # sd of sigma ~ sigma / sqrt(2 n) (the Laplace approximation of a normal scale)
            var_u = (sigma_hat**2 / (2 * n)) / jnp.exp(sigma_transform.log_det_jacobian(u_s)) ** 2
            u_hat = jnp.concatenate([u_hat, u_s[None]])
            cov_u = jax.scipy.linalg.block_diag(cov_u, var_u[None, None])
        cov_u = 0.5 * (cov_u + cov_u.T)
        return u_hat, cov_u

    @functools.partial(jax.jit, static_argnums=(6, 7, 8, 9, 10))
    def sample(keys, u_hat, cov_u, x, y, w, num_warmup, num_samples, warmup, target, doublings):
        def logdensity(u):
            return log_posterior(u, x, y, w)

        chol = jnp.linalg.cholesky(cov_u)

        def chain(key):
            k_start, k_warm, k_draw = jax.random.split(key, 3)
            u0 = u_hat + chol @ jax.random.normal(k_start, u_hat.shape, u_hat.dtype)
            if warmup == "window":
                adapt = blackjax.window_adaptation(blackjax.nuts, logdensity, is_mass_matrix_diagonal=False,
                                                   initial_inverse_mass_matrix=cov_u, target_acceptance_rate=target,
                                                   max_num_doublings=doublings,
                                                   adaptation_info_fn=_steps_only)
                (state, parameters), info = adapt.run(k_warm, u0, num_steps=max(num_warmup, 1))
                warm_steps = jnp.sum(info.num_integration_steps)
                step_size, inverse_mass = parameters["step_size"], parameters["inverse_mass_matrix"]
                kernel = blackjax.nuts(logdensity, step_size, inverse_mass, max_num_doublings=doublings)

                def draw(state, k):
                    state, info = kernel.step(k, state)
                    return state, (state.position, info.num_integration_steps, info.is_divergent)

                _, (positions, counts, divergent) = jax.lax.scan(draw, state, jax.random.split(k_draw, num_samples))
                return positions, jnp.sum(counts), jnp.sum(divergent), warm_steps, step_size
            # one NUTS kernel for warmup and draws (one compilation): the step size adapts while `adapting`, then
            # stays at dual averaging's final average
            init, update, final = dual_averaging_adaptation(target)

            def step(carry, inputs):
                state, da = carry
                k, adapting = inputs
                eps = jnp.where(adapting, jnp.exp(da.log_step_size), final(da))
                state, info = blackjax.nuts(logdensity, eps, cov_u, max_num_doublings=doublings).step(k, state)
                da = jax.tree_util.tree_map(lambda new, old: jnp.where(adapting, new, old),
                                            update(da, info.acceptance_rate), da)
                return (state, da), (state.position, info.num_integration_steps, info.is_divergent)

            adapting = jnp.arange(num_warmup + num_samples) < num_warmup
            state = blackjax.nuts(logdensity, 1.0, cov_u).init(u0)
            (_, da), (positions, counts, divergent) = jax.lax.scan(
                step, (state, init(1.0)), (jax.random.split(k_warm, num_warmup + num_samples), adapting))
            step_size = final(da) if num_warmup else jnp.asarray(1.0, u0.dtype)
            return (positions[num_warmup:], jnp.sum(counts[num_warmup:]), jnp.sum(divergent[num_warmup:]),
                    jnp.sum(counts[:num_warmup]), step_size)

        return jax.vmap(chain)(keys)

    def initial_u(params0):
        starts = _Layout.of(params0)[1]
        return jnp.concatenate([jnp.ravel(t.inverse(jnp.asarray(starts[a:b]))) for (a, b), t in zip(layout.bounds,
                                                                                                     transforms)])

    return _PosteriorProgram(fit, laplace, start, sample, jax.jit(constrained_all), initial_u)


def _steps_only(state, info, adaptation_state):
    """What window adaptation keeps per step: the leapfrog steps (counted as model evaluations)."""
    return info


__all__ = ["HalfNormal", "Jeffreys", "LogNormal", "Normal", "PosteriorResult", "PosteriorWarning", "Uniform",
           "sample_posterior", "sample_posterior_replicates"]
