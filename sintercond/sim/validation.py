"""The checks of a simulation's input, on concrete values before anything compiles: each names the field and the
allowed range (diffrax's ``_integrate.py`` habit), with the float32 precision warning of a mechanical state."""

from __future__ import annotations

import warnings

import jax.numpy as jnp
import numpy as np

from sintercond.laws import materials
from sintercond.sim import mechanics, neck_growth
from sintercond._validation import all_concrete, fail_where, require_positive
from sintercond.sim.state import Params, SimState, Simulator
from sintercond.sim.terms import sources


MAX_INITIAL_OVERLAP = 0.5
"""Deepest sphere-sphere overlap a mechanical run may start from, as a fraction of the smaller radius: Hertz's law
(a small-strain law) would blow such spheres apart."""


def _checked_property(name, value, tabulated, symbol, unit, bound, needs):
    """``[n_materials]`` values of ``Params.<name>``, a :class:`sintercond.laws.materials.Table` where the spec's
    ``<name>_table`` says so (one material: its first node's value); raises ``ValueError`` naming the field."""
    field = f"Params.{name}"
    if tabulated:
        if not isinstance(value, materials.Table):
            raise ValueError(f"Conduction.{name}_table needs {field} as a sintercond.laws.materials.Table "
                             f"(materials.tabulated(T, {symbol})); got {value!r}")
        if value.extrapolate:
            raise ValueError(f"{field} (a table) must clamp at its ends (extrapolate=False): the stable step is "
                             f"bounded by the table's {bound}")
        nodes, values = np.asarray(value.temperatures, np.float64), np.asarray(value.values, np.float64)
        require_positive(f"{field} table's temperatures (K)", nodes)
        if nodes.ndim != 1 or nodes.shape != values.shape or len(nodes) < 2 or not np.all(np.diff(nodes) > 0):
            raise ValueError(f"{field} (a table) needs >= 2 strictly increasing temperatures (K) and as many "
                             f"values; got {nodes.tolist()} and {values.tolist()}")
        require_positive(f"{field} table's values ({unit})", values)
        return values[:1]  # one material
    if isinstance(value, materials.Table):
        raise ValueError(f"{field} is a table: set Conduction.{name}_table=True{needs}")
    return np.atleast_1d(np.asarray(value, np.float64))


def check_save_interval(n_steps, every) -> None:
    """Raise ``ValueError`` unless ``n_steps`` and ``every`` (``SaveAt.every``) are integers >= 1 and ``every``
    divides ``n_steps``: a rollout saves at the end of every ``every`` steps."""
    if not (isinstance(n_steps, int) and isinstance(every, int) and n_steps >= 1 and every >= 1):
        raise ValueError(f"n_steps and saveat.every must be integers >= 1; got {n_steps!r}, {every!r}")
    if n_steps % every:
        raise ValueError(f"n_steps ({n_steps}) must be a multiple of saveat.every ({every}); "
                         f"{n_steps // every * every} or {(n_steps // every + 1) * every} would do")


