"""Rizza & Galati (2024): Eqs. 1, 4, 5, 6 against their tables (fitting/data/rizza_galati2024).

Table 9 must follow exactly (with gamma rounded to two decimals first, as the
paper did); Tables 2, 4, 5 do not as printed (SPEC.md), so their deviations
are measured and bounded here rather than forced.
"""

import csv
import pathlib

import jax
import numpy as np
import pytest

import fitting.data.rizza_galati2024

from sintercond.laws import tortuosity as tt

DATA = pathlib.Path(fitting.data.rizza_galati2024.__file__).parent
U0_CELL, S0_CELL = 80.0**3, 6 * 80.0**2  # 512,000 um^3, 38,400 um^2
U0_PB, S0_PB, SSS_PB, N_PB = 150.0**3, 6 * 150.0**2, 70714.0, 0.66


def _table(name):
    with open(DATA / name) as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) if k != "couple_id" else 0.0 for r in rows]) for k in rows[0]}, rows


def _round2(x):
    """Two decimals, half up (as the paper rounds: 0.925 -> 0.93; np.round gives 0.92)."""
    return np.floor(np.asarray(x) * 100 + 0.5) / 100


def _lambda0(times):
    t, _, lam = tt.ti6al4v_conductivity_table()
    return np.array([lam[np.argmin(np.abs(t - x))] for x in times])


def test_equations_and_limits():
    assert float(tt.gamma_factor(0.0, 80.0)) == 1.0
    assert float(tt.gamma_factor(3.84, 80.0)) == pytest.approx(0.904, rel=1e-15)
    # Eq. 2 limits: tau^2 -> 1 for a dense solid (n = 1, full faces, no constriction) ...
    assert float(tt.tortuosity_squared(1.0, 1.0, 1.0, 8.0)) == 1.0
    # ... and lambda_pow -> lambda_0 there; n -> 0 sends tau^2 -> infinity for phi > 1
    assert float(tt.powder_conductivity(1.0, 1.0, 16.72)) == 16.72
    assert float(tt.tortuosity_squared(0.5, 0.9, 1e-6, 3.0)) > 1e11
    # differentiable in phi (a fittable exponent): d tau^2 / d phi = -ln(n) tau^2
    g = jax.grad(lambda p: tt.tortuosity_squared(0.8, 0.9, 0.7, p))(8.0)
    assert float(g) == pytest.approx(-np.log(0.7) * float(tt.tortuosity_squared(0.8, 0.9, 0.7, 8.0)), rel=1e-13)


def test_preheating_ramp_reproduces_table_1():
    t, temperature, _ = tt.ti6al4v_conductivity_table()
    np.testing.assert_allclose(tt.preheating_temperature(t, at_step_end=True), temperature, atol=1.0)
    assert float(tt.preheating_temperature(0.0)) == 845.0 and float(tt.preheating_temperature(9.5)) == 1273.0
    ramp = np.asarray(tt.preheating_temperature(np.linspace(0, 9.5, 500)))
    assert np.all(np.diff(ramp) >= 0) and len(np.unique(ramp)) == 26  # 25 steps


def test_lambda0_table_interpolation():
    t, temperature, lam = tt.ti6al4v_conductivity_table()
    np.testing.assert_allclose(tt.ti6al4v_conductivity(temperature), lam, rtol=1e-15)
    assert np.isnan(tt.ti6al4v_conductivity(300.0))


def test_table9_pb_exactly():
    values, rows = _table("table9_pb.csv")
    necks, neck_rows = _table("table8_pb_necks.csv")
    sss = SSS_PB / S0_PB
    for time in ("0.5", "3.5", "6.5", "9.5"):
        diameter = np.maximum(necks["D1_um"], necks["D2_um"])
        gamma = np.asarray(tt.gamma_factor(necks[f"x_{time}"], diameter))
        np.testing.assert_allclose(_round2(gamma), values[f"gamma_{time}"], atol=1e-9)
        tau2 = np.asarray(tt.tortuosity_squared(sss, _round2(gamma), N_PB, 8.0))
        np.testing.assert_allclose(tau2, values[f"tau2_{time}"], atol=0.005 + 1e-9)
        lam = np.asarray(tt.powder_conductivity(N_PB, tau2, _lambda0([float(time)])[0]))
        np.testing.assert_allclose(lam, values[f"lambda_{time}"], atol=0.005 + 1e-9)
    # the paper's means: 0.86, 1.12, 1.28, 1.44 W/(m K) at 0.5, 3.5, 6.5, 9.5 s
    means = [values[f"lambda_{t}"].mean() for t in ("0.5", "3.5", "6.5", "9.5")]
    np.testing.assert_allclose(means, [0.86, 1.12, 1.28, 1.44], atol=0.01)


def test_table2_sc_to_about_one_percent():
    v, _ = _table("table2_sc.csv")
    n = v["U0s_um3"] / U0_CELL
    gamma = np.asarray(tt.gamma_factor(v["x_um"], 80.0))
    # 0.865 (x = 5.40) is printed as 0.86 although 0.925 becomes 0.93 in Table 9
    np.testing.assert_allclose(_round2(gamma), v["gamma"], atol=0.01 + 1e-9)
    tau2 = np.asarray(tt.tortuosity_squared(v["Sss_um2"] / S0_CELL, v["gamma"], n, 3.0))
    lam = np.asarray(tt.powder_conductivity(n, tau2, _lambda0(v["time_s"])))
    # measured: tau^2 within 1.3 %, lambda within 1.4 % of the printed values
    assert np.max(np.abs(tau2 / v["tau2"] - 1)) < 0.015
    assert np.max(np.abs(lam / v["lambda_pow"] - 1)) < 0.015


def test_tables4_5_bcc_do_not_follow_as_printed():
    for name in ("table4_bcc_couple1.csv", "table5_bcc_couple2.csv"):
        v, _ = _table(name)
        n = v["U0s_um3"] / U0_CELL
        tau2 = np.asarray(tt.tortuosity_squared(v["Sss_um2"] / S0_CELL, v["gamma"], n, 8.0))
        deviation = np.abs(tau2 / v["tau2"] - 1)
        # SPEC.md: up to ~13 % off; reported, not forced
        assert 0.005 < deviation.max() < 0.15


def test_preheating_ramp_holds_each_step_until_its_end():
    """Eq. 6's int() is a floor: within step k (of 25, each 0.38 s, 17.12 K) the temperature is
    T_bp + k 17.12 K all the way to the step's end. Mutant "ramp floor" (round instead) jumped a step early
    in the second half of every step, which the table's step-end values and the end points did not see."""
    width, rise = 9.5 / 25, (1273.0 - 845.0) / 25
    for k in (0, 3, 24):
        for part in (0.1, 0.6, 0.95):
            assert float(tt.preheating_temperature((k + part) * width)) == pytest.approx(845.0 + k * rise, rel=1e-14)
