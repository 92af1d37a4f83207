"""Sintering kinetics: rate evaluations and neck growth per second, integration error, float32.

Usage: python benchmarks/sintering_kinetics.py [--pairs N]

* Rates: ``sintering.growth_rate`` of the grain-boundary law on N random pairs
  (radii 20-60 um, necks up to 0.9 of the equilibrium neck, 900-1300 K),
  jitted, float64 and float32, against the same formula vectorised in NumPy.
* Growth: ``sintering.grow_neck`` from point contacts along Rizza & Galati's
  Eq. 6 ramp (26 intervals to 9.5 s) on the same pairs, against the obvious
  alternative, classical Runge-Kutta in ``u = a^6`` written in NumPy with m
  substeps per interval.
* Error against step size: the grain-boundary neck at 9.5 s on the ramp for
  one 80-58.6 um couple (the law fitted to Rizza & Galati's 80-58.6 series),
  against a reference with 64 nodes and 12 Newton steps: sintercond's
  quadrature nodes and Newton steps, and RK4 in ``u`` with m substeps (its
  order falls at the point contact, where the rate is not smooth in ``u``).
  The power law and viscous flow are integrated in closed form (tests).
* float32 against float64 on the growth of all N pairs.

Times: minimum over repeats after a warm-up (``_common.best_time``). Prints the
tables and rewrites the ``sintering_kinetics`` section of benchmarks/RESULTS.md.
"""

import argparse

import jax
import jax.numpy as jnp
import numpy as np
from _common import best_time, command_line, markdown_table, write_section

from sintercond.laws import sintering as st

R = st.GAS_CONSTANT
GB = {"A": 1.2e-20, "activation_energy": 37.0, "dihedral_angle": 150.0}  # about the 80-58.6 fit


def numpy_rate(a, r_i, r_j, temperature, params=GB):
    """The grain-boundary ``d(a^6)/dt`` written out in NumPy (module docstring of sintercond.laws.sintering)."""
    psi = np.deg2rad(params["dihedral_angle"]) / 2
    r_star = 2 * r_i * r_j / (r_i + r_j)
    slope = 0.0
    for r in (r_i, r_j):
        s = np.sqrt((r - a) * (r + a))
        slope = slope + (2 * r + s) / (3 * (r + s) ** 2)
    a_over_h = 1 / (2 * slope)
    mobility = params["A"] / temperature * np.exp(-1e3 * params["activation_energy"] / (R * temperature))
    rate = 48 * a_over_h * mobility * (4 * r_star * (1 - np.cos(psi)) + a * np.sin(psi))
    return np.where(a < np.minimum(r_i, r_j) * np.sin(psi), rate, 0.0)


def numpy_rk4_growth(r_i, r_j, temperatures, durations, substeps, params=GB):
    """RK4 in ``u = a^6`` with ``substeps`` per interval, clipped at the equilibrium neck."""
    u_cap = (np.minimum(r_i, r_j) * np.sin(np.deg2rad(params["dihedral_angle"]) / 2)) ** 6
    u = np.zeros_like(r_i)
    out = []
    for temperature, dt in zip(temperatures, durations):
        h = dt / substeps
        for _ in range(substeps):
            def f(u):
                return numpy_rate(np.maximum(u, 0) ** (1 / 6), r_i, r_j, temperature, params)
            k1 = f(u)
            k2 = f(u + 0.5 * h * k1)
            k3 = f(u + 0.5 * h * k2)
            k4 = f(u + h * k3)
            u = np.minimum(u + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), u_cap)
        out.append(u ** (1 / 6))
    return np.array(out)


def pairs(n, seed=0):
    rng = np.random.default_rng(seed)
    r_i, r_j = rng.uniform(20e-6, 60e-6, (2, n))
    cap = np.minimum(r_i, r_j) * np.sin(np.deg2rad(75.0))
    return r_i, r_j, rng.uniform(0, 0.9, n) * cap, rng.uniform(900.0, 1300.0, n)


