"""Sintering kinetics (sintercond.laws.sintering) against closed forms, limits and finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sintercond as sc
from sintercond.laws import sintering as st
from sintercond.laws import tortuosity as tt
from sintercond.laws.neck import NeckStatus

RADIUS_PAIRS = [(40e-6, 40e-6), (1e-3, 3e-3), (29.3e-6, 40e-6), (1.0, 1000.0), (1000.0, 1.0), (20e-6, 100e-6)]
GB = {"A": 1e-16, "activation_energy": 120.0, "dihedral_angle": 150.0}


def _central(f, x, rel=1e-5):
    step = rel * abs(x) if x != 0 else rel
    return (f(x + step) - f(x - step)) / (2 * step)


# --------------------------------------------------------------------------
# geometry


@pytest.mark.slow
@pytest.mark.parametrize("r_i, r_j", RADIUS_PAIRS)
def test_neck_overlap_inverts_neck_radius_over_the_domain(r_i, r_j):
    h_max = float(sc.max_overlap(r_i, r_j))
    h = h_max * np.concatenate([np.geomspace(1e-12, 1e-2, 9), np.linspace(0.02, 0.98, 25), [0.999, 0.99999, 1.0]])
    a = np.asarray(sc.neck_radius(r_i, r_j, h))
    np.testing.assert_allclose(np.asarray(st.neck_overlap(a, r_i, r_j)), h, rtol=1e-14, atol=0)
    # and the other way round, from necks
    r_min = min(r_i, r_j)
    necks = r_min * np.concatenate([np.geomspace(1e-9, 1e-2, 8), np.linspace(0.05, 0.95, 19), [0.9999, 1.0]])
    np.testing.assert_allclose(np.asarray(sc.neck_radius(r_i, r_j, st.neck_overlap(necks, r_i, r_j))), necks,
                               rtol=1e-14, atol=0)


def test_neck_overlap_limits():
    r = 40e-6
    assert float(st.neck_overlap(r, r, r)) == pytest.approx(2 * r / 3, rel=1e-15)  # Rojek Eqs. 18-19
    assert float(st.neck_overlap(0.0, r, 2 * r)) == 0.0
    for r_i, r_j in RADIUS_PAIRS:
        r_star = 2 * r_i * r_j / (r_i + r_j)
        a = 1e-5 * min(r_i, r_j)
        # Coble, a^2 = 2 r* h, to O((a/r)^2)
        assert float(st.neck_overlap(a, r_i, r_j)) == pytest.approx(a * a / (2 * r_star), rel=1e-9)
        assert float(st.neck_overlap_slope(a, r_i, r_j)) == pytest.approx(a / r_star, rel=1e-9)
    assert float(st.neck_overlap_slope(r, r, r)) == pytest.approx(8 / 3, rel=1e-15)


@pytest.mark.parametrize("r_i, r_j", RADIUS_PAIRS)
@pytest.mark.parametrize("fraction", [1e-4, 0.05, 0.5, 0.95])
def test_neck_overlap_gradient_equals_central_differences(r_i, r_j, fraction):
    a = fraction * min(r_i, r_j)
    grads = jax.grad(st.neck_overlap, argnums=(0, 1, 2))(a, r_i, r_j)
    args = [a, r_i, r_j]
    for k, g in enumerate(grads):
        def along(x, k=k):
            return float(st.neck_overlap(*[x if m == k else v for m, v in enumerate(args)]))
        assert float(g) == pytest.approx(_central(along, args[k]), rel=2e-7, abs=1e-12 * abs(float(g)) + 1e-300)


def test_neck_overlap_gradient_is_finite_at_both_ends():
    r = 1.0
    for r_j in (1.0, 2.5):
        g0 = jax.grad(st.neck_overlap, argnums=(0, 1, 2))(0.0, r, r_j)
        assert all(float(v) == 0.0 for v in g0)
        g1 = jax.grad(st.neck_overlap, argnums=(0, 1, 2))(r, r, r_j)
        assert all(np.isfinite(float(v)) for v in g1)
        # the slope at a = min(r) is the limit of the slopes inside (H'' diverges there like 1/s, so
        # secants from inside approach it like sqrt(step), not like step)
        inside = float(jax.grad(st.neck_overlap)(r * (1 - 1e-10), r, r_j))
        assert float(g1[0]) == pytest.approx(inside, rel=1e-4)
        errors = [abs((float(st.neck_overlap(r, r, r_j)) - float(st.neck_overlap(r - step, r, r_j))) / step
                      - float(g1[0])) for step in (1e-4, 1e-6)]
        assert 0.05 < errors[1] / errors[0] < 0.2  # sqrt(step): 10x smaller per 100x smaller step
    # second derivative at a = 0 exists (Coble: 1/r*)
    assert float(jax.grad(jax.grad(st.neck_overlap))(0.0, 1.0, 1.0)) == pytest.approx(1.0, rel=1e-12)


def test_neck_overlap_out_of_domain_is_nan_with_a_status_and_zero_gradient():
    a = jnp.array([0.0, 0.5, 1.0, 1.01, -0.1, jnp.nan])
    h = st.neck_overlap(a, 1.0, 1.0)
    assert np.all(np.isfinite(np.asarray(h[:3]))) and np.all(np.isnan(np.asarray(h[3:])))
    status = np.asarray(st.neck_overlap_status(a, 1.0, 1.0))
    assert status.tolist() == [NeckStatus.NO_CONTACT, NeckStatus.OK, NeckStatus.OK, NeckStatus.BEYOND_MAX_OVERLAP,
                               NeckStatus.INVALID_INPUT, NeckStatus.INVALID_INPUT]
    g = jax.grad(lambda x: jnp.sum(jnp.where(jnp.isnan(st.neck_overlap(x, 1.0, 1.0)), 0.0,
                                             st.neck_overlap(x, 1.0, 1.0))))(a)
    assert np.all(np.isfinite(np.asarray(g)))
    assert np.isnan(float(st.neck_overlap(0.5, -1.0, 1.0)))


def test_neck_overlap_float32():
    a = np.linspace(0.0, 1.0, 101, dtype=np.float32) * np.float32(40e-6)
    h32 = np.asarray(st.neck_overlap(a, np.float32(40e-6), np.float32(55e-6)))
    assert h32.dtype == np.float32
    h64 = np.asarray(st.neck_overlap(a.astype(np.float64), 40e-6, 55e-6))
    np.testing.assert_allclose(h32, h64, rtol=5e-7, atol=0)


def test_validate_neck_overlap_inputs_names_the_argument():
    with pytest.raises(ValueError, match=r"a must be <= min\(r_i, r_j\)"):
        st.validate_neck_overlap_inputs(1.2, 1.0, 2.0)
    with pytest.raises(ValueError, match="a must be finite and >= 0"):
        st.validate_neck_overlap_inputs(-0.1, 1.0, 2.0)
    with pytest.raises(ValueError, match="r_j must be finite and > 0"):
        st.validate_neck_overlap_inputs(0.1, 1.0, -2.0)
    st.validate_neck_overlap_inputs([0.0, 1.0], 1.0, 2.0)


# --------------------------------------------------------------------------
# kinetic laws and growth


def _isothermal(n_intervals, t_end, temperature):
    return np.full(n_intervals, temperature), np.full(n_intervals, t_end / n_intervals)


def test_isothermal_grain_boundary_growth_follows_the_sixth_power_law_at_small_necks():
    """(a/r)^6 ~ t, with the prefactor 192 r*^2 (A/T) exp(-Q/RT) (1 - cos(psi/2)) of the point contact."""
    r_i, r_j, temperature = 40e-6, 60e-6, 1000.0
    times = np.geomspace(1e-9, 1e-5, 9)
    durations = np.diff(np.concatenate([[0.0], times]))
    a = np.asarray(st.grow_neck("grain_boundary", 0.0, r_i, r_j, np.full(times.size, temperature), durations, GB))
    assert a[-1] / min(r_i, r_j) < 0.02  # small necks throughout
    r_star = 2 * r_i * r_j / (r_i + r_j)
    psi = np.deg2rad(GB["dihedral_angle"])
    prefactor = (192 * r_star**2 * GB["A"] / temperature * np.exp(-GB["activation_energy"] * 1e3 /
                                                                  (8.314462618 * temperature)) * (1 - np.cos(psi / 2)))
    # a^6 / t tends to the prefactor as a -> 0. Beyond it: the force's a sin(psi/2) term and a / H'(a) =
    # r* (1 - kappa a^2), kappa = r* sum_k 1 / (6 r_k^3) (the series of s_k = sqrt(r_k^2 - a^2)), make the rate
    # c0 (1 + beta a)(1 - kappa a^2); integrated in u = a^6,
    # a^6 / (c0 t) = 1 + (6/7) beta a + [(36/49) beta^2 - (3/4)(beta^2 + kappa)] a^2 + O(a^3)
    ratio = a**6 / times / prefactor
    beta = np.sin(psi / 2) / (4 * r_star * (1 - np.cos(psi / 2)))
    kappa = r_star * (1 / (6 * r_i**3) + 1 / (6 * r_j**3))
    assert ratio[0] - 1 < 1e-3
    series = 1 + 6 / 7 * beta * a + (36 / 49 * beta**2 - 0.75 * (beta**2 + kappa)) * a**2
    np.testing.assert_allclose(ratio, series, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(st.small_neck_grain_boundary(times, r_i, r_j, temperature, GB)) / a,
                               ratio ** (-1 / 6), rtol=1e-13)
    # the slope of log a against log t is 1/6 where the necks are smallest
    slope = np.polyfit(np.log(times[:4]), np.log(a[:4]), 1)[0]
    assert slope == pytest.approx(1 / 6, rel=2e-3)


@pytest.mark.slow
def test_grain_boundary_growth_is_exact_per_interval_and_stops_at_the_equilibrium_neck():
    r_i, r_j = 40e-6, 29.3e-6
    temperature = 1100.0
    # exact for a constant temperature: one interval equals the same time cut into 1000 pieces (whose
    # errors would add up if the scheme had any), from a point contact and from a grown neck
    for a0 in (0.0, 0.2 * r_j):
        one = float(st.grow_neck("grain_boundary", a0, r_i, r_j, [temperature], [16.0], GB)[-1])
        many = float(st.grow_neck("grain_boundary", a0, r_i, r_j, np.full(1000, temperature), np.full(1000, 0.016),
                                  GB)[-1])
        assert one / r_j > 0.25 and one == pytest.approx(many, rel=1e-13)
        # the quadrature and the Newton steps converge to it
        errors = [abs(float(st.grow_neck("grain_boundary", a0, r_i, r_j, [temperature], [16.0], GB,
                                         quadrature_nodes=q)[-1]) / one - 1) for q in (3, 4, 6)]
        assert errors[0] < 1e-4 and errors[1] < 1e-6 and errors[2] < 1e-10  # spectral in the node count
        newton = [abs(float(st.grow_neck("grain_boundary", a0, r_i, r_j, [temperature], [16.0], GB,
                                         newton_iterations=k)[-1]) / one - 1) for k in (1, 2)]
        assert newton[0] < 1e-5 and newton[1] < 1e-13  # quadratic
    # long enough: the neck stops at the smaller sphere's r sin(psi/2) and stays there
    long = np.asarray(st.grow_neck("grain_boundary", 0.0, r_i, r_j, np.full(20, 1273.0), np.full(20, 1e4), GB))
    a_eq = r_j * np.sin(np.deg2rad(75.0))
    assert long[-1] == pytest.approx(a_eq, rel=1e-14)
    assert np.all(np.diff(long) >= 0) and np.all(long <= a_eq * (1 + 1e-14))
    assert int(st.growth_status("grain_boundary", long[-1], r_i, r_j, np.full(20, 1273.0), np.full(20, 1e4),
                                GB)) == \
        st.GrowthStatus.AT_CAP


def test_exact_laws_integrate_their_closed_forms_along_a_ramp():
    durations, temperatures, index = st.preheating_history(np.arange(0.5, 10.0, 1.0))
    r_i, r_j = 40e-6, 29.3e-6
    r_star = 2 * r_i * r_j / (r_i + r_j)
    R = 8.314462618
    power = {"K0": 1e-24, "activation_energy": 30.0, "exponent": 4.0, "size_exponent": -1.0,
             "reference_radius": 40e-6}
    a = np.asarray(st.grow_neck("power_law", 0.0, r_i, r_j, temperatures, durations, power))[index]
    integral = np.cumsum(durations * np.exp(-30e3 / (R * temperatures)))[index]
    np.testing.assert_allclose(a, (1e-24 * (r_star / 40e-6) ** -1.0 * integral) ** 0.25, rtol=1e-13)
    visc = {"surface_energy": 0.03, "viscosity": 1e6, "activation_energy": 50.0}
    a = np.asarray(st.grow_neck("viscous", 1e-6, r_i, r_j, temperatures, durations, visc))[index]
    viscosity = 1e6 * np.exp(50e3 / (R * temperatures))
    a_squared = 1e-12 + np.cumsum(durations * 1.5 * 0.03 * r_star / viscosity)[index]
    np.testing.assert_allclose(a, np.sqrt(a_squared), rtol=1e-13)


def test_preheating_history_is_rizza_galatis_ramp_with_the_erratum():
    times = np.arange(0.5, 10.0, 1.0)
    durations, temperatures, index = st.preheating_history(times)
    ends = np.cumsum(durations)
    np.testing.assert_allclose(ends[index], times, rtol=1e-14)
    assert ends[-1] == pytest.approx(9.5, rel=1e-14)
    # the temperature held at each reading is Table 1's (within 1 K), and the ramp's at_step_end reading
    table_temperature = tt.ti6al4v_conductivity_table()[1]
    np.testing.assert_allclose(temperatures[index], table_temperature, atol=1.0)
    mid = ends - 0.5 * durations
    np.testing.assert_allclose(temperatures, np.asarray(tt.preheating_temperature(mid, at_step_end=True)), rtol=1e-14)
    assert np.unique(temperatures).size == 25 and np.all(np.diff(temperatures) >= 0)


@pytest.mark.parametrize("law, params, a0", [
    ("grain_boundary", GB, 0.0),
    ("grain_boundary", GB, 5e-6),
    ("power_law", {"K0": 1e-24, "activation_energy": 30.0, "exponent": 4.0, "size_exponent": -1.0}, 0.0),
    ("viscous", {"surface_energy": 0.03, "viscosity": 1e6, "activation_energy": 50.0}, 0.0),
])
@pytest.mark.slow
def test_grown_neck_gradients_equal_central_differences(law, params, a0):
    durations, temperatures, index = st.preheating_history(np.arange(0.5, 10.0, 1.0))
    r_i, r_j = 40e-6, 29.3e-6

    def end_neck(p, temps=temperatures):
        return st.grow_neck(law, a0, r_i, r_j, temps, durations, p)[-1]

    grads = jax.grad(end_neck)({k: float(v) for k, v in params.items()})
    for name, value in params.items():
        g = float(grads[name])
        assert np.isfinite(g)
        fd = _central(lambda x, name=name: float(end_neck({**params, name: x})), float(value), rel=1e-6)
        assert g == pytest.approx(fd, rel=1e-6, abs=1e-9 * abs(float(end_neck(params))) / max(abs(value), 1e-30))
    # and the temperatures (each interval's)
    g_temps = np.asarray(jax.grad(lambda t: end_neck(params, t))(jnp.asarray(temperatures)))
    assert np.all(np.isfinite(g_temps)) and np.all(g_temps >= 0)
    for k in (0, 7, len(temperatures) - 1):
        def along(x, k=k):
            t = temperatures.copy()
            t[k] = x
            return float(end_neck(params, t))
        assert g_temps[k] == pytest.approx(_central(along, temperatures[k], rel=1e-6), rel=1e-6)


@pytest.mark.slow
def test_point_contact_growth_has_no_nan_in_values_or_gradients():
    durations = np.array([0.0, 1e-9, 0.1])
    temperatures = np.array([900.0, 900.0, 900.0])
    for law, params in (("grain_boundary", GB), ("power_law", {}), ("viscous", {})):
        p = st.law_params(law, params)
        value = st.grow_neck(law, 0.0, 40e-6, 40e-6, temperatures, durations, p)
        assert np.all(np.isfinite(np.asarray(value))) and float(value[0]) == 0.0
        grads = jax.grad(lambda q: st.grow_neck(law, 0.0, 40e-6, 40e-6, temperatures, durations, q)[1])(p)
        assert all(np.isfinite(float(g)) for g in grads.values())
        g_r = jax.grad(lambda r: st.grow_neck(law, 0.0, r, 40e-6, temperatures, durations, p)[0])(40e-6)
        assert float(g_r) == 0.0


@pytest.mark.slow
def test_growth_vmaps_over_a_million_pairs_and_matches_single_pairs():
    rng = np.random.default_rng(0)
    n = 1_000_000
    r_i, r_j = rng.uniform(20e-6, 60e-6, (2, n))
    temperatures = np.linspace(900.0, 1200.0, 5)[:, None] + rng.uniform(-20, 20, (5, n))
    durations = np.full(5, 0.5)
    a = np.asarray(st.grow_neck("grain_boundary", 0.0, r_i, r_j, temperatures, durations, GB))
    assert a.shape == (5, n) and np.all(np.isfinite(a)) and np.all(np.diff(a, axis=0) > 0)
    for k in (0, 12345, n - 1):
        single = st.grow_neck("grain_boundary", 0.0, r_i[k], r_j[k], temperatures[:, k], durations, GB)
        np.testing.assert_allclose(np.asarray(single), a[:, k], rtol=1e-14)


@pytest.mark.slow
def test_growth_float32_agrees_with_float64():
    durations, temperatures, _ = st.preheating_history(np.arange(0.5, 10.0, 1.0))
    r = np.linspace(20e-6, 60e-6, 64)
    a64 = np.asarray(st.grow_neck("grain_boundary", 0.0, r, 40e-6, temperatures[:, None], durations, GB))
    a32 = np.asarray(st.grow_neck("grain_boundary", np.float32(0.0), r.astype(np.float32), np.float32(40e-6),
                                  temperatures[:, None].astype(np.float32), durations.astype(np.float32),
                                  {k: np.float32(v) for k, v in GB.items()}))
    assert a32.dtype == np.float32
    np.testing.assert_allclose(a32, a64, rtol=2e-6)


def test_growth_to_a_large_neck_matches_an_independent_ode_solution():
    """From a/r = 0.05 to about 0.9 at 1200 K against SciPy's solve_ivp on da/dt = rate(a) / (6 a^5), the rate
    written out from the module docstring with H'(a) = 1 / (da/dh) from neck.neck_radius's implicit derivative."""
    from scipy.integrate import solve_ivp

    r_i, r_j, temperature = 40e-6, 29.3e-6, 1273.0
    r_star = 2 * r_i * r_j / (r_i + r_j)
    psi = np.deg2rad(GB["dihedral_angle"]) / 2
    mobility = GB["A"] / temperature * np.exp(-GB["activation_energy"] * 1e3 / (8.314462618 * temperature))
    slope_of = jax.jit(lambda a: 1.0 / jax.grad(sc.neck_radius, argnums=2)(r_i, r_j, st.neck_overlap(a, r_i, r_j)))

    def rhs(_, y):
        a = y[0]
        slope = float(slope_of(a))
        rate = 48 * (a / slope) * mobility * (4 * r_star * (1 - np.cos(psi)) + a * np.sin(psi))
        return [rate / (6 * a**5)]

    a0, t_end = 0.05 * r_j, 2500.0
    reference = solve_ivp(rhs, (0.0, t_end), [a0], method="DOP853", rtol=1e-12, atol=0).y[0, -1]
    assert 0.85 < reference / r_j < 0.95
    ours = st.grow_neck("grain_boundary", a0, r_i, r_j, np.full(25, temperature), np.full(25, t_end / 25), GB)[-1]
    assert float(ours) == pytest.approx(reference, rel=1e-9)


@pytest.mark.slow
def test_temperatures_per_interval_broadcast_over_pairs_and_parameters_per_pair():
    """A 1-D history applies to every pair (it was broadcast along the pair axis when there were as many pairs as
    intervals); parameters may be given per pair, and one bad pair's parameter spoils only that pair."""
    temps, durations = np.array([900.0, 1200.0]), np.array([1.0, 1.0])
    power = {"K0": 1e-12, "activation_energy": 30.0, "exponent": 2.0}
    single = np.asarray(st.grow_neck("power_law", 0.0, 40e-6, 40e-6, temps, durations, power))
    both = np.asarray(st.grow_neck("power_law", 0.0, np.full(2, 40e-6), 40e-6, temps, durations, power))
    np.testing.assert_allclose(both, np.stack([single, single], axis=1), rtol=1e-15)
    angles = np.array([100.0, 170.0, 150.0])
    per_pair = np.asarray(st.grow_neck("grain_boundary", 0.0, np.full(3, 40e-6), 29.3e-6, np.full(5, 1200.0),
                                       np.full(5, 2.0), {**GB, "dihedral_angle": angles}))
    for k, angle in enumerate(angles):
        alone = np.asarray(st.grow_neck("grain_boundary", 0.0, 40e-6, 29.3e-6, np.full(5, 1200.0), np.full(5, 2.0),
                                        {**GB, "dihedral_angle": angle}))
        np.testing.assert_allclose(per_pair[:, k], alone, rtol=1e-13)
    run = jax.jit(lambda q: st.grow_neck("grain_boundary", 0.0, np.full(3, 40e-6), 29.3e-6, np.full(5, 1200.0),
                                         np.full(5, 2.0), {**GB, "activation_energy": q}))
    mixed = np.asarray(run(jnp.array([120.0, -1.0, 120.0])))
    assert np.all(np.isfinite(mixed[:, [0, 2]])) and np.all(np.isnan(mixed[:, 1]))


