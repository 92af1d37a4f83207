"""Mutation testing: do the tests catch small deliberate bugs in every module?

Usage: python benchmarks/mutation.py [--only SUBSTRING [--merge]] [--check] [--timeout S] [--no-write]

Each mutant is (module, original snippet, mutated snippet, tests): the snippet
must occur exactly once in the module. The whole repository (git's tracked and
untracked, not ignored, files) is copied once to a temporary directory; each
mutant is applied to that copy, the covering tests run there with
``python -m pytest -x -q -n0 -p no:cacheprovider`` (first failure stops them)
under a time limit, and the module is restored before the next mutant. A
mutant is *killed* when the tests fail (or time out), *survives* when they
pass. The working tree is never touched. Prints a table, writes every
mutant's row to benchmarks/results/mutation.csv and the counts per module to
the ``mutation`` section of benchmarks/RESULTS.md (not with ``--no-write``, nor
with ``--only`` unless ``--merge``: then those mutants' rows replace theirs
in the record, and the section is rewritten from the whole record). ``--check`` only verifies that every snippet is found once.

Mutants of the simulator (network, neighbors, walls, simulate, thermal, run)
were re-aimed after the redesign landed.
Too slow for CI (over an hour: one core per mutant); run it before a release or
after changing tests.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CSV = ROOT / "benchmarks" / "results" / "mutation.csv"

# Known survivors: mutant name -> why it is equivalent or left (listed in RESULTS.md).
EXPLAINED = {
    "safe_sqrt grad": "equivalent: the NaN of d sqrt at the safe 0 falls on entries the same where then sets to 0 "
                      "(the safe value matters where no inner where guards: mutant 'no inner where')",
    "finite check": "equivalent: every float key has a bounded range, which inf and NaN fail anyway",
    "beam clip": "equivalent: jnp.interp already clamps to the path's first and last waypoints",
}

T = "tests/"
NECK = [T + "test_neck.py"]
COND = [T + "test_conductance.py"]
DZ = [T + "test_dryden_zok.py"]
FIT = [T + "test_fitting.py"]
FIT_TREE = [T + "test_fitting_pytree.py"]
TEETH = T + "test_teeth_thermal.py"
THERMAL = [T + "test_thermal.py", TEETH]
SCENE = [T + "test_scene.py", T + "test_scene_run.py"]
MECH = [T + "test_mechanics.py"]
SINTER = "sintercond/laws/sintering.py"
SINT = [T + "test_sintering.py"]
FSINT = [T + "test_fit_sintering.py"]

# (name, module, original, mutated, tests)
MUTANTS = [
    ("walls rub regardless", "sintercond/sim/mechanics.py", "friction=spec.friction and spec.wall_friction",
     "friction=spec.friction", MECH),
    ("walls never rub", "sintercond/sim/mechanics.py", "friction=spec.friction and spec.wall_friction",
     "friction=False", MECH),
    # --- sintercond/laws/neck.py
    ("coble r*", "sintercond/laws/neck.py", "r_star = 2.0 * r_i * r_j / (r_i + r_j)\n    a = safe_sqrt(2.0 * r_star * h)",
     "r_star = r_i * r_j / (r_i + r_j)\n    a = safe_sqrt(2.0 * r_star * h)", NECK),
    ("hertz r*", "sintercond/laws/neck.py", "r_star = r_i * r_j / (r_i + r_j)\n    a = safe_sqrt(r_star * h)",
     "r_star = 2.0 * r_i * r_j / (r_i + r_j)\n    a = safe_sqrt(r_star * h)", NECK),
    ("lens d^2", "sintercond/laws/neck.py", "(2.0 * x_j - eta) / (4.0 * d_safe**2)", "(2.0 * x_j - eta) / (4.0 * d_safe)",
     NECK),
    ("h_max third", "sintercond/laws/neck.py", "h_max = r_s / 3.0 + r_s**2", "h_max = r_s / 3.1 + r_s**2", NECK),
    ("newton 4 steps", "sintercond/laws/neck.py", "DEFAULT_NEWTON_ITERATIONS = 5", "DEFAULT_NEWTON_ITERATIONS = 4", NECK),
    ("while any->all", "sintercond/laws/neck.py", "& jnp.any(step > tolerance * x)", "& jnp.all(step > tolerance * x)",
     NECK),
    ("coble start", "sintercond/laws/neck.py", "x = jnp.minimum(4.0 * eta * rho_i * rho_j / (rho_i + rho_j), x_max)",
     "x = jnp.minimum(2.0 * eta * rho_i * rho_j / (rho_i + rho_j), x_max)", NECK),
    ("jvp da/dh", "sintercond/laws/neck.py", "da_dh = factor * b_i * b_j", "da_dh = factor * b_i * b_i", NECK),
    ("jvp factor", "sintercond/laws/neck.py", "3.0 / (2.0 * root_x * (c_i * b_j + c_j * b_i))",
     "3.0 / (2.0 * root_x * (c_i * b_j + c_j * b_i) * 1.001)", NECK),
    ("no contact -> coble", "sintercond/laws/neck.py", "jnp.where(contact, a, 0.0), jnp.nan)",
     "jnp.where(contact | True, a, 0.0), jnp.nan)", NECK),
    # --- sintercond/_numerics.py, _validation.py
    ("safe_sqrt grad", "sintercond/_numerics.py",
     "x_safe = jnp.where(positive, x, jnp.ones_like(x))\n    return jnp.where(positive, jnp.sqrt(x_safe)",
     "x_safe = jnp.where(positive, x, jnp.zeros_like(x))\n    return jnp.where(positive, jnp.sqrt(x_safe)", NECK),
    ("no inner where", "sintercond/_numerics.py",
     "x_safe = jnp.where(positive, x, jnp.ones_like(x))\n    return jnp.where(positive, jnp.sqrt(x_safe)",
     "x_safe = x\n    return jnp.where(positive, jnp.sqrt(x_safe)", NECK),
    ("safe_divide fill", "sintercond/_numerics.py", "return jnp.where(nonzero, numerator / safe_den, fill)",
     "return jnp.where(nonzero, numerator / safe_den, 1.0)", COND),
    ("positive allows 0", "sintercond/_validation.py", "(values >= np.finfo(np.float64).tiny)", "(values >= 0)",
     NECK + COND),
    ("finite dropped", "sintercond/_validation.py",
     "fail_where(~np.isfinite(values), lambda i:", "fail_where(np.isnan(values), lambda i:", NECK + COND),
    # --- sintercond/laws/conductance.py
    ("rojek slope", "sintercond/laws/conductance.py", "ROJEK_SLOPE = 1.064", "ROJEK_SLOPE = 1.065", COND),
    ("argento slope", "sintercond/laws/conductance.py", "ARGENTO_BOUVARD_SLOPE = 1.0 / 0.899",
     "ARGENTO_BOUVARD_SLOPE = 1.0 / 0.9", COND),
    ("series R_c", "sintercond/laws/conductance.py", "k_i + k_j + k_i * k_j * r_c)", "k_i + k_j + k_i * r_c)", COND),
    ("fitted half x", "sintercond/laws/conductance.py",
     "k_j = kappa_j * jnp.pi * r_j * fitted_half_conductance_ratio(a / r_j, c)",
     "k_j = kappa_j * jnp.pi * r_j * fitted_half_conductance_ratio(a / r_i, c)", COND),
    ("fitted log term", "sintercond/laws/conductance.py", "(1.0 + c1 * x_log_x + c2 * x", "(1.0 - c1 * x_log_x + c2 * x",
     COND),
    ("conductivity k_ij", "sintercond/laws/conductance.py", "k_ij = (r_i + r_j) / (r_i / kappa_i + r_j / kappa_j)",
     "k_ij = (r_i + r_j) / (r_i / kappa_i + r_j / kappa_i)", COND),
    ("feng alpha^2", "sintercond/laws/conductance.py", "+ 1.5 + alpha**2 / 36.0", "+ 1.5 + alpha**2 / 30.0", COND),
    ("kappa_j default", "sintercond/laws/conductance.py", "kappa_j = kappa_i if kappa_j is None else kappa_j\n    r_i, r_j",
     "kappa_j = kappa_i\n    r_i, r_j", COND),
    ("no-contact k", "sintercond/laws/conductance.py", "jnp.where(undefined, jnp.nan, jnp.where(contact, k, 0.0))",
     "jnp.where(undefined, 0.0, jnp.where(contact, k, 0.0))", COND),
    # --- sintercond/laws/dryden_zok.py, effective.py
    ("dz grading", "sintercond/laws/dryden_zok.py", "ratio = max(0.35,", "ratio = max(0.5,", DZ),
    ("dz closest break", "sintercond/laws/dryden_zok.py", "_CLOSEST_BREAK = 1e-14", "_CLOSEST_BREAK = 0.0", DZ),
    ("dz sigma 6/pi", "sintercond/laws/dryden_zok.py", "return 6.0 / jnp.pi * alpha * jnp.sum(w * j",
     "return 6.0 / 3.1416 * alpha * jnp.sum(w * j", DZ),
    ("dz valid range", "sintercond/laws/dryden_zok.py", "valid = (alpha > 0) & (alpha <= jnp.pi / 2)",
     "valid = (alpha > 0) & (alpha <= jnp.pi)", DZ),
    ("dz cap angle", "sintercond/laws/dryden_zok.py", "dryden_zok_sigma(cap_angle(alpha_bar, coordination), nodes)",
     "dryden_zok_sigma(cap_angle(alpha_bar, coordination + 1), nodes)", DZ),
    ("hs upper", "sintercond/laws/effective.py", "upper = _hashin_shtrikman(k_hi, k_lo, 1.0 - v_hi)",
     "upper = _hashin_shtrikman(k_hi, k_lo, v_hi)", [T + "test_effective.py"]),
    ("maxwell 2v", "sintercond/laws/effective.py", "3 * k_matrix + (1 + 2 * inclusion_fraction) * d",
     "3 * k_matrix + (1 + inclusion_fraction) * d", [T + "test_effective.py"]),
    # --- sintercond/laws/tortuosity.py, geometry.py, packing.py, settle.py
    ("gamma 2x", "sintercond/laws/tortuosity.py", "return (diameter - 2.0 * x) / diameter", "return (diameter - x) / diameter",
     [T + "test_tortuosity.py"]),
    ("tau2 exponent", "sintercond/laws/tortuosity.py", "n ** (1.0 - phi)", "n ** (1.0 + phi)", [T + "test_tortuosity.py"]),
    ("ramp floor", "sintercond/laws/tortuosity.py", "else jnp.floor(fraction * steps + STEP_EDGE)",
     "else jnp.round(fraction * steps + STEP_EDGE)",
     [T + "test_tortuosity.py"]),
    ("segment area", "sintercond/laws/geometry.py", "return 0.5 * (x * np.sqrt(np.maximum(r * r - x * x, 0.0))",
     "return 0.5 * (x * np.sqrt(np.maximum(r * r - 0.99 * x * x, 0.0))", [T + "test_geometry.py"]),
    ("coordination", "sintercond/laws/geometry.py", "np.bincount(pairs.ravel(), minlength=len(radii))",
     "np.bincount(pairs[:, 0], minlength=len(radii))", [T + "test_geometry.py"]),
    ("bed gravity", "sintercond/beds/settle.py", "return force.at[:, 2].add(-weight)", "return force.at[:, 2].add(weight)",
     [T + "test_packing.py"]),
    ("deposit misses the bins to the left", "sintercond/beds/packing.py", "around = np.arange(-1, 2)",
     "around = np.arange(0, 2)", [T + "test_packing.py::test_the_deposit_grid_finds_what_the_full_search_finds"]),
    ("deposit keeps the highest drop", "sintercond/beds/packing.py", "best = int(np.argmin(z))", "best = int(np.argmax(z))",
     [T + "test_packing.py::test_the_deposit_grid_finds_what_the_full_search_finds"]),
    # --- sintercond/laws/heat_sources.py
    ("nozzle linear", "sintercond/laws/heat_sources.py", "radius**2 * (1.0 - depth / max_depth), 0.0)",
     "radius**2 * (1.0 - 0.5 * depth / max_depth), 0.0)", [T + "test_heat_sources.py"]),
    ("nusselt ignored", "sintercond/laws/heat_sources.py", "h = nusselt * environment_conductivity / (2.0 * radius)",
     "h = environment_conductivity / radius", [T + "test_heat_sources.py"]),
    ("stefan-boltzmann", "sintercond/laws/heat_sources.py", "STEFAN_BOLTZMANN = 5.670367e-8", "STEFAN_BOLTZMANN = 5.67e-8",
     [T + "test_heat_sources.py"]),
    ("whitaker Pr", "sintercond/laws/heat_sources.py", "* prandtl**0.4 *", "* prandtl**0.3 *", [T + "test_heat_sources.py"]),
    ("beam clip", "sintercond/laws/heat_sources.py", "s = jnp.clip(speed * t, 0.0, arc[-1])", "s = speed * t",
     [T + "test_heat_sources.py"]),
    # --- sintercond/scene.py
    ("swelling bound", "sintercond/scene/schema.py", '"sinter_swelling": Key(float, _within(0.0, 0.05)',
     '"sinter_swelling": Key(float, _within(0.0, 0.06)', SCENE[:1]),
    ("penetration bound", "sintercond/scene/schema.py", '"penetration": Key(float, _within(0.0, 0.2)',
     '"penetration": Key(float, _within(0.0, 0.25)', SCENE[:1]),
    ("finite check", "sintercond/scene/schema.py", "        ok = ok and math.isfinite(value)", "        ok = ok",
     SCENE[:1]),
    ("nu and re", "sintercond/scene/validate.py", 'if "reynolds" in convection and "nusselt" in convection:', "if False:",
     SCENE[:1]),
    ("checkpoint multiple", "sintercond/scene/validate.py",
     'if "output_every" in run and run.get("checkpoint_every", run["output_every"]) % run["output_every"]:',
     "if False:", SCENE),
    # --- sintercond/state.py, sweep.py, cli.py, __init__.py
    ("mass", "sintercond/state.py", "mass = 4.0 / 3.0 * np.pi * radii**3 * rho",
     "mass = 4.0 / 3.0 * np.pi * radii**2 * rho", [T + "test_state.py"]),
    ("sweep padding", "sintercond/sweep.py", "index = np.minimum(np.arange(start, start + chunk), stop - 1)",
     "index = np.minimum(np.arange(start, start + chunk), stop)", [T + "test_sweep.py"]),
    ("cli copper", "sintercond/cli.py", "COPPER_CONDUCTIVITY = 394.0", "COPPER_CONDUCTIVITY = 390.0",
     [T + "test_cli.py"]),
    ("x64 off", "sintercond/__init__.py", '_jax.config.update("jax_enable_x64", True)',
     '_jax.config.update("jax_enable_x64", False)', NECK),
    # --- the simulator: network.py, neighbors.py, walls.py, simulate.py, thermal.py, run.py
    ("two materials", "sintercond/contacts/network.py", "k_pairs = pair_conductances(law, p, kappa[p.i], kappa[p.j], params, neck_model)",
     "k_pairs = pair_conductances(law, p, kappa[p.i], kappa[p.i], params, neck_model)", [TEETH]),
    ("lift two materials", "sintercond/sim/contacts.py", "kappa[material[lo]],\n                              kappa[material[hi]], law_params)",
     "kappa[material[lo]],\n                              kappa[material[lo]], law_params)", [T + "test_simulate.py"]),
    ("wall neck", "sintercond/laws/walls.py", "r_minus_s = 12.0 * r * h_in / (3.0 * r + 3.0 * h_in + root)",
     "r_minus_s = 11.0 * r * h_in / (3.0 * r + 3.0 * h_in + root)", [T + "test_walls.py", TEETH]),
    ("contact tolerance", "sintercond/contacts/neighbors.py", "    return distance <= (radii[i] + radii[j]) * (1.0 + tolerance)",
     "    return distance < (radii[i] + radii[j])",
     THERMAL[:1] + [TEETH + "::test_touching_within_the_tolerance_is_a_contact"]),
    ("stable step", "sintercond/sim/thermal.py", "return jnp.min(jnp.where(total > 0, capacity / jnp.where(total > 0, total, 1.0), jnp.inf))",
     "return jnp.min(jnp.where(total > 0, 2.0 * capacity / jnp.where(total > 0, total, 1.0), jnp.inf))",
     [TEETH + "::test_auto_time_step_is_nine_tenths_of_the_stable_step"]),
    ("source clock", "sintercond/simulate.py", "state = init_state(particles, contacts, dt, start_step)",
     "state = init_state(particles, contacts, dt, 0)", [TEETH]),
    ("held ignored", "sintercond/sim/thermal.py", "    return jnp.where(fixed_mask, fixed_temperature, new)",
     "    return new", THERMAL[:1]),
    ("symmetric transpose", "sintercond/contacts/network.py", "tangent = self_adjoint(_gather_laplacian, (conductance, neighbors), dx, _gather_laplacian_cotangent)",
     "tangent = self_adjoint(lambda t, v: 0.5 * _gather_laplacian(t, v), (conductance, neighbors), dx,\n"
     "                              lambda t, v: 0.5 * _gather_laplacian_cotangent(t, v))",
     [T + "test_simulate.py"]),
    ("checkpoint segments", "sintercond/sim/rollout.py", "    q, r = divmod(n_saves, group)",
     "    q, r = divmod(n_saves, group)\n    r = 0", [T + "test_simulate.py"]),
    ("dynamic skin overflow", "sintercond/sim/contacts.py",
     "    overflow = did_buffer_overflow(nbrs) | half_pairs_overflowed(half)",
     "    overflow = half_pairs_overflowed(half)", [T + "test_moving.py"]),
    ("swelling ignored", "sintercond/beds/packing.py", 'radii=bed.radii * (1.0 + p.get("sinter_swelling", 0.0)))',
     "radii=bed.radii)", [TEETH + "::test_sinter_swelling_grows_the_settled_radii"]),
    ("dt auto factor", "sintercond/scene/build.py", "dt = 0.9 * limit if", "dt = 1.9 * limit if",
     [TEETH + "::test_auto_time_step_is_nine_tenths_of_the_stable_step"]),
    ("duration end", "sintercond/scene/build.py", "    return run.duration / n_steps, n_steps, limit",
     "    return dt, n_steps, limit",
     [T + "test_bad_input_run.py"]),
    ("wall penetration", "sintercond/scene/build.py",
     'wall.penetration * float(np.mean(radii))',
     'wall.penetration * float(np.mean(radii)) * 2',
     [TEETH + "::test_conducting_wall_penetration_sets_the_overlap"]),
    ("shrinkage rate", "sintercond/sim/contacts.py", "return lambda t: centroid + (1.0 - rate * t) * (centres - centroid)",
     "return lambda t: centroid + (1.0 - 0.5 * rate * t) * (centres - centroid)", [T + "test_moving.py"]),
    # --- fitting/
    ("weights ignored", "fitting/core.py",
     "w = jnp.ones_like(y) if weights is None else jnp.broadcast_to(jnp.asarray(weights, y.dtype), y.shape)",
     "w = jnp.ones_like(y)", FIT),
    ("stderr halved", "fitting/core.py", "covariance = s2 * np.linalg.inv(jtj)",
     "covariance = s2 / 4 * np.linalg.inv(jtj)", FIT + [TEETH]),
    ("dof", "fitting/core.py", "dof = int(r.shape[0]) - len(names)", "dof = int(r.shape[0])", FIT),
    ("bounded inverse", "fitting/core.py", "return jnp.log(p) - jnp.log1p(-p)", "return jnp.log(p) - jnp.log(p)", FIT),
    ("positive inverse", "fitting/core.py", "return x + jnp.log(-jnp.expm1(-x))", "return x", FIT),
    ("lm damping", "fitting/core.py", "damping = jnp.where(better, damping / 3.0, damping * 2.0)",
     "damping = jnp.where(better, damping * 2.0, damping / 3.0)", FIT),
    ("pytree dict keys sorted", "fitting/core.py",
     "return [(jax.tree_util.DictKey(k), v) for k, v in node.items()]",
     "return [(jax.tree_util.DictKey(k), node[k]) for k in sorted(node)]", FIT_TREE),
    ("pytree subtree transform taken once", "fitting/core.py", "found.extend([t] * len(_walk(node)[1]))",
     "found.append(t)", FIT_TREE),
    ("pytree one slot per leaf", "fitting/core.py",
     "stops = np.cumsum([int(np.prod(shape)) for shape in self.shapes], dtype=int).tolist()",
     "stops = np.cumsum([1 for shape in self.shapes], dtype=int).tolist()", FIT_TREE),
    ("slope keep", "fitting/slope.py", "keep = a_over_r <= max_a_over_r", "keep = a_over_r < max_a_over_r", FIT),
    ("phi mean", "fitting/phi.py", "return lam.mean(axis=1)", "return lam.max(axis=1)", FIT),
    ("phi bounds", "fitting/phi.py", 'transforms = {"phi": Bounded(1.0, 12.0)}', 'transforms = {"phi": Bounded(1.0, 5.0)}',
     FIT),
    ("neck law relative", "fitting/neck_law.py", "relative=True, max_steps=4000), x, y",
     "relative=False, max_steps=4000), x, y", FIT),
    ("reference csv", "fitting/reference.py", '.joinpath("fe_neck_conductance.csv"))',
     '.joinpath("fe_neck_conductance.csv"))[::-1] if False else None', FIT),
    ("flash energy", "fitting/inverse.py", "power = temperature_rise * specific_heat_min * mass.sum() / pulse_duration",
     "power = 0.5 * temperature_rise * specific_heat_min * mass.sum() / pulse_duration", [TEETH]),
    ("adjoint pulse clock", "fitting/inverse.py", "t = jnp.asarray(k, experiment.power.dtype) * experiment.dt",
     "t = jnp.asarray(k + 1, experiment.power.dtype) * experiment.dt",
     [T + "test_inverse.py::test_adjoint_and_simulate_give_the_same_readings"]),
    ("fitting x64", "fitting/__init__.py", "import sintercond  # noqa: F401,E402", "import jax  # noqa: F401,E402",
     [T + "test_fitting.py::test_importing_fitting_alone_turns_on_float64"]),
    # sintering kinetics (session 11: each written before its test ran)
    ("overlap cap term", SINTER, "(r_i + 2.0 * s_i) / (3.0 * b_i * b_i)", "(r_i + s_i) / (3.0 * b_i * b_i)", SINT),
    ("overlap jvp radius sign", SINTER, "dh_da * da - u / (b_i * b_i) * dr_i", "dh_da * da + u / (b_i * b_i) * dr_i",
     SINT),
    ("overlap beyond min(r)", SINTER, "& (a <= _max_neck(r_i, r_j))", "& (a <= 2.0 * _max_neck(r_i, r_j))", SINT),
    ("sintering force term", SINTER, "+ a * jnp.sin(psi_half)", "+ a * jnp.cos(psi_half)", SINT),
    ("arrhenius in J/mol", SINTER, "jnp.exp(-1e3 * activation_energy_kj", "jnp.exp(-activation_energy_kj", SINT),
    ("mobility 1/T dropped", SINTER, 'return params["A"] / temperature * _arrhenius', 'return params["A"] * _arrhenius', SINT),
    ("equilibrium neck of the larger sphere", SINTER,
     'return jnp.minimum(r_i, r_j) * jnp.sin(0.5 * jnp.deg2rad(params["dihedral_angle"]))',
     'return jnp.maximum(r_i, r_j) * jnp.sin(0.5 * jnp.deg2rad(params["dihedral_angle"]))', SINT),
    ("damped newton", SINTER, "u_end - residual * shape(x_end)", "u_end - 0.5 * residual * shape(x_end)", SINT),
    ("viscous without 3/2", SINTER, "return 1.5 * _equivalent_radius(r_i, r_j)", "return _equivalent_radius(r_i, r_j)",
     SINT),
    ("ramp floor reading", SINTER, "step_temperatures = temperature_start + k * (",
     "step_temperatures = temperature_start + (k - 1) * (", SINT),
    ("pair temperature geometric", SINTER, "return 0.5 * (temperature_i + temperature_j)",
     "return jnp.sqrt(temperature_i * temperature_j)", SINT),
    ("durations may be negative", SINTER, 'require_positive("durations (s)", durations, allow_zero=True)',
     'require_positive("durations (s)", np.abs(durations), allow_zero=True)', SINT),
    ("bed duplicate kept", "fitting/sintering.py", 'keep = ~((t8["particle_1"] == 2) & (t8["particle_2"] == 3))',
     'keep = t8["particle_1"] > 0', FSINT),
    ("A without T_ref", "fitting/sintering.py", 'out["A"] = rate_ref * reference_temperature * arrhenius_ref',
     'out["A"] = rate_ref * arrhenius_ref', FSINT),
    ("lattice not turned to the axis", "fitting/sintering.py", "    shifts[:, [axis, 0]] = shifts[:, [0, axis]]",
     "    pass", FSINT),
    ("time step for a negative approach speed", "sintercond/laws/forces.py",
     '"v_rel (m/s, the largest normal approach speed)", speed, allow_zero=sized_by_load)',
     '"v_rel (m/s, the largest normal approach speed)", abs(speed), allow_zero=sized_by_load)',
     [T + "test_forces.py::test_stable_time_step_refuses_an_approach_speed_that_sizes_nothing"]),
    # the layer above the step (session 12: each written before its test ran)
    ("host loop ignores the lists' overflow", "sintercond/sim/rollout.py", "if bool(new.overflow) or bool(overflowed):",
     "if bool(overflowed):", [T + "test_rollout.py", T + "test_moving.py"]),
    ("host loop ignores measure's flag", "sintercond/sim/rollout.py", "if bool(new.overflow) or bool(overflowed):",
     "if bool(new.overflow):", [T + "test_rollout.py"]),
    ("host loop hands on an unchecked state", "sintercond/sim/rollout.py", "        check(new)\n", "        pass\n",
     [T + "test_rollout.py"]),
    ("settling stops one chunk late", "sintercond/beds/settle.py",
     'return figures["kinetic"] < kinetic_tol and figures["force"] < force_tol',
     'return figures["kinetic"] < kinetic_tol and figures["force"] < force_tol and int(s.step) > 2 * check_every',
     [T + "test_rollout.py::test_settling_runs_on_the_host_loop", T + "test_packing.py"]),
    ("LM loop drops the trial steps' flags", "fitting/core.py",
     "                    jnp.linalg.norm(grad), change, flagged | flag)",
     "                    jnp.linalg.norm(grad), change, flagged)", FIT),
    ("Adam loop drops its flags", "fitting/core.py",
     "jnp.linalg.norm(grad), change, flagged | flag\n", "jnp.linalg.norm(grad), change, flagged\n", FIT),
    ("steady k* hot face from the far side", "sintercond/sim/steady.py",
     "hot = centres[:, axis] - radii <= lo[axis] + 1e-12 * (hi[axis] - lo[axis])",
     "hot = centres[:, axis] + radii <= lo[axis] + 1e-12 * (hi[axis] - lo[axis])",
     [T + "test_thermal.py", T + "test_simulate.py"]),
    ("the floor may exceed the modulus", "sintercond/sim/mechanics.py", "above = e_min > e0", "above = e_min > 2.0 * e0",
     [T + "test_api_validation.py", T + "test_scene_mechanics.py"]),
    ("parameter ranges only check finiteness", "sintercond/sim/mechanics.py",
     "bad = ~(np.isfinite(v) & (v >= low) & (v <= high))", "bad = ~np.isfinite(v)", [T + "test_api_validation.py"]),
    ("deep overlaps up to 2 r allowed", "sintercond/sim/validation.py", "deep = depth > MAX_INITIAL_OVERLAP",
     "deep = depth > 2.0", [T + "test_api_validation.py"]),
    ("rollout skips the boundary checks", "sintercond/sim/rollout.py",
     "    validate_inputs(sim, state, params)\n    if sim.physics.mechanics", "    if sim.physics.mechanics",
     [T + "test_api_validation.py"]),
    ("float32 overlaps warned only below a tenth of a step", "sintercond/sim/validation.py",
     "if smallest < FLOAT32_OVERLAP_STEPS * ulp:", "if smallest < 0.1 * ulp:", [T + "test_api_validation.py"]),
    ("python-float kappa flags every pair", "sintercond/laws/conductance.py",
     "~((jnp.asarray(kappa_i) > 0) & (jnp.asarray(kappa_j) > 0))", "~((kappa_i > 0) & (kappa_j > 0))", COND),
    # issue 28: the step sized from what the run meets, and the guards (mutants written before running them)
    ("scene wall velocity dropped", "sintercond/scene/build.py",
     'tuple(float(v) for v in wall.velocity)', "(0.0, 0.0, 0.0)",
     [T + "test_moving_walls.py"]),
    ("wall speed left out of the sizing speed", "sintercond/scene/build.py", "v_rel = impact + wall_speed",
     "v_rel = impact", [T + "test_moving_walls.py"]),
    ("wall step from the largest radius", "sintercond/scene/build.py",
     "step = WALL_STEP_FRACTION * float(np.min(radii)) / wall_speed",
     "step = WALL_STEP_FRACTION * float(np.max(radii)) / wall_speed", [T + "test_moving_walls.py"]),
    ("tangential wall speed sizes the step", "sintercond/scene/estimate.py",
     'return max(inward * float(wall["velocity"][wall["axis"]]), 0.0)',
     'return float(np.linalg.norm(wall["velocity"]))', [T + "test_moving_walls.py"]),
    ("receding walls size the step", "sintercond/scene/estimate.py",
     'return max(inward * float(wall["velocity"][wall["axis"]]), 0.0)',
     'return abs(inward * float(wall["velocity"][wall["axis"]]))', [T + "test_moving_walls.py"]),
    ("beam step bound ignored by a fixed dt", "sintercond/scene/build.py",
     "        for kind, (bound, name) in bounds.items():\n            if dt > bound:",
     "        for kind, (bound, name) in bounds.items():\n            if dt > bound and kind != 'beam':",
     [T + "test_moving_walls.py"]),
    ("beam step from the diameter", "sintercond/scene/estimate.py",
     'return BEAM_STEP_FRACTION * beam["spot_radius"] / beam["speed"]',
     'return BEAM_STEP_FRACTION * 2 * beam["spot_radius"] / beam["speed"]', [T + "test_moving_walls.py"]),
    ("guard approach sign flipped", "sintercond/sim/guards.py", "closing = np.sum((v[i] - v[j]) * normal, axis=1)",
     "closing = np.sum((v[j] - v[i]) * normal, axis=1)", [T + "test_moving_walls.py"]),
    ("guard ignores the walls' approach", "sintercond/sim/guards.py", "        if closing.max() > fastest:",
     "        if False:", [T + "test_moving_walls.py"]),
    ("guard wall approach without the wall's speed", "sintercond/sim/guards.py",
     "closing = np.where(near, (wall_velocity - v) @ wall_normal, -np.inf)",
     "closing = np.where(near, -v @ wall_normal, -np.inf)", [T + "test_moving_walls.py"]),
    ("energy guard off", "sintercond/sim/guards.py", "        if after > before + ENERGY_TOLERANCE * scale:",
     "        if False:", [T + "test_moving_walls.py"]),
    ("energy guard counts gravity's work twice", "sintercond/sim/guards.py",
     "after = now.kinetic + now.elastic + work", "after = now.kinetic + now.elastic + 2 * work",
     [T + "test_moving_walls.py"]),
    ("guard not in the scene run", "sintercond/run.py", "    if model.sized_speed is None:\n        return temperatures",
     "    if True:\n        return temperatures", [T + "test_moving_walls.py"]),
    ("hertz energy 8/15 -> 2/5", "sintercond/laws/forces.py", "return (8.0 / 15.0) * safe_sqrt(r_star) * e_star",
     "return (2.0 / 5.0) * safe_sqrt(r_star) * e_star", [T + "test_moving_walls.py"]),
    ("lens radius scaled by the smaller radius only in the value", "sintercond/laws/neck.py",
     "return jnp.where(defined, scale * safe_sqrt(jnp.where(h > 0, a_squared, 0.0)), jnp.nan)",
     "return jnp.where(defined, jnp.minimum(r_i, r_j) * safe_sqrt(jnp.where(h > 0, a_squared, 0.0)), jnp.nan)",
     COND),
    ("pair modulus of i for both spheres", "sintercond/sim/mechanics.py",
     "                                                modulus[j], nu[j])",
     "                                                modulus[i], nu[i])", [T + "test_unequal_contacts.py"]),
    ("pair radius of i for both spheres", "sintercond/sim/mechanics.py",
     "nu_j = (radii_f[i], radii_f[j], mass_f[i],",
     "nu_j = (radii_f[i], radii_f[i], mass_f[i],", [T + "test_unequal_contacts.py"]),
    ("softening at the mean temperature", "sintercond/sim/mechanics.py", "return softened_modulus(temperature, e0",
     "return softened_modulus(jnp.mean(temperature) + 0 * temperature, e0", [T + "test_unequal_contacts.py"]),
    ("coupled step without its sources", "sintercond/sim/terms/mechanics.py",
     "    power = power + sources.power(physics, state, params)", "    power = power + 0.0",
     [T + "test_coupled_sources.py"]),
    ("beam depth from the top centre", "sintercond/sim/thermal.py", "surface = jnp.max(positions[:, 2] + radii)",
     "surface = jnp.max(positions[:, 2])", [T + "test_coupled_sources.py"]),
    ("pulse never ends", "sintercond/sim/thermal.py", "(t < params.pulse.duration)", "(t >= 0)",
     [T + "test_coupled_sources.py"]),
    ("beam at rest", "sintercond/sim/thermal.py", "spot = heat_sources.beam_position(t, b.path, b.speed)",
     "spot = heat_sources.beam_position(0.0 * t, b.path, b.speed)", [T + "test_coupled_sources.py"]),
    ("saved at the start of each interval", "sintercond/sim/rollout.py",
     "buffer = jax.lax.cond((k + 1) % every == 0, save,", "buffer = jax.lax.cond(k % every == 0, save,",
     [T + "test_observable_times.py"]),
    ("every-step write one slot late", "sintercond/sim/rollout.py",
     "jax.lax.dynamic_update_index_in_dim(b, x, k // every, 0)",
     "jax.lax.dynamic_update_index_in_dim(b, x, (k + 1) // every, 0)", [T + "test_observable_times.py"]),
    ("one save observes before its steps", "sintercond/sim/rollout.py",
     "        s = run_steps(s, every)\n        return s, observe(s)", "        return run_steps(s, every), observe(s)",
     [T + "test_observable_times.py"]),
    ("history time from the previous step", "sintercond/output/observe.py",
     "values = [state_time(state), float(t.mean())", "values = [state_time(state) - float(state.dt), float(t.mean())",
     [T + "test_observable_times.py"]),
    ("tangential damping key ignored", "sintercond/scene/build.py", 'xi_fric=m.tangential_damping',
     'xi_fric=1.0', [T + "test_scene_keys.py"]),
    ("softening rate key dropped", "sintercond/scene/build.py", 'rate=f(soft.rate if soft else 1.0)', "rate=f(1.0)",
     [T + "test_scene_keys.py"]),
    ("rolling projection key dropped", "sintercond/scene/build.py", 'rolling_projection=p.rolling_projection',
     "rolling_projection=False", [T + "test_scene_keys.py"]),
    ("wall rolling friction from the pairs'", "sintercond/scene/build.py", 'mu_r_wall=m.wall_rolling_friction',
     'mu_r_wall=m.rolling_friction', [T + "test_scene_keys.py"]),
    ("beam spot radius key ignored", "sintercond/scene/build.py", 'spot_radius=f(beam.spot_radius)',
     'spot_radius=f(beam.spot_radius * 0 + 1e-3)', [T + "test_scene_keys.py"]),
    ("covariance and polish unweighted", "fitting/core.py",
     "            return weighted_residuals(forward_model, t, x, y, w)\n\n        jac, (residual, flag)",
     "            return weighted_residuals(forward_model, t, x, y, jnp.ones_like(w))\n\n        jac, (residual, flag)",
     [T + "test_fitting.py::test_weighted_nonlinear_standard_errors_have_their_monte_carlo_coverage"]),
    ("crushed contacts allowed", "sintercond/sim/guards.py", "        if now.depth > simulate.MAX_INITIAL_OVERLAP:",
     "        if now.depth > 10 * simulate.MAX_INITIAL_OVERLAP:", [T + "test_moving_walls.py"]),
    ("floating clusters keep the solver's 0", "sintercond/sim/steady.py", "    reached = np.isin(label, label[held])",
     "    reached = np.isin(label, label)", [T + "test_packing_files.py"]),
    ("a resume takes the rebuilt model's step", "sintercond/run.py",
     "    if duration is not None or float(state.dt) != model.dt:", "    if duration is not None:",
     [T + "test_first_day.py::test_an_interrupted_extension_resumes_with_the_runs_own_step"]),
    ("extensions checkpoint only on the grid", "sintercond/run.py", "        if crossed or step >= model.n_steps:",
     '        if step % run["checkpoint_every"] == 0 or step >= model.n_steps:',
     [T + "test_first_day.py::test_an_interrupted_extension_resumes_with_the_runs_own_step"]),
    ("wall friction defaults to 0, not to the pairs' friction", "sintercond/scene/validate.py",
     "        return table.get(spec.default)  # a reference", "        return 0.0  # a reference",
     [T + "test_scene_defaults.py"]),
    ("defaults filled before the mechanics-only keys are checked", "sintercond/scene/validate.py",
     "    if (section, key) in _MECHANICAL_ONLY and not on:\n        return None",
     "    if False:\n        return None", [T + "test_scene_defaults.py"]),
    ("rough-bed penetration on every packing", "sintercond/scene/validate.py",
     '    return ROUGH_BED_PENETRATION if rough else _WALL["penetration"].default', "    return ROUGH_BED_PENETRATION",
     [T + "test_first_day.py"]),
    ("the melting point never stops a run", "sintercond/run.py",
     "            if hottest > melting:", "            if hottest > 10 * melting:", [T + "test_first_day.py"]),
    ("the beam stays on after its path", "sintercond/laws/heat_sources.py",
     "    done = (s > arc[-1]) & (arc[-1] > 0)", "    done = s < 0", [T + "test_first_day.py"]),
    # sintering in the simulator (issue 26, session 15)
    ("necks grow at the end temperature only", "sintercond/sim/neck_growth.py", "    start = carried.interval_temperature\n",
     "    start = end_temperature\n", [T + "test_neck_growth.py"]),
    ("approach not the neck's", "sintercond/sim/neck_growth.py",
     "    return a, jnp.where(active, sintering.neck_overlap(a, r_i, r_j), 0.0), u, unbalanced",
     "    return a, jnp.where(active, sintering.neck_overlap(a, r_i, r_j) * 1.001, 0.0), u, unbalanced",
     [T + "test_neck_growth.py"]),
    ("grown necks never unstable", "sintercond/sim/terms/sintering.py",
     "unstable=carried.unstable | jnp.any(state.dt > limit))", "unstable=carried.unstable)",
     [T + "test_neck_growth.py"]),
    ("interval start not carried", "sintercond/sim/terms/sintering.py",
     "    return dataclasses.replace(carried, interval_temperature=particles.temperature,",
     "    return dataclasses.replace(carried, interval_temperature=carried.interval_temperature,",
     [T + "test_neck_growth.py"]),
    ("ramp level at its start", "sintercond/laws/tortuosity.py", "step = (jnp.ceil(fraction * steps - STEP_EDGE)",
     "step = (jnp.floor(fraction * steps - STEP_EDGE)", [T + "test_neck_growth.py"]),
    ("step on the start necks", "sintercond/sim/neck_growth.py", "    neck = jnp.maximum(cap, contacts.neck)\n",
     "    neck = contacts.neck\n", [T + "test_sintering_scene.py"]),
    # many-body shrinkage (issue 26, session 16)
    ("balance unweighted", "sintercond/sim/neck_growth.py",
     "    rhs = jnp.where(movable, on_particles(weights * free_approach), 0.0)",
     "    rhs = jnp.where(movable, on_particles(free_approach), 0.0)", [T + "test_shrinkage.py"]),
    ("supports ignored", "sintercond/sim/neck_growth.py", "    movable = ~supports\n",
     "    movable = jnp.ones_like(supports)\n", [T + "test_shrinkage.py"]),
    ("many-body neck from free growth", "sintercond/sim/neck_growth.py",
     "    a = jnp.where(active, jnp.clip(neck_radius(r_i, r_j, h), a_start, cap), a_start)",
     "    a = jnp.where(active, jnp.clip(a_free, a_start, cap), a_start)", [T + "test_shrinkage.py"]),
    ("sintering force at the start neck", "sintercond/sim/neck_growth.py", "law.force(0.5 * (a_start + a_free), ",
     "law.force(a_start, ", [T + "test_shrinkage.py"]),
    ("balance never flagged", "sintercond/sim/neck_growth.py",
     "    return u, ~converged\n", "    return u, converged & False\n",
     [T + "test_shrinkage.py"]),
    ("particles not moved", "sintercond/sim/terms/sintering.py", "            moved = particles.positions + displacement\n",
     "            moved = particles.positions + 0.0 * displacement\n", [T + "test_shrinkage.py"]),
    ("many-body supports not from walls", "sintercond/scene/build.py",
     '            supports[:, 2] |= np.asarray(plane.penetration(centres, radii)) >= 0',
     '            supports[:, 2] |= np.asarray(plane.penetration(centres, radii)) > 1.0',
     [T + "test_sintering_scene.py"]),
    # sintering with the elastic mechanics: necks on the half pair list (issue 26, stop 37)
    ("necks not carried through a rebuild", "sintercond/sim/mechanics.py",
     'PAIR_HISTORY = ("spring", "rolling", "neck", "neck_overlap")', 'PAIR_HISTORY = ("spring", "rolling")',
     [T + "test_sintering_mechanics.py"]),
    ("elastic laws on the whole overlap", "sintercond/sim/contacts.py",
     "    overlap = geometry.overlap - neck_overlap\n", "    overlap = geometry.overlap - 0.0 * neck_overlap\n",
     [T + "test_sintering_mechanics.py"]),
    ("conductance on the overlap only", "sintercond/sim/contacts.py",
     "jnp.where(geometry.touching, jnp.maximum(geometry.overlap, neck_overlap), 0.0)",
     "jnp.where(geometry.touching, geometry.overlap, 0.0)", [T + "test_sintering_mechanics.py"]),
    ("a contact the shrinkage closes is elastic", "sintercond/sim/neck_growth.py",
     "    closed = after.touching & ~geometry.touching\n",
     "    closed = after.touching & ~geometry.touching & False\n",
     [T + "test_sintering_mechanics.py"]),
    ("point contacts do not sinter", "sintercond/sim/neck_growth.py", "POINT_CONTACT_GAP = 1e-9\n",
     "POINT_CONTACT_GAP = 0.0\n", [T + "test_sintering_mechanics.py"]),
    ("pair necks not padded on reallocation", "sintercond/sim/contacts.py",
     "**{f: pad(getattr(motion, f)) for f in mechanics.PAIR_HISTORY}",
     "**{f: pad(getattr(motion, f)) for f in ('spring', 'rolling')}", [T + "test_sintering_mechanics.py"]),
    ("guard counts the sintered overlap", "sintercond/sim/guards.py",
     "        overlap = overlap - np.asarray(motion.neck_overlap, np.float64)[real]\n",
     "        overlap = overlap - 0.0 * np.asarray(motion.neck_overlap, np.float64)[real]\n",
     [T + "test_sintering_mechanics.py"]),
    ("dump without the neck ratio", "sintercond/run.py",
     '        fields["neck_ratio"] = np.asarray(neck_growth.particle_neck_ratio(state))\n',
     '        pass\n', [T + "test_sintering_scene.py"]),
    # --- rolled beds, packing-file temperatures, the forces on the network's lines (issue 27)
    ("three supports always stable", "sintercond/beds/rolling.py", "                if np.all(lam >= -_TOL):\n",
     "                if True:\n", [T + "test_rolling.py"]),
    ("no support ever pulls", "sintercond/beds/rolling.py", "            if lam_at[a] == 0.0:\n",
     "            lam_at[a] = np.inf\n            if lam_at[a] == 0.0:\n",
     [T + "test_rolling.py"]),
    ("rolled past the equator", "sintercond/beds/rolling.py", "return _Arc(q, s, u, w, math.atan2(u[2], -w[2]))  # the equator",
     "return _Arc(q, s, u, w, 1.2 * math.atan2(u[2], -w[2]))  # the equator", [T + "test_rolling.py"]),
    ("overlap ignored by the walls", "sintercond/beds/rolling.py", "offsets = _wall_offsets(R * shrink, L)",
     "offsets = _wall_offsets(R, L)", [T + "test_rolling.py"]),
    ("fill past the height", "sintercond/beds/rolling.py", "float(surface.mean()) >= fill_height",
     "float(surface.mean()) >= 1.1 * fill_height", [T + "test_rolling.py"]),
    ("dump temperatures not by id", "sintercond/beds/packing_files.py", "None if heat is None else heat[order].copy()",
     "None if heat is None else heat.copy()", [T + "test_packing_files.py"]),
    # tests/test_unaimed_classes.py: classes independently written mutants slipped past (issue 43, item 14)
    ("scaled dump coordinates from the origin", "sintercond/beds/packing_files.py",
     "centres = bounds[:, 0] + centres * (bounds[:, 1] - bounds[:, 0])",
     "centres = centres * (bounds[:, 1] - bounds[:, 0])", [T + "test_unaimed_classes.py"]),
    ("fast table path keeps a diameter", "sintercond/beds/packing_files.py",
     "    radii = values[:, 3] / 2 if diameter else values[:, 3]\n    return values[:, :3].copy()",
     "    radii = values[:, 3]\n    return values[:, :3].copy()", [T + "test_unaimed_classes.py"]),
    ("step estimate at the first sphere's mass", "sintercond/sim/mechanics.py", "forces.effective_mass(mi, mj)",
     "forces.effective_mass(mi, mi)", [T + "test_unaimed_classes.py"]),
    ("mean temperature over the held particles too", "sintercond/sim/rollout.py",
     "    weight = jnp.where(p.fixed, 0.0, p.mass)\n", "    weight = p.mass\n", [T + "test_unaimed_classes.py"]),
    ("softened modulus without its floor", "sintercond/laws/materials.py",
     "    return jnp.where(softened >= E_min, softened, E_min)", "    return softened", [T + "test_unaimed_classes.py"]),
    ("wall friction switched by the pairs' coefficient", "sintercond/scene/build.py", 'wall_friction=c["mu_wall"] > 0,',
     'wall_friction=c["mu"] > 0,', [T + "test_unaimed_classes.py"]),
    ("necks grow a step early", "sintercond/sim/neck_growth.py", "    return step % spec.every == 0\n",
     "    return (step + 1) % spec.every == 0\n", [T + "test_unaimed_classes.py"]),
    ("necks grow over one step of the interval", "sintercond/sim/terms/sintering.py",
     "        elapsed = (state.step - carried.interval_start).astype(state.dt.dtype) * state.dt\n        pairs, neck,",
     "        elapsed = state.dt + 0.0 * carried.interval_start\n        pairs, neck,", [T + "test_unaimed_classes.py"]),
    ("conducting wall's heat out of the packing", "sintercond/output/observe.py",
     'q = k_w * (wall["temperature"] - temperature)', 'q = k_w * (temperature - wall["temperature"])',
     [T + "test_unaimed_classes.py"]),
    ("held wall's heat from every particle", "sintercond/output/observe.py",
     "            flows[k] = -float(np.sum((np.asarray(power) + conducting_power)[mask]))",
     "            flows[k] = -float(np.sum((np.asarray(power) + conducting_power)))", [T + "test_unaimed_classes.py"]),
    ("resume drops the checkpoint step's history row", "sintercond/run.py",
     'if int(r.split(",")[0]) <= step]', 'if int(r.split(",")[0]) < step]', [T + "test_unaimed_classes.py"]),
    ("resume keeps the rows after the checkpoint", "sintercond/run.py",
     'if int(r.split(",")[0]) <= step]', 'if int(r.split(",")[0]) >= 0]', [T + "test_unaimed_classes.py"]),
    ("grain-boundary cap at the full dihedral angle", "sintercond/laws/sintering.py",
     'jnp.minimum(r_i, r_j) * jnp.sin(0.5 * jnp.deg2rad(params["dihedral_angle"]))',
     'jnp.minimum(r_i, r_j) * jnp.sin(0.55 * jnp.deg2rad(params["dihedral_angle"]))', [T + "test_unaimed_classes.py"]),
    ("softening stderr without the value", "fitting/softening.py",
     "stderr = {k: values[k] * float(np.sqrt(log_cov[i, i])) for i, k in enumerate(fit)}",
     "stderr = {k: float(np.sqrt(log_cov[i, i])) for i, k in enumerate(fit)}",
     [T + "test_fit_softening.py::test_temperatures_alone_with_conductivity_known"]),
    ("coupled step ignores the rolling projection", "sintercond/sim/mechanics.py", "projection=spec.rolling_projection",
     "projection=False", [T + "test_unaimed_classes.py"]),
    ("projection keeps the twist", "sintercond/laws/forces.py", "        rate = tangential_part(rate, normal)\n",
     "        rate = rate + 0.0 * tangential_part(rate, normal)\n", [T + "test_unaimed_classes.py"]),
    ("settle report without the walls' overlaps", "sintercond/beds/settle.py",
     "figures[\"force\"], float(force_tol), _overlaps(final, radii, physics.mechanics.walls),",
     "figures[\"force\"], float(force_tol), _overlaps(final, radii, ()),", [T + "test_unaimed_classes.py"]),
    ("settle force ratio over the mass", "sintercond/beds/settle.py",
     "    ratio = jnp.linalg.norm(force, axis=1) / (p.mass * GRAVITY)\n",
     "    ratio = jnp.linalg.norm(force, axis=1) / (p.mass * GRAVITY) / 10.0\n", [T + "test_unaimed_classes.py"]),
    ("file temperatures dropped", "sintercond/scene/build.py", "        return np.array(file_temperatures(scene.packing))",
     "        return scene.initial.temperature", [T + "test_packing_files.py"]),
    ("capacity at the start temperature", "sintercond/sim/terms/conduction.py",
     "    if physics.conduction.specific_heat_table:\n        return thermal.enthalpy_update(",
     "    if False:\n        return thermal.enthalpy_update(", [T + "test_specific_heat_table.py"]),
    ("stable step at the largest c", "sintercond/sim/stability.py",
     "specific_heat=jnp.min(jnp.asarray(params.specific_heat.values))[None]",
     "specific_heat=jnp.max(jnp.asarray(params.specific_heat.values))[None]", [T + "test_specific_heat_table.py"]),
    ("enthalpy inverse off the segment's slope", "sintercond/laws/materials.py",
     "jnp.sqrt(jnp.maximum(values[k] ** 2 + 2.0 * slope[k] * d, 0.0))",
     "jnp.sqrt(jnp.maximum(values[k] ** 2 + 1.9 * slope[k] * d, 0.0))", [T + "test_specific_heat_table.py"]),
    # tests/test_table_ends.py: tables below and above their nodes against np.interp and quadrature
    ("enthalpy below the nodes at the second value", "sintercond/laws/materials.py",
     "+ values[0] * jnp.minimum(theta - temperatures[0], 0.0)", "+ values[1] * jnp.minimum(theta - temperatures[0], 0.0)",
     [T + "test_table_ends.py"]),
    ("enthalpy above the nodes at the last but one value", "sintercond/laws/materials.py",
     "+ values[-1] * jnp.maximum(theta - temperatures[-1], 0.0)",
     "+ values[-2] * jnp.maximum(theta - temperatures[-1], 0.0)", [T + "test_table_ends.py"]),
    ("inverse above the nodes by the first value", "sintercond/laws/materials.py",
     "+ jnp.maximum(integral - upto[-1], 0.0) / values[-1])", "+ jnp.maximum(integral - upto[-1], 0.0) / values[0])",
     [T + "test_table_ends.py"]),
    ("table extrapolated below its nodes", "sintercond/laws/materials.py",
     "    inside = jnp.clip(theta, temperatures[0], temperatures[-1])\n    k = jnp.clip(",
     "    inside = jnp.clip(theta, -jnp.inf, temperatures[-1])\n    k = jnp.clip(", [T + "test_table_ends.py"]),
    ("normal force pulls", "sintercond/output/observe.py", '"normal_force": -np.sum(force', '"normal_force": np.sum(force',
     [T + "test_contact_network.py"]),
]


def _copy_repo(destination: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, capture_output=True,
                           check=True).stdout.decode().split("\0")
    for name in filter(None, files):
        source = ROOT / name
        if source.is_file():
            (destination / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, destination / name)


def _check(mutants) -> list[str]:
    problems = []
    for name, module, original, mutated, tests in mutants:
        count = (ROOT / module).read_text().count(original)
        if count != 1 or original == mutated:
            problems.append(f"{name}: snippet found {count} times in {module}")
        for test in tests:
            if not (ROOT / test.split("::")[0]).exists():
                problems.append(f"{name}: no test file {test}")
    return problems


def run(mutants, timeout):
    rows = []
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    with tempfile.TemporaryDirectory(prefix="sintercond-mutants-") as tmp:
        work = Path(tmp)
        _copy_repo(work)
        for name, module, original, mutated, tests in mutants:
            path = work / module
            text = path.read_text()
            path.write_text(text.replace(original, mutated, 1))
            t0 = time.perf_counter()
            try:
                proc = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-n0", "-p", "no:cacheprovider", *tests],
                                      cwd=work, env=env, capture_output=True, text=True, timeout=timeout)
                status = "survived" if proc.returncode == 0 else "killed"
                if proc.returncode not in (0, 1):  # collection errors, crashes: killed, but say so
                    status = f"killed (pytest exit {proc.returncode})"
            except subprocess.TimeoutExpired:
                status = "killed (timeout)"
            finally:
                path.write_text(text)
            seconds = time.perf_counter() - t0
            rows.append((name, module, status, " ".join(t.replace("tests/", "") for t in tests), f"{seconds:.0f}"))
            print(*rows[-1], sep="\t", flush=True)
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--record", action="store_true",
                        help="only rewrite RESULTS.md's section from results/mutation.csv (runs nothing)")
    parser.add_argument("--only", default=None, help="run the mutants whose name contains this (several: A|B)")
    parser.add_argument("--check", action="store_true", help="only check that every snippet is found once")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per mutant")
    parser.add_argument("--no-write", action="store_true", help="do not rewrite RESULTS.md")
    parser.add_argument("--merge", action="store_true",
                        help="with --only: replace those mutants' rows in the record and rewrite RESULTS.md")
    args = parser.parse_args()
    mutants = [m for m in MUTANTS if args.only is None or any(o in m[0] for o in args.only.split("|"))]
    problems = _check(mutants)
    if problems or args.check:
        print("\n".join(problems) or f"{len(mutants)} mutants, every snippet found once")
        sys.exit(1 if problems else 0)
    if args.record:
        write_record([])
        return
    rows = run(mutants, args.timeout)
    killed = sum(r[2].startswith("killed") for r in rows)
    print(f"{killed} of {len(rows)} mutants killed ({100 * killed / len(rows):.1f} %)")
    for r in rows:
        if not r[2].startswith("killed"):
            print(f"survived: {r[0]} ({r[1]}): {EXPLAINED.get(r[0], 'not explained')}")
    if (args.only is None or args.merge) and not args.no_write:
        write_record(rows)


def _recorded_rows() -> dict:
    """The rows of benchmarks/results/mutation.csv by mutant name (empty if there is none)."""
    if not CSV.exists():
        return {}
    with CSV.open(newline="") as f:
        return {row[0]: tuple(row) for row in list(csv.reader(f))[1:]}


def write_record(rows) -> None:
    """Write every mutant's row to the CSV and the counts per module to RESULTS.md.

    ``rows`` replace the recorded rows of the same mutants; recorded rows of mutants no longer in
    :data:`MUTANTS` are dropped. The record must then cover every mutant (run the missing ones first).
    """
    from _common import command_line, markdown_table, write_section

    merged = {**_recorded_rows(), **{r[0]: tuple(r) for r in rows}}
    missing = [m[0] for m in MUTANTS if m[0] not in merged]
    if missing:
        raise SystemExit(f"the record lacks {len(missing)} mutants ({', '.join(missing[:5])}...): run them first")
    rows = [merged[m[0]] for m in MUTANTS]
    CSV.parent.mkdir(exist_ok=True)
    with CSV.open("w", newline="") as f:
        csv.writer(f).writerows([("mutant", "module", "result", "tests", "seconds"), *rows])
    killed = sum(r[2].startswith("killed") for r in rows)
    modules = sorted({r[1] for r in rows})
    summary = f"{killed} of {len(rows)} mutants killed ({100 * killed / len(rows):.1f} %) in {len(modules)} modules"
    per_folder = []
    for folder in sorted({m.rsplit("/", 1)[0] for m in modules}):
        mine = [m for m in modules if m.rsplit("/", 1)[0] == folder]
        counts = []
        for module in mine:
            rows_of = [r for r in rows if r[1] == module]
            killed_of = sum(r[2].startswith("killed") for r in rows_of)
            counts.append(f"{module.rsplit('/', 1)[1]} {killed_of}/{len(rows_of)}")
        seconds = sum(float(r[4]) for r in rows if r[1] in mine)
        per_folder.append((folder, "; ".join(counts), f"{seconds:.0f}"))
    survivors = [r for r in rows if not r[2].startswith("killed")]
    body = (
        "## Mutation testing\n\n"
        "Small deliberate bugs (benchmarks/mutation.py: each replaces one snippet of one module) against the "
        "tests of that module (`pytest -x`). Killed: the tests fail. "
        f"{summary}. Every mutant's result: [results/mutation.csv](results/mutation.csv).\n\n"
        + markdown_table(("folder", "module killed/mutants", "seconds"), per_folder)
        + ("\n\nSurvivors:\n" + "\n".join(f"- {r[0]} ({r[1]}): {EXPLAINED.get(r[0], 'not explained')}"
                                         for r in survivors) if survivors else "\n\nNo survivors.")
    )
    command = command_line()
    if "--only" in sys.argv:  # a merged record: the names of the rerun mutants are in the CSV, not the command
        chosen = sys.argv[sys.argv.index("--only") + 1]
        command = command.replace(chosen, f"'<{len(chosen.split('|'))} mutants>'")
    write_section("mutation", command, body)


if __name__ == "__main__":
    main()
