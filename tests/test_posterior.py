"""fitting.posterior: NUTS posteriors against closed forms, simulation-based calibration, and bad input.

References independent of the sampler: the conjugate normal-linear model's exact posterior (Gelman et al. 2013,
BDA3, Eq. 14.5 with a normal prior), binomial bands on the coverage of credible intervals over replicates drawn
from the prior (Talts et al. 2018), finite differences of the transforms.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("blackjax", reason="install the 'posterior' extra")
from scipy import stats  # noqa: E402

from fitting import posterior as fp  # noqa: E402
from fitting.core import Bounded, Free, Positive  # noqa: E402

X = np.linspace(-1.0, 1.0, 9)
SIGMA = 0.1 + 0.05 * np.abs(X)  # heteroscedastic, known
PRIOR_MEAN, PRIOR_SD = np.array([0.5, 1.0, -0.5]), np.array([2.0, 1.5, 3.0])


def quadratic(params, x):
    return params["a"] + params["slope"][0] * x + params["slope"][1] * x**2


def exact_posterior(y):
    """Mean and covariance of (a, slope0, slope1) for the linear-Gaussian model with independent normal priors."""
    design = np.stack([np.ones_like(X), X, X**2], axis=1)
    precision = design.T @ (design / SIGMA[:, None] ** 2) + np.diag(1 / PRIOR_SD**2)
    cov = np.linalg.inv(precision)
    mean = cov @ (design.T @ (y / SIGMA**2) + PRIOR_MEAN / PRIOR_SD**2)
    return mean, cov


def slope_prior(s):
    """The slope leaf is one array: its prior is a callable on the array (the sum of both normals)."""
    return fp.Normal(PRIOR_MEAN[1], PRIOR_SD[1]).log_density(s[0]) + fp.Normal(PRIOR_MEAN[2], PRIOR_SD[2]).log_density(s[1])


QUADRATIC_PRIORS = {"a": fp.Normal(PRIOR_MEAN[0], PRIOR_SD[0]), "slope": slope_prior}


def _quadratic_posterior(y, **options):
    return fp.sample_posterior(quadratic, jnp.asarray(X), y, {"a": 0.0, "slope": np.zeros(2)}, priors=QUADRATIC_PRIORS,
                               sigma=SIGMA, num_samples=500, num_warmup=150, seed=3, **options)


@pytest.fixture(scope="module")
def conjugate():
    rng = np.random.default_rng(7)
    y = 0.3 - 0.8 * X + 1.2 * X**2 + rng.normal(0, SIGMA)
    return y, _quadratic_posterior(y)


@pytest.mark.slow
def test_conjugate_normal_linear_posterior_matches_the_closed_form(conjugate):
    y, post = conjugate
    mean, cov = exact_posterior(y)
    # the Laplace approximation is exact for a linear-Gaussian model
    np.testing.assert_allclose(post.laplace_covariance, cov, rtol=1e-8, atol=1e-14)
    assert all(abs(r - 1) < 0.1 for r in post.laplace_ratio.values())
    draws = post.draws
    ess = np.array([post.ess[n] for n in post.names])
    sd = np.sqrt(np.diag(cov))
    # Monte Carlo error of the mean: sd / sqrt(ESS); 4 of them
    assert np.all(np.abs(draws.mean(axis=0) - mean) < 4 * sd / np.sqrt(ess)), (draws.mean(axis=0), mean)
    # the sd to within 4 of its Monte Carlo errors, sd / sqrt(2 ESS)
    assert np.all(np.abs(draws.std(axis=0, ddof=1) / sd - 1) < 4 / np.sqrt(2 * ess)), (draws.std(axis=0), sd)
    corr = cov / np.outer(sd, sd)
    assert np.all(np.abs(post.correlation() - corr) < 0.1)
    # draws in params0's structure, leading draw axis
    assert post.samples["a"].shape == (4 * 500,) and post.samples["slope"].shape == (4 * 500, 2)
    np.testing.assert_array_equal(post.samples["slope"][:, 1], draws[:, 2])
    assert post.names == ("a", "slope[0]", "slope[1]")
    assert all(v < 1.01 for v in post.rhat.values()) and post.divergences == 0 and not post.warnings
    assert post.evaluations["sampling"] >= 4 * 500 and post.sigma_samples is None


@pytest.mark.slow
def test_failed_diagnostics_warn_with_a_named_class(conjugate):
    y, _ = conjugate
    with pytest.warns(fp.PosteriorWarning, match="effective sample size below"):
        post = _quadratic_posterior(y, min_ess=10**9)
    assert post.warnings
    with pytest.warns(fp.PosteriorWarning, match="R-hat above"):
        _quadratic_posterior(y, rhat_max=0.5)


def decay(params, x):
    return params["A"] * jnp.exp(-params["k"] * x)


DECAY_X = np.linspace(0.0, 2.0, 10)
DECAY_PRIORS = {"A": fp.Normal(1.0, 0.2), "k": fp.LogNormal(0.0, 0.3)}
SIGMA_PRIOR = fp.LogNormal(math.log(0.05), 0.2)


@pytest.mark.slow
def test_simulation_based_calibration_covers_at_the_nominal_rate():
    """160 replicates drawn from the prior (A normal, k lognormal through its Positive transform, sigma sampled):
    each central 50 % and 90 % interval covers the truth at its nominal rate within a 99.9 % binomial band."""
    replicates = 160
    rng = np.random.default_rng(11)
    truth = np.stack([rng.normal(1.0, 0.2, replicates), np.exp(rng.normal(0.0, 0.3, replicates)),
                      np.exp(rng.normal(math.log(0.05), 0.2, replicates))], axis=1)
    ys = truth[:, :1] * np.exp(-truth[:, 1:2] * DECAY_X) + truth[:, 2:] * rng.normal(size=(replicates, DECAY_X.size))
    draws = fp.sample_posterior_replicates(decay, jnp.asarray(DECAY_X), ys, {"A": 1.0, "k": 1.0}, priors=DECAY_PRIORS,
                                           sigma=None, sigma_prior=SIGMA_PRIOR, num_samples=150, num_warmup=60,
                                           num_chains=2, seed=5)
    assert draws.shape == (replicates, 300, 3) and np.all(np.isfinite(draws))
    for level in (0.5, 0.9):
        lo, hi = np.quantile(draws, [(1 - level) / 2, (1 + level) / 2], axis=1)
        covered = np.sum((lo <= truth) & (truth <= hi), axis=0)
        band = stats.binom.interval(0.999, replicates, level)
        assert np.all((band[0] <= covered) & (covered <= band[1])), (level, covered, band)


@pytest.mark.parametrize("transform", [Free(), Positive(), Bounded(-2.0, 5.0)])
def test_log_det_jacobian_is_the_log_derivative_of_forward(transform):
    u = jnp.linspace(-4.0, 4.0, 17)
    h = 1e-6
    fd = (transform.forward(u + h) - transform.forward(u - h)) / (2 * h)
    np.testing.assert_allclose(np.exp(transform.log_det_jacobian(u)), fd, rtol=1e-7)
    low, high = transform.range()
    assert np.all((transform.forward(u) > low) & (transform.forward(u) < high))


@pytest.mark.parametrize("prior, x", [(fp.Normal(1.0, 2.0), [-1.0, 0.5, 3.0]), (fp.LogNormal(0.3, 0.7), [0.2, 1.0, 4.0]),
                                      (fp.Uniform(-1.0, 2.0), [-0.5, 0.0, 1.9]), (fp.HalfNormal(1.5), [0.1, 1.0, 3.0])])
def test_named_priors_are_scipys_densities(prior, x):
    reference = {fp.Normal: lambda p: stats.norm(p.mean, p.sd),
                 fp.LogNormal: lambda p: stats.lognorm(p.sigma, scale=math.exp(p.mu)),
                 fp.Uniform: lambda p: stats.uniform(p.low, p.high - p.low), fp.HalfNormal: lambda p: stats.halfnorm(scale=p.sd)}
    np.testing.assert_allclose(prior.log_density(jnp.asarray(x)), reference[type(prior)](prior).logpdf(x), rtol=1e-12)


def test_a_prior_picks_its_transform_and_the_fit_starts_inside():
    problem = fp._problem(decay, DECAY_X, np.ones(10), {"A": 1.0, "k": 1.0},
                          {"A": fp.Uniform(0.0, 3.0), "k": fp.LogNormal(0.0, 1.0)}, 0.1, None, None, False, None, None)
    assert problem.transforms == (Bounded(0.0, 3.0), Positive())


@pytest.mark.parametrize("kwargs, message", [
    ({"priors": {"A": fp.Normal(0.0, -1.0)}}, r"priors\['A'\].sd must be a finite number > 0"),
    ({"priors": {"B": fp.Normal(0.0, 1.0)}}, r"priors has keys that are not in params0: \['B'\]"),
    ({"priors": {"k": "wide"}}, r"priors\['k'\] must be Normal, LogNormal"),
    ({"priors": {"k": fp.LogNormal(0.0, 1.0)}, "transforms": {"k": Free()}},
     r"priors\['k'\] is LogNormal.*transforms\['k'\] is Free"),
    ({"priors": {"A": fp.Uniform(0.0, 2.0)}, "transforms": {"A": Bounded(-1.0, 2.0)}}, r"priors\['A'\] is Uniform"),
    ({"priors": {"k": fp.LogNormal(0.0, 1.0)}, "params0": {"A": 1.0, "k": -1.0}},
     r"params0\['k'\] must be > 0 for its Positive transform"),
    ({"sigma": -0.1}, "sigma must be finite and > 0"),
    ({"sigma": np.ones(3)}, "sigma must be a number > 0 or an array broadcasting to y's shape"),
    ({"sigma": None, "sigma_prior": fp.Normal(0.0, 1.0)}, "sigma_prior must be Jeffreys"),
    ({"sigma": 0.1, "sigma_prior": fp.Jeffreys()}, "sigma_prior is for a sampled sigma"),
    ({"sigma": None, "params0": {"A": 1.0, "k": 1.0, "sigma": 1.0}}, "params0 has a parameter named 'sigma'"),
    ({"num_chains": 1}, "num_chains must be an integer >= 2"),
    ({"num_samples": 10.0}, "num_samples must be an integer >= 2"),
    ({"warmup": "long"}, "warmup must be 'step_size' or 'window'"),
    ({"seed": -1}, r"seed must be an integer in \[0, 2\*\*32\)"),
    ({"fit_options": {"weights": 2.0}}, "fit_options has keys least_squares does not take here"),
    ({"y": np.full(10, np.nan)}, "y must be finite"),
])
def test_bad_input_is_named_before_compiling(kwargs, message, monkeypatch):
    def no_compile(*args, **kw):
        raise AssertionError("compiled before checking the input")

    monkeypatch.setattr(fp, "_posterior_program", no_compile)
    monkeypatch.setattr(fp, "least_squares", no_compile)
    arguments = {"params0": {"A": 1.0, "k": 1.0}, "y": np.ones(10), "sigma": 0.1, **kwargs}
    params0, y = arguments.pop("params0"), arguments.pop("y")
    with pytest.raises(ValueError, match=message):
        fp.sample_posterior(decay, DECAY_X, y, params0, **arguments)


def test_fitting_exports_sample_posterior_lazily():
    import fitting

    assert fitting.sample_posterior is fp.sample_posterior and fitting.Normal is fp.Normal
    with pytest.raises(AttributeError):
        fitting.no_such_name  # noqa: B018


def test_diagnostics_match_their_definitions_on_known_chains():
    """Split R-hat of chains with shifted means exceeds 1 by the closed form; the ESS of an AR(1) chain is
    ``N (1 - phi) / (1 + phi)`` (its integrated autocorrelation time)."""
    rng = np.random.default_rng(0)
    m, n, phi = 4, 4000, 0.6
    e = rng.normal(size=(m, n))
    ar = np.zeros((m, n))
    for t in range(n):
        ar[:, t] = phi * ar[:, t - 1] + e[:, t] if t else e[:, 0] / math.sqrt(1 - phi**2)
    rhat, ess = fp._diagnostics(ar[..., None])
    expected = m * n * (1 - phi) / (1 + phi)
    assert abs(ess[0] / expected - 1) < 0.15 and abs(rhat[0] - 1) < 0.01
    white = rng.normal(size=(m, n, 1)) + np.arange(m)[:, None, None]  # chains 1 apart, unit variance
    rhat, _ = fp._diagnostics(white)
    # between-chain variance of the split halves: var of (0,0,1,1,2,2,3,3) = 10/7 against 1 within
    half = n // 2
    expected = math.sqrt(((half - 1) / half + 10 / 7) / 1.0)
    assert abs(rhat[0] - expected) < 0.02

