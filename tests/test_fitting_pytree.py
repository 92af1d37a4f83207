"""least_squares over a parameter pytree (issue 24): nested dicts, array leaves, tuples, against closed forms.

The references are independent of the fitting code: ordinary least squares of a polynomial in closed form
(values and the covariance ``s^2 (X'X)^-1``), the linearised standard error ``s / ||t exp(-k t)||`` of a decay
rate fitted alone, and the flat-dict API, which the pytree layout must reproduce.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from fitting.core import Bounded, Free, Positive, least_squares

X = np.linspace(-1.0, 1.0, 30)
DESIGN = np.stack([np.ones_like(X), X, X**2], axis=1)  # columns: intercept, slope, quadratic
TRUTH = {"line": {"slope": -0.7, "intercept": 1.3}, "curve": {"quadratic": 0.45}}
START = {"line": {"slope": 0.0, "intercept": 0.0}, "curve": {"quadratic": 0.0}}
ORDER = [1, 0, 2]  # the design's columns in params0's reading order (slope, intercept, quadratic)


def nested_quadratic(p, x):
    return p["line"]["intercept"] + p["line"]["slope"] * x + p["curve"]["quadratic"] * x**2


def flat_quadratic(p, x):
    return p["intercept"] + p["slope"] * x + p["quadratic"] * x**2


def noisy_quadratic(seed=3, sigma=0.05):
    clean = DESIGN @ np.array([TRUTH["line"]["intercept"], TRUTH["line"]["slope"], TRUTH["curve"]["quadratic"]])
    return clean + sigma * np.random.default_rng(seed).standard_normal(X.shape)


def ols(y):
    """Closed-form least squares of the quadratic: (values, covariance), in params0's reading order."""
    beta, *_ = np.linalg.lstsq(DESIGN, y, rcond=None)
    s2 = np.sum((y - DESIGN @ beta) ** 2) / (len(y) - 3)
    covariance = s2 * np.linalg.inv(DESIGN.T @ DESIGN)
    return beta[ORDER], covariance[np.ix_(ORDER, ORDER)]


@pytest.mark.parametrize("method", ["levenberg_marquardt", "adam"])
def test_nested_dict_fit_recovers_a_noise_free_truth(method):
    y = nested_quadratic(TRUTH, X)
    fit = least_squares(nested_quadratic, X, y, START, method=method, max_steps=200 if method != "adam" else 5000)
    assert fit.names == ("line.slope", "line.intercept", "curve.quadratic")  # reading order, not JAX's sorted one
    assert set(fit.params) == {"line", "curve"} and list(fit.params["line"]) == ["slope", "intercept"]
    for group, values in TRUTH.items():
        for key, value in values.items():
            assert fit.params[group][key] == pytest.approx(value, abs=1e-8)
            assert isinstance(fit.params[group][key], float) and isinstance(fit.stderr[group][key], float)


def test_nested_dict_fit_has_the_closed_form_values_and_errors_and_the_flat_fits():
    """With seeded noise: the closed-form OLS values and covariance, the truth within 3 standard errors, and the
    same standard errors as the flat-dict fit of the same model (to round-off)."""
    y = noisy_quadratic()
    fit = least_squares(nested_quadratic, X, y, START, method="levenberg_marquardt", max_steps=200)
    beta, covariance = ols(y)
    flat_values = [fit.params["line"]["slope"], fit.params["line"]["intercept"], fit.params["curve"]["quadratic"]]
    flat_errors = [fit.stderr["line"]["slope"], fit.stderr["line"]["intercept"], fit.stderr["curve"]["quadratic"]]
    np.testing.assert_allclose(flat_values, beta, rtol=1e-8)
    np.testing.assert_allclose(fit.covariance, covariance, rtol=1e-6)
    np.testing.assert_allclose(flat_errors, np.sqrt(np.diag(covariance)), rtol=1e-6)
    truth = [TRUTH["line"]["slope"], TRUTH["line"]["intercept"], TRUTH["curve"]["quadratic"]]
    assert np.all(np.abs(np.array(flat_values) - truth) < 3 * np.array(flat_errors))

    flat = least_squares(flat_quadratic, X, y, {"slope": 0.0, "intercept": 0.0, "quadratic": 0.0},
                         method="levenberg_marquardt", max_steps=200)
    np.testing.assert_allclose(flat_errors, [flat.stderr[k] for k in ("slope", "intercept", "quadratic")], rtol=1e-12)
    np.testing.assert_allclose(fit.covariance, flat.covariance, rtol=1e-12)
    assert fit.flat_params == pytest.approx({"line.slope": flat.params["slope"],
                                             "line.intercept": flat.params["intercept"],
                                             "curve.quadratic": flat.params["quadratic"]}, rel=1e-12)
    assert fit.residual_std == pytest.approx(flat.residual_std, rel=1e-12)