def test_float32_growth_of_submicron_necks_at_the_default_parameters():
    """a^6 in m^6 underflows float32 below a ~ 0.5 um (1e-38): the integration works in units of min(r)."""
    temps, durations = np.full(4, 1000.0), np.full(4, 1.0)
    a64 = np.asarray(st.grow_neck("grain_boundary", 0.0, 40e-6, 40e-6, temps, durations))
    a32 = np.asarray(st.grow_neck("grain_boundary", np.float32(0.0), np.float32(40e-6), np.float32(40e-6),
                                  temps.astype(np.float32), durations.astype(np.float32),
                                  {k: np.float32(v) for k, v in st.KINETIC_LAWS["grain_boundary"].default_params.items()}))
    assert 0.3e-6 < a64[0] < a64[-1] < 1e-6
    np.testing.assert_allclose(a32, a64, rtol=2e-6)


def test_growth_rate_is_nan_outside_the_domain():
    rates = np.asarray(st.growth_rate("grain_boundary", np.array([-1e-6, 1e-6, 39e-6, 41e-6]), 40e-6, 40e-6, 1000.0))
    assert np.isnan(rates[0]) and rates[1] > 0 and rates[2] == 0.0 and np.isnan(rates[3])  # 39 um: past the cap
    assert np.isnan(float(st.growth_rate("grain_boundary", 1e-6, 40e-6, 40e-6, -5.0)))
    over = np.asarray(st.growth_rate("power_law", np.array([30e-6, 45e-6]), 40e-6, 60e-6, 1000.0,
                                     {"max_neck_ratio": 1.5}))
    assert over[0] > 0 and np.isnan(over[1])  # max_neck_ratio > 1 cannot grow a neck beyond min(r)