def validate_inputs(sim: Simulator, state: SimState, params: Params) -> None:
    """Raise ``ValueError`` naming the field and the allowed range unless ``(state, params)`` can run on ``sim``.

    Checked on concrete input, before anything compiles (:func:`rollout` calls it
    when nothing is traced, :func:`sintercond.rollout.advance` always): the
    time step finite and > 0; conductivities and specific heats finite and > 0,
    one per material, every particle's material among them; finite positions
    and temperatures > 0 K; with mechanics the contact parameters
    (:func:`sintercond.sim.mechanics.validate_mechanical_params`, the scene's rules),
    finite velocities and spins, and no two listed spheres at the same centre
    or overlapping by more than :data:`MAX_INITIAL_OVERLAP` of the smaller
    radius. Traced leaves are skipped (under ``jit`` they are the caller's).
    """
    sources.validate(sim.physics, params)
    if sim.physics.conduction.coupling == "sphere" and getattr(state.contacts, "sphere", None) is None:
        raise ValueError("Conduction.coupling='sphere' needs SimState.contacts built for it: "
                         "simulate.lifted_contacts(physics, ...) with that physics (the necks' directions)")
    if not all_concrete(state, params):
        return
    if sim.physics.conduction.coupling == "sphere" and sim.physics.sintering is not None:
        _check_coupled_at_cap(state)
    dt = np.asarray(state.dt, np.float64)
    if not (dt.shape == () and np.isfinite(dt) and dt > 0):
        raise ValueError(f"SimState.dt (the time step) must be finite and > 0 s; got {state.dt!r}")
    conduction = sim.physics.conduction
    kappa = _checked_property("conductivity", params.conductivity, conduction.conductivity_table, "kappa",
                              "W/(m K)", "largest conductivity", " (with conductance='lifted')")
    heat = _checked_property("specific_heat", params.specific_heat, conduction.specific_heat_table, "c",
                             "J/(kg K)", "smallest specific heat", "")
    if kappa.ndim != 1 or heat.shape != kappa.shape:
        raise ValueError(f"Params.conductivity and Params.specific_heat must be [n_materials] each; got shapes "
                         f"{kappa.shape} and {heat.shape}")
    require_positive("Params.conductivity (W/(m K))", kappa)
    require_positive("Params.specific_heat (J/(kg K))", heat)
    p = state.particles
    material = np.asarray(p.material)
    if material.size and not (0 <= material.min() and material.max() < len(kappa)):
        raise ValueError(f"particle materials must index Params.conductivity ({len(kappa)} materials); got "
                         f"materials {material.min()}..{material.max()}")
    fail_where(~np.isfinite(np.asarray(p.positions)).all(axis=1),
               lambda i: f"particle positions must be finite; particle {i[0]} is not")
    require_positive("particle temperatures (K)", np.asarray(p.temperature, np.float64))
    if sim.physics.conduction.held_ramp:
        ramp = params.held_ramp
        if ramp is None:
            raise ValueError("Conduction.held_ramp needs Params.held_ramp (simulate.HeldRampParams)")
        if all_concrete(ramp):
            require_positive("Params.held_ramp.end_temperature (K)", np.asarray(ramp.end_temperature, np.float64))
            require_positive("Params.held_ramp.duration (s)", np.asarray(ramp.duration, np.float64))
            steps = np.asarray(ramp.steps, np.float64)
            if not (steps.shape == () and steps >= 1 and steps == np.round(steps)):
                raise ValueError(f"Params.held_ramp.steps must be a whole number >= 1; got {ramp.steps!r}")
    if sim.physics.sintering is not None:
        if state.sintering is None:
            raise ValueError("Physics.sintering needs SimState.sintering (simulate.init_state(..., "
                             "sintering=neck_growth.neck_state(contacts, temperature)))")
        neck_growth.validate_sintering(sim.physics.sintering, params.sintering, state.contacts, p.radii,
                                       state.sintering)
        if sim.physics.mechanics is not None:
            neck_growth.validate_pair_necks(state.mechanics, p.radii, state.contacts.pairs.pairs)
    if sim.physics.mechanics is None:
        return
    if params.mechanics is None:
        raise ValueError("Physics.mechanics needs Params.mechanics (sintercond.sim.mechanics.MechanicalParams)")
    mechanics.validate_mechanical_params(params.mechanics, len(kappa))
    m = state.mechanics
    for name in ("velocity", "spin"):
        value = np.asarray(getattr(m, name), np.float64)
        fail_where(~np.isfinite(value).all(axis=-1), lambda i, name=name: f"MechanicalState.{name} must be finite; "
                                                                          f"particle {i[0]} is not")
    pairs = np.asarray(state.contacts.pairs.pairs)
    n = p.radii.shape[0]
    pairs = pairs[(pairs[:, 0] < n) & (pairs[:, 1] < n)]
    if len(pairs):
        x, r = np.asarray(p.positions, np.float64), np.asarray(p.radii, np.float64)
        i, j = pairs[:, 0], pairs[:, 1]
        distance = np.linalg.norm(x[i] - x[j], axis=1)
        depth = (r[i] + r[j] - distance) / np.minimum(r[i], r[j])
        _warn_float32_positions(p.positions, r[i] + r[j] - distance)
        deep = depth > MAX_INITIAL_OVERLAP
        if deep.any():
            k = int(np.argmax(depth))
            where = "at the same centre" if distance[k] <= 1e-12 * (r[i[k]] + r[j[k]]) else (
                f"overlapping by {depth[k]:.3g} of the smaller radius ({r[i[k]] + r[j[k]] - distance[k]:.3g} m)")
            raise ValueError(f"particles {int(i[k])} and {int(j[k])} are {where}; a mechanical run may start from "
                             f"overlaps of at most {MAX_INITIAL_OVERLAP:g} of the smaller radius (Hertz's law would "
                             "blow them apart): move them apart")


class PrecisionWarning(UserWarning):
    """The state's dtype cannot resolve what the run must resolve (float32 positions and nanometre overlaps)."""


FLOAT32_OVERLAP_STEPS = 64
"""Fewest float32 steps of the positions a touching pair's overlap should span before :class:`PrecisionWarning`."""


