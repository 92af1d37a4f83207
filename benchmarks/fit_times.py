"""Time to fit each parameter: optimiser steps and seconds (compile included and excluded).

Usage: python benchmarks/fit_times.py

* slope s of Rojek Eq. 40 against the FE data (fitting.slope);
* the smooth neck law's four coefficients (fitting.neck_law);
* phi against Rizza & Galati's Table 6 (fitting.phi), and phi with a lambda_0 scale;
* kappa from noisy probe histories of a flash experiment (fitting.inverse; 216-particle lattice,
  2000 steps): Adam with adjoint gradients, Levenberg-Marquardt with forward-mode Jacobians, and
  SciPy least_squares (trust region, finite-difference Jacobian) through the same jitted simulator.

Each fit is run twice: the first call compiles, the second reuses the compiled fit (least_squares
caches it per model and settings; the data are arguments). The phi rows' second call is mostly
the BCC geometry, recomputed on every fit_phi call. SciPy's loop is plain Python around one
jitted forward. Prints the table and rewrites its section of
benchmarks/RESULTS.md.
"""

import time

import jax
import numpy as np
import scipy.optimize
from _common import markdown_table, new_figure, number, save_figure, write_section

from fitting import inverse, neck_law
from fitting import phi as phi_fit
from fitting.reference import fe_neck_conductance
from fitting.slope import fit_slope


def timed(fn):
    t0 = time.perf_counter()
    result = fn()
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = fn()
    return result, first, time.perf_counter() - t0


def plot(rows):
    """Seconds of every fit, first call (compilation included) and second call, as grouped bars."""
    fig = new_figure(8, 4.2)
    ax = fig.subplots()
    y = np.arange(len(rows))[::-1]
    for offset, column, label in ((0.2, 3, "first call (compiles)"), (-0.2, 4, "second call (compiled)")):
        seconds = [max(number(r[column]), 5e-3) for r in rows]  # printed to 0.01 s: "0.00" drawn at 5 ms
        ax.barh(y + offset, seconds, height=0.38, label=label)
        for yy, r, x in zip(y + offset, rows, seconds):
            ax.annotate(f" {r[column]} s", (x, yy), va="center", fontsize=6)
    ax.set_yticks(y, [r[0] for r in rows], fontsize=7)
    ax.set(xscale="log", xlabel="time to fit [s]", title="Time to fit each parameter")
    ax.set_xlim(right=4 * max(number(r[3]) for r in rows))  # room for the labels
    ax.grid(alpha=0.3, which="both", axis="x")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2)
    return save_figure("fit_times", fig, "Time to fit each parameter, first and second call")


def main():
    data = fe_neck_conductance()
    rows = []

    fit, first, again = timed(lambda: fit_slope(data["a_over_r"], data["K_over_Kcyl"], max_a_over_r=0.7))
    rows.append(["slope s (Eq. 40), 11 points", f"{fit.params['slope']:.4f} +- {fit.stderr['slope']:.4f}",
                 fit.steps, f"{first:.2f}", f"{again:.2f}"])

    (fit, x, y), first, again = timed(neck_law.fit_smooth_law)
    err = np.max(np.abs(np.asarray(neck_law.smooth_law(fit.params, x)) / y - 1))
    rows.append([f"smooth law c1..c4, {len(x)} points", f"max err {100 * err:.2f} %", fit.steps, f"{first:.2f}",
                 f"{again:.2f}"])

    fit, first, again = timed(lambda: phi_fit.fit_phi())
    rows.append(["phi (Table 6, our BCC)", f"{fit.params['phi']:.3f} +- {fit.stderr['phi']:.3f}", fit.steps,
                 f"{first:.2f}", f"{again:.2f}"])
    fit, first, again = timed(lambda: phi_fit.fit_phi(joint=True))
    rows.append(["phi + lambda_0 scale", f"phi {fit.params['phi']:.1f} +- {fit.stderr['phi']:.1f} (not identifiable)",
                 fit.steps, f"{first:.2f}", f"{again:.2f}"])

    side, d = 6, 1e-4
    grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3) * d * 0.97
    ex = inverse.flash_experiment(grid, np.full(len(grid), d / 2), 4430.0, n_steps=2000, save_every=20,
                                  kappa_max=20.0, specific_heat_min=500.0)
    clean = ex.temperatures(7.0, 560.0)
    noisy = clean + 0.05 * jax.random.normal(jax.random.key(0), clean.shape)
    fit, first, again = timed(lambda: inverse.fit_conductivity(ex, noisy, 560.0, kappa0=3.0, noise=0.05,
                                                               learning_rate=0.1, max_steps=300))
    rows.append([f"kappa, flash on {len(grid)} particles, 2000 steps",
                 f"{fit.params['kappa']:.4f} +- {fit.stderr['kappa']:.4f} (true 7)", fit.steps, f"{first:.2f}",
                 f"{again:.2f}"])

    fit, first, again = timed(lambda: inverse.fit_conductivity(ex, noisy, 560.0, kappa0=3.0, noise=0.05,
                                                               method="levenberg_marquardt", max_steps=50))
    rows.append(["kappa, same, Levenberg-Marquardt (forward-mode Jacobian)",
                 f"{fit.params['kappa']:.4f} +- {fit.stderr['kappa']:.4f}", fit.steps, f"{first:.2f}",
                 f"{again:.2f}"])

    forward = jax.jit(lambda k: ex.temperatures(k, 560.0))

    def scipy_fit():
        res = scipy.optimize.least_squares(lambda k: (np.asarray(forward(k[0])) - np.asarray(noisy)).ravel() / 0.05,
                                           x0=[3.0], bounds=([0.0], [ex.max_diffusivity_ratio() * 560.0]))
        return res

    res, first, again = timed(scipy_fit)
    rows.append(["kappa, same, SciPy least_squares (FD Jacobian)", f"{res.x[0]:.4f}", f"{res.nfev} evaluations",
                 f"{first:.2f}", f"{again:.2f}"])

    header = ["fit", "result", "optimiser steps", "seconds (first call)", "seconds (second call)"]
    body = markdown_table(header, rows) + "\n\n" + plot(rows)
    print(body)
    write_section("fit_times", "python benchmarks/fit_times.py", body)


if __name__ == "__main__":
    main()