def test_a_flat_dict_keeps_its_key_order_in_names_covariance_and_the_models_input():
    """Bug it guards: JAX flattens a dict in sorted key order; taken as is, a flat dict's names and covariance
    would come out sorted, while fitting.softening reads the covariance by the position of its own keys."""
    y = noisy_quadratic(seed=5)
    seen = []

    def model(p, x):
        seen.append(list(p))
        return flat_quadratic(p, x)

    fit = least_squares(model, X, y, {"slope": 0.0, "intercept": 0.0, "quadratic": 0.0},
                        method="levenberg_marquardt", max_steps=200)
    beta, covariance = ols(y)
    assert fit.names == ("slope", "intercept", "quadratic") and list(fit.params) == list(fit.names)
    assert all(keys == ["slope", "intercept", "quadratic"] for keys in seen) and seen
    np.testing.assert_allclose(np.diag(fit.covariance), np.diag(covariance), rtol=1e-6)
    assert fit.flat_params == fit.params and fit.flat_stderr == fit.stderr


def test_transforms_in_the_tree_and_on_a_subtree():
    """A exp(-k t) + c with the decay's transforms given per leaf and, equivalently, once for the whole subtree."""
    t = jnp.linspace(0.0, 2.0, 40)

    def model(p, t):
        return p["decay"]["A"] * jnp.exp(-p["decay"]["k"] * t) + p["offset"]

    truth = {"decay": {"A": 3.0, "k": 1.7}, "offset": 0.4}
    start = {"decay": {"A": 1.0, "k": 1.0}, "offset": 0.0}
    y = model(truth, t)
    for transforms in ({"decay": {"A": Positive(), "k": Bounded(0.1, 10.0)}, "offset": Free()}, {"decay": Positive()}):
        fit = least_squares(model, t, y, start, transforms, method="levenberg_marquardt", max_steps=200)
        assert fit.params["decay"]["A"] == pytest.approx(3.0, rel=1e-8), transforms
        assert fit.params["decay"]["k"] == pytest.approx(1.7, rel=1e-8), transforms
        assert fit.params["offset"] == pytest.approx(0.4, rel=1e-8), transforms


T = np.linspace(0.0, 3.0, 25)
RATES = np.array([0.5, 1.3, 2.9])
WHICH = np.repeat(np.arange(3), len(T))  # the dataset of each observation


def decays(p, x):
    """Three datasets y = exp(-k_i t), concatenated: ``p["k"]`` a 3-vector (or a tuple of three)."""
    t, which = x
    return jnp.exp(-jnp.stack(p["k"])[which] * t) if isinstance(p["k"], tuple) else jnp.exp(-p["k"][which] * t)


def flat_decays(p, x):
    return decays({"k": jnp.stack([p["k0"], p["k1"], p["k2"]])}, x)