def _check_coupled_at_cap(state: SimState) -> None:
    """With growing necks every contact must be in the coupled geometry (built on the necks at the cap), except
    those joining two held particles."""
    g, p = state.contacts.sphere, state.particles
    coupled = np.asarray(g.coupled).reshape(-1)[np.asarray(g.neck_slots)].any(axis=1)
    pairs, fixed = np.asarray(state.contacts.pairs), np.asarray(p.fixed)
    missing = ~coupled & ~(fixed[pairs[:, 0]] & fixed[pairs[:, 1]])
    if missing.any():
        i, j = (int(v) for v in pairs[np.argmax(missing)])
        raise ValueError(f"Conduction.coupling='sphere' with Physics.sintering: contact ({i}, {j}) is not in the "
                         "coupled geometry; build it on the necks at the kinetic law's cap: "
                         "simulate.coupled_contacts(contacts, centres, radii, neck_growth.necks_at_cap(...).neck)")


def _warn_float32_positions(positions, overlaps):
    """Warn when float32 positions resolve the contacts' overlaps in a few float32 steps only: contacts then open
    and close on round-off (a stiff settled bed loses a third of its touching pairs), where float64 positions with
    float32 laws (``Mechanics(force_dtype="float32")``) keep them."""
    if positions.dtype != jnp.float32:
        return
    touching = overlaps[overlaps > 0]
    if not touching.size:
        return
    ulp = float(np.spacing(np.float32(np.max(np.abs(np.asarray(positions))))))
    smallest = float(np.median(touching))
    if smallest < FLOAT32_OVERLAP_STEPS * ulp:
        warnings.warn(f"float32 positions resolve the contacts' overlaps (median {smallest:.3g} m) in "
                      f"{smallest / ulp:.0f} float32 steps of {ulp:.3g} m only: contacts will open and close on "
                      "round-off. Run with float64 positions (SINTERCOND_ENABLE_X64=1, the default) and "
                      "Mechanics(force_dtype='float32') for float32 contact laws", PrecisionWarning, stacklevel=3)


SLOWEST_APPROACH = 1e-9
"""Approach speed (m/s) :func:`check_mechanical_step` assumes of a state at rest: its contacts' own overlaps set the
limit then."""


def check_mechanical_step(sim: Simulator, state: SimState, params: Params) -> None:
    """Raise ``ValueError`` when a mechanical state's time step exceeds the stability limit of its stiffest contact
    as it stands (Quintana-Ruiz & Campello 2020, Eq. 47, and the symplectic-Euler bounds of MECHANICS.md's
    erratum 8, :func:`sintercond.sim.mechanics.mechanical_time_step` with ``fraction = safety = 1``): at the deepest
    overlap of its listed pairs and walls and the fastest relative speed of its listed pairs (or of a particle
    against a wall). Beyond it the step adds energy at every contact and the packing flies apart.

    A bound on the state, not on the run: contacts that a fall or an impact will press deeper are the caller's to
    size for (``mechanical_time_step`` with the approach speed expected) or the run's guards'
    (:func:`sintercond.sim.guards.motion_guard`). Traced states are not checked.
    """
    spec = sim.physics.mechanics
    if spec is None or not all_concrete(state, params):
        return
    p = state.particles
    x, r = np.asarray(p.positions, np.float64), np.asarray(p.radii, np.float64)
    v = np.asarray(state.mechanics.velocity, np.float64)
    n = len(r)
    pairs = np.asarray(state.contacts.pairs.pairs)
    pairs = pairs[(pairs[:, 0] < n) & (pairs[:, 1] < n)]
    i, j = pairs[:, 0], pairs[:, 1]
    depth = [r[i] + r[j] - np.linalg.norm(x[i] - x[j], axis=1)]
    speed = [np.linalg.norm(v[i] - v[j], axis=1)]
    if spec.walls:
        depth.append(np.ravel(mechanics.wall_penetration(spec.walls, x, r, float(np.asarray(state.time)))))
        speed += [np.linalg.norm(v, axis=1) + np.linalg.norm(np.asarray(w.velocity)) for w in spec.walls]
    delta = max(float(np.max(np.concatenate(depth), initial=0.0)), 0.0)
    v_rel = max(float(np.max(np.concatenate(speed), initial=0.0)), SLOWEST_APPROACH)
    limit = float(mechanics.mechanical_time_step(spec, p, state.contacts.neighbor_list.idx, params.mechanics, v_rel,
                                                 delta=delta, fraction=1.0, safety=1.0))
    dt = float(np.asarray(state.dt))
    if dt > limit:
        raise ValueError(f"SimState.dt = {dt:.6g} s exceeds the stability limit {limit:.6g} s of the state's stiffest "
                         f"contact (overlap {delta:.3g} m, relative speed {v_rel:.3g} m/s; Eq. 47 and the "
                         f"symplectic-Euler bounds at E0): the packing would fly apart. Use dt <= {limit:.6g} s, or "
                         "size it with sintercond.sim.mechanics.mechanical_time_step at the approach speed you expect")