def test_pair_temperature_is_the_mean():
    assert float(st.pair_temperature(900.0, 1000.0)) == 950.0
    harmonic = 2 * 900.0 * 1000.0 / 1900.0
    assert 950.0 - harmonic == pytest.approx((100.0**2) / (4 * 950.0), rel=1e-12)


def test_grain_boundary_a_from_material_constants():
    # A = Omega delta_b D_0b gamma_s / k_B
    assert float(st.grain_boundary_a(1.8e-29, 5e-15, 1.5)) == pytest.approx(1.8e-29 * 5e-15 * 1.5 / 1.380649e-23,
                                                                           rel=1e-15)


# --------------------------------------------------------------------------
# bad input


@pytest.mark.parametrize("kwargs, message", [
    ({"r_i": -1e-6}, "r_i must be finite and > 0"),
    ({"r_j": np.nan}, "r_j must be finite and > 0"),
    ({"a0": 50e-6}, r"a0 must be <= min\(r_i, r_j\)"),
    ({"a0": -1e-6}, "a0 must be finite and >= 0"),
    ({"temperatures": np.array([900.0, 0.0])}, r"temperatures \(K\) must be finite and > 0"),
    ({"temperatures": np.array([900.0, -5.0])}, r"temperatures \(K\) must be finite and > 0"),
    ({"durations": np.array([0.1, -0.1])}, r"durations \(s\) must be finite and >= 0"),
    ({"durations": np.array([0.1, 0.1, 0.1])}, "temperatures must have one row per interval"),
    ({"params": {"A": -1.0}}, r"params\['A'\] of kinetic law 'grain_boundary' \(m\^4 K/s\) must be finite and > 0"),
    ({"params": {"activation_energy": -10.0}}, r"params\['activation_energy'\].*must be finite and >= 0"),
    ({"params": {"dihedral_angle": 200.0}}, r"dihedral_angle'\] must be in \(0, 180\]"),
    ({"params": {"Q": 100.0}}, "unknown parameter 'Q' of kinetic law 'grain_boundary'"),
    ({"law": "surface_diffusion"}, "law must be one of"),
    ({"quadrature_nodes": 0}, "quadrature_nodes must be an integer >= 1"),
    ({"newton_iterations": 2.5}, "newton_iterations must be an integer >= 1"),
])
def test_bad_growth_input_names_the_argument(kwargs, message):
    args = {"law": "grain_boundary", "a0": 0.0, "r_i": 40e-6, "r_j": 40e-6, "temperatures": np.array([900.0, 950.0]),
            "durations": np.array([0.1, 0.1]), "params": GB}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        st.grow_neck(args.pop("law"), args.pop("a0"), args.pop("r_i"), args.pop("r_j"), args.pop("temperatures"),
                     args.pop("durations"), args.pop("params"), **args)


def test_invalid_growth_under_jit_is_nan_with_a_status():
    a0 = jnp.array([0.0, 0.0, 0.0, 50e-6])
    temps = jnp.array([[900.0, -1.0, 900.0, 900.0]])
    r_i = jnp.array([40e-6, 40e-6, -40e-6, 40e-6])

    @jax.jit
    def run(a0, r_i, temps):
        a = st.grow_neck("grain_boundary", a0, r_i, 40e-6, temps, jnp.array([0.5]), GB)
        return a, st.growth_status("grain_boundary", a0, r_i, 40e-6, temps, jnp.array([0.5]), GB)

    a, status = run(a0, r_i, temps)
    assert np.isfinite(float(a[0, 0])) and np.all(np.isnan(np.asarray(a[0, 1:])))
    assert np.asarray(status).tolist() == [st.GrowthStatus.OK] + [st.GrowthStatus.INVALID_INPUT] * 3