def noisy_decays(seed=11, sigma=0.01):
    x = (np.tile(T, 3), WHICH)
    return x, np.exp(-RATES[WHICH] * x[0]) + sigma * np.random.default_rng(seed).standard_normal(WHICH.shape)


def test_an_array_leaf_recovers_the_vector_with_its_closed_form_errors():
    x, y = noisy_decays()
    clean = least_squares(decays, x, np.exp(-RATES[WHICH] * x[0]), {"k": np.ones(3)}, {"k": Positive()},
                          method="levenberg_marquardt", max_steps=200)
    np.testing.assert_allclose(clean.params["k"], RATES, rtol=1e-8)

    fit = least_squares(decays, x, y, {"k": np.ones(3)}, {"k": Positive()}, method="levenberg_marquardt",
                        max_steps=200)
    k, se = fit.params["k"], fit.stderr["k"]
    assert isinstance(k, np.ndarray) and k.shape == (3,) and se.shape == (3,)
    assert fit.names == ("k[0]", "k[1]", "k[2]")
    # each rate sees only its own dataset: s / ||d exp(-k t) / dk|| at the fitted k, covariance diagonal
    s = np.sqrt(np.sum((y - np.exp(-k[WHICH] * x[0])) ** 2) / (len(y) - 3))
    np.testing.assert_allclose(se, [s / np.linalg.norm(T * np.exp(-ki * T)) for ki in k], rtol=1e-6)
    off_diagonal = fit.covariance - np.diag(np.diag(fit.covariance))
    assert np.max(np.abs(off_diagonal)) < 1e-10 * np.max(np.diag(fit.covariance))
    assert np.all(np.abs(k - RATES) < 3 * se)
    low, high = fit.intervals()
    np.testing.assert_allclose(low["k"], k - 1.959964 * se, rtol=1e-14)
    np.testing.assert_allclose(high["k"], k + 1.959964 * se, rtol=1e-14)
    assert fit.flat_stderr == {f"k[{i}]": float(se[i]) for i in range(3)}
    np.testing.assert_array_equal(fit.to_tree(np.sqrt(np.diag(fit.covariance)))["k"], se)
    with pytest.raises(ValueError, match=r"one value per fitted scalar, shape \(3,\)"):
        fit.to_tree(np.zeros(2))


@pytest.mark.parametrize("method", ["levenberg_marquardt", "adam"])
def test_array_leaf_tuple_and_flat_dict_are_the_same_fit(method):
    """The flat API as the reference: the same three rates as one array leaf, as a tuple and as three keys."""
    x, y = noisy_decays(seed=2)
    options = {"method": method, "max_steps": 200 if method == "levenberg_marquardt" else 3000}
    flat = least_squares(flat_decays, x, y, {"k0": 1.0, "k1": 1.0, "k2": 1.0},
                         {"k0": Positive(), "k1": Positive(), "k2": Positive()}, **options)
    reference = [flat.params[f"k{i}"] for i in range(3)]
    array = least_squares(decays, x, y, {"k": np.ones(3)}, {"k": Positive()}, **options)
    as_tuple = least_squares(decays, x, y, {"k": (1.0, 1.0, 1.0)}, {"k": (Positive(),) * 3}, **options)
    assert as_tuple.names == array.names == ("k[0]", "k[1]", "k[2]") and isinstance(as_tuple.params["k"], tuple)
    for fit, values in ((array, array.params["k"]), (as_tuple, as_tuple.params["k"])):
        np.testing.assert_allclose(values, reference, rtol=1e-12)
        np.testing.assert_allclose(fit.covariance, flat.covariance, rtol=1e-10)
        assert fit.steps == flat.steps
    assert np.all(np.abs(np.array(reference) - RATES) < 3 * np.array([flat.stderr[f"k{i}"] for i in range(3)]))