def throughput(n):
    r_i, r_j, a, temperature = pairs(n)
    durations, temperatures, _ = st.preheating_history([9.5])
    rows = []
    rate64 = jax.jit(lambda *v: st.growth_rate("grain_boundary", *v, GB))
    f32 = {k: np.float32(v) for k, v in GB.items()}
    rate32 = jax.jit(lambda *v: st.growth_rate("grain_boundary", *v, f32))
    args64 = [jnp.asarray(v) for v in (a, r_i, r_j, temperature)]
    args32 = [v.astype(jnp.float32) for v in args64]
    t_np = min(best_time(numpy_rate, a, r_i, r_j, temperature, repeats=5) for _ in range(1))
    t64, t32 = best_time(rate64, *args64), best_time(rate32, *args32)
    reference = numpy_rate(a, r_i, r_j, temperature)
    err64 = np.max(np.abs(np.asarray(rate64(*args64)) / reference - 1))
    err32 = np.max(np.abs(np.asarray(rate32(*args32)) / reference - 1))
    rows += [["rate, NumPy float64", f"{n / t_np:.3g}", f"{1e3 * t_np:.1f}", "-"],
             ["rate, JAX float64", f"{n / t64:.3g}", f"{1e3 * t64:.1f}", f"{err64:.1e}"],
             ["rate, JAX float32", f"{n / t32:.3g}", f"{1e3 * t32:.1f}", f"{err32:.1e}"]]

    grow64 = jax.jit(lambda ri, rj: st.grow_neck("grain_boundary", 0.0, ri, rj, temperatures[:, None], durations, GB))
    t_grow = best_time(grow64, args64[1], args64[2], repeats=5)
    a64 = np.asarray(grow64(args64[1], args64[2]))
    grow32 = jax.jit(lambda ri, rj: st.grow_neck("grain_boundary", np.float32(0), ri, rj,
                                                 temperatures[:, None].astype(np.float32),
                                                 durations.astype(np.float32), f32))
    t_grow32 = best_time(grow32, args32[1], args32[2], repeats=5)
    a32 = np.asarray(grow32(args32[1], args32[2]))
    err_32 = np.max(np.abs(a32[-1] / a64[-1] - 1))
    m = 4
    subset = slice(0, n // 10)  # NumPy RK4 on a tenth of the pairs (its time scales linearly)
    t_rk = best_time(numpy_rk4_growth, r_i[subset], r_j[subset], temperatures, durations, m, repeats=2) * 10
    a_rk = numpy_rk4_growth(r_i[subset], r_j[subset], temperatures, durations, m)
    err_rk = np.max(np.abs(a_rk[-1] / a64[-1, subset] - 1))
    intervals = len(durations)
    rows += [[f"growth on the ramp ({intervals} intervals), JAX float64 (exact per interval)",
              f"{n * intervals / t_grow:.3g}", f"{1e3 * t_grow:.0f}", "reference"],
             ["growth, JAX float32", f"{n * intervals / t_grow32:.3g}", f"{1e3 * t_grow32:.0f}", f"{err_32:.1e}"],
             [f"growth, NumPy RK4 in u, {m} substeps", f"{n * intervals / t_rk:.3g}", f"{1e3 * t_rk:.0f}",
              f"{err_rk:.1e}"]]
    return rows


def step_error():
    durations, temperatures, _ = st.preheating_history([9.5])
    r_i, r_j = 40e-6, 29.3e-6
    reference = float(st.grow_neck("grain_boundary", 0.0, r_i, r_j, temperatures, durations, GB,
                                   quadrature_nodes=64, newton_iterations=12)[-1])
    rows = []
    for q in (2, 3, 4, 6, 8):
        a = float(st.grow_neck("grain_boundary", 0.0, r_i, r_j, temperatures, durations, GB, quadrature_nodes=q)[-1])
        rows.append([f"sintercond, {q} nodes, 4 Newton steps", f"{abs(a / reference - 1):.1e}"])
    for k in (1, 2, 3):
        a = float(st.grow_neck("grain_boundary", 0.0, r_i, r_j, temperatures, durations, GB,
                               newton_iterations=k)[-1])
        rows.append([f"sintercond, 8 nodes, {k} Newton step{'s' * (k > 1)}", f"{abs(a / reference - 1):.1e}"])
    errors = []
    for m in (1, 2, 4, 8, 16, 64):
        a = numpy_rk4_growth(np.array([r_i]), np.array([r_j]), temperatures, durations, m)[-1, 0]
        errors.append(abs(a / reference - 1))
        rows.append([f"RK4 in u, {m} substeps per interval (step {9.5 / len(durations) / m:.3g} s at most)",
                     f"{errors[-1]:.1e}"])
    order = np.log2(errors[-2] / errors[-1]) / 2
    return rows, reference, order


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=1_000_000)
    args = parser.parse_args()
    rows = throughput(args.pairs)
    table = markdown_table(["what", "pair-evaluations / s", "ms per call", "max rel. difference"], rows)
    error_rows, reference, order = step_error()
    errors = markdown_table(["integration", "rel. error of a(9.5 s)"], error_rows)
    body = (f"### Sintering kinetics: rates and growth ({args.pairs:,} pairs)\n\n"
            "Grain-boundary law (A = 1.2e-20 m^4 K/s, Q = 37 kJ/mol, psi = 150 deg). Growth: from point contacts "
            "along Rizza & Galati's Eq. 6 ramp; the pair-evaluations are pairs times intervals. Differences: "
            "rates against the NumPy formula, growth against sintercond's float64 neck at 9.5 s.\n\n"
            f"{table}\n\n"
            f"Error against step size, one 80-58.6 um couple at 9.5 s (a = {reference * 1e6:.4f} um; reference "
            f"64 nodes, 12 Newton steps). RK4 in u converges at order {order:.2f} between its last two step sizes "
            "(4 for a smooth rate): the rate is not smooth in u at the point contact.\n\n"
            f"{errors}\n")
    print(body)
    write_section("sintering_kinetics", command_line(), body)


if __name__ == "__main__":
    main()