def test_a_refit_of_the_same_tree_on_new_data_does_not_recompile():
    from fitting import core

    x, y = noisy_decays(seed=7)
    least_squares(decays, x, y, {"k": np.ones(3)}, {"k": Positive()}, method="levenberg_marquardt", max_steps=50)
    misses = core._fit_program.cache_info().misses
    least_squares(decays, x, noisy_decays(seed=8)[1], {"k": np.full(3, 2.0)}, {"k": Positive()},
                  method="levenberg_marquardt", max_steps=50)
    assert core._fit_program.cache_info().misses == misses


BAD = [
    ("transform key not in params0", {"s": {"A": 1.0}}, {"s": {"a": Positive()}},
     r"transforms\['s'\] has keys that are not in params0\['s'\]: \['a'\]"),
    ("transforms per element of an array", {"kappa": np.ones(3)}, {"kappa": [Positive()] * 3},
     r"transforms\['kappa'\] is a list but params0\['kappa'\] is one parameter"),
    ("transforms list too short", {"s": [1.0, 2.0]}, {"s": [Free()]}, r"transforms\['s'\] does not match params0\['s'\]"),
    ("transforms list for a dict", {"s": {"A": 1.0}}, {"s": [Free()]}, r"transforms\['s'\] does not match params0\['s'\]"),
    ("not a transform", {"s": {"A": 1.0}}, {"s": {"A": "positive"}}, r"transforms\['s'\]\['A'\] must be Free\(\)"),
    ("Bounded the wrong way round", {"s": {"A": 1.0}}, {"s": {"A": Bounded(2.0, 0.0)}},
     r"transforms\['s'\]\['A'\] must have finite numbers low < high"),
    ("Bounded above by inf", {"s": {"A": 1.0}}, {"s": Bounded(0.0, math.inf)},
     r"transforms\['s'\] must have finite numbers low < high"),
    ("inf leaf", {"s": {"A": math.inf}}, None, r"params0\['s'\]\['A'\] must be a finite number"),
    ("NaN element", {"kappa": np.array([1.0, np.nan, 2.0])}, None, r"params0\['kappa'\]\[1\] must be a finite number"),
    ("negative element, Positive", {"kappa": np.array([1.0, -2.0])}, {"kappa": Positive()},
     r"params0\['kappa'\]\[1\] must be > 0 for its Positive transform"),
    ("outside a subtree's bounds", {"s": {"A": 0.5, "B": 2.0}}, {"s": Bounded(0.0, 1.0)},
     r"params0\['s'\]\['B'\] must be in \(0, 1\)"),
    ("integer leaf", {"s": {"n": 6}}, None, r"params0\['s'\]\['n'\] is an integer"),
    ("integer array", {"k": np.arange(3)}, None, r"params0\['k'\] is an integer"),
    ("bool leaf", {"on": True}, None, r"params0\['on'\] is a bool"),
    ("string leaf", {"s": ["x"]}, None, r"params0\['s'\]\[0\] must be a finite number"),
    ("empty dict", {}, None, "params0 must be a non-empty"),
    ("empty tree", {"s": {}, "t": []}, None, "params0 must be a non-empty.*no parameters"),
    ("empty array", {"k": np.zeros(0)}, None, r"params0\['k'\] is an empty array"),
    ("not a tree", 1.0, None, "params0 must be a non-empty"),
    ("names collide", {"s.A": 1.0, "s": {"A": 2.0}}, None, r"params0\['s.A'\] and params0\['s'\]\['A'\].*'s.A'"),
    ("more scalars than observations", {"k": np.ones(50)}, None, "50 parameters: an underdetermined fit"),
]


@pytest.mark.parametrize("params0,transforms,match", [case[1:] for case in BAD], ids=[case[0] for case in BAD])
def test_a_bad_tree_is_refused_naming_the_path_before_the_model_is_traced(params0, transforms, match):
    traced = []

    def model(p, x):
        traced.append(p)
        return x

    with pytest.raises(ValueError, match=match):
        least_squares(model, X, X, params0, transforms)
    assert not traced
