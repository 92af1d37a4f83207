"""Heat conduction on a static pipe network: the explicit and implicit updates.

Lumped capacitances ``C_i = m_i c`` exchange heat through the network,
``C_i dT_i/dt = sum_j K_ij (T_j - T_i)`` (Rojek et al. 2022, Eqs. 1-4);
particles may be held at fixed temperatures. For a static packing the
conductances are computed once (:mod:`sintercond.contacts.network`) and each step is
one gather-and-sum over the padded contact table.

* :func:`table_time_step`: ``min_i C_i / sum_j K_ij``. At or below it
  explicit Euler is stable and every new temperature is a convex combination
  of old ones (discrete maximum principle).
* :func:`explicit_update` / :func:`backward_euler_solve`: one step; the
  implicit step solves ``(C/dt + L) T' = C/dt T`` by conjugate gradients and
  is stable for any ``dt``.

Time stepping a whole table network is :func:`sintercond.simulate.simulate_table`
(a convenience over the simulator); steady states and ``k*`` are in
:mod:`sintercond.sim.steady`.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.sparse.linalg import cg

from sintercond.laws import heat_sources, materials
from sintercond._validation import shown
from sintercond._deprecation import old_names
from sintercond._numerics import materialized
from sintercond._symmetric import linear_call
from sintercond.contacts.network import (ContactTable, gather_laplacian, network_laplacian,
                                         total_conductance)


def table_time_step(capacity, table: ContactTable):
    """Largest explicit-Euler step with the maximum principle: ``min_i C_i / sum_j K_ij`` (s).

    Args:
      capacity: ``[n]`` heat capacities ``C_i`` (J/K), or a scalar.
      table: the network.
    """
    return explicit_stability_limit(capacity, total_conductance(table))


def explicit_stability_limit(capacity, total):
    """``min_i C_i / G_i`` (s) over particles with ``G_i > 0`` (inf if none): ``G_i`` the diagonal of the
    linear operator (conductances to neighbours and walls, linearised sources), ``C_i`` in J/K."""
    capacity = jnp.broadcast_to(jnp.asarray(capacity, total.dtype), total.shape)
    return jnp.min(jnp.where(total > 0, capacity / jnp.where(total > 0, total, 1.0), jnp.inf))


def check_table_time_step(dt, capacity, table: ContactTable) -> float:
    """Raise ``ValueError`` if an explicit step ``dt`` exceeds :func:`table_time_step`; returns the limit.

    For concrete input at the API boundary (scene loading), before anything
    is compiled.
    """
    limit = float(table_time_step(capacity, table))
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0 s; got {shown(dt)}")
    if dt > limit:
        raise ValueError(f"dt = {dt:.6g} s exceeds the explicit stability limit min(C_i / sum_j K_ij) = {limit:.6g} s; "
                         f"use dt <= {limit:.6g} s or the implicit integrator")
    return limit


def explicit_update(temperature, power, capacity, dt, fixed_mask=None, fixed_temperature=None, *, network=None,
                    pulse=None, rates=None):
    """The explicit Euler update ``T + dt P / C``, held particles reset to their values.

    The one explicit step of the package: every caller (the simulator of
    :mod:`sintercond.simulate`, hence ``sintercond run``, the inverse
    experiments and the benchmarks) goes through it. ``power`` ``[n]`` (W) is
    the heat into each particle (:func:`heat_power` and conduction),
    ``capacity`` ``C_i = m_i c`` (J/K), Rojek et al. (2022) Eq. 1.

    ``network=(scale, conductance, neighbors)`` adds the conduction of a
    padded table, ``P - scale L T`` (:func:`sintercond.contacts.network.network_laplacian`;
    ``scale`` a scalar or ``[n]``), inside the update: the same numbers as
    passing that power, with a derivative written for reverse mode
    (:func:`_conduction_update`). ``pulse=(field, switch)`` adds
    ``switch * field`` (W; a loop-invariant ``[n]`` field and a scalar, as
    :func:`source_power_parts` returns them) to ``power``: the same numbers,
    and with a network reverse mode keeps the scalar per step, not the sum.
    With a network the derivative in ``scale`` and ``capacity`` goes through
    ``rates``, :func:`conduction_rates` of them (computed here if None): a
    loop computed once outside its steps (:func:`sintercond.simulate.rollout`
    does) then accumulates per-particle cotangents of the rates in reverse
    mode instead of reducing one for ``scale`` at every step.
    """
    if network is None:
        if pulse is not None:
            power = power + pulse[1] * pulse[0]
        new = temperature + dt * power / capacity
    else:
        field, switch = (jnp.zeros((), temperature.dtype), jnp.zeros((), temperature.dtype)) if pulse is None else pulse
        scale, conductance, neighbors = network
        rate, inverse_capacity = conduction_rates(scale, capacity) if rates is None else rates
        # scale and capacity set the numbers; their derivative is that of the rates
        new = _conduction_update(temperature, power, field, switch, jax.lax.stop_gradient(capacity), dt,
                                 jax.lax.stop_gradient(scale), conductance, neighbors, rate, inverse_capacity)
    return _held(new, fixed_mask, fixed_temperature)


def _held(new, fixed_mask, fixed_temperature):
    """``new`` with the held particles (``fixed_mask``, or none if None) reset to ``fixed_temperature``."""
    if fixed_mask is None:
        return new
    return jnp.where(fixed_mask, fixed_temperature, new)


def enthalpy_update(temperature, power, mass, dt, specific_heat, fixed_mask=None, fixed_temperature=None):
    """The explicit Euler step of the enthalpy with a specific heat against temperature: ``h(T') = h(T) + dt P / m``.

    ``h(T) = int c dT`` of the clamped table ``specific_heat`` (a :class:`sintercond.laws.materials.Table`,
    :func:`sintercond.laws.materials.integrate_table`), inverted in closed form on its quadratic pieces
    (:func:`sintercond.laws.materials.invert_table_integral`): each particle's enthalpy moves by exactly the heat
    in, so a network's exchange (``sum_i P_i = 0``) keeps ``sum_i m_i h(T_i)`` to round-off, and the step is
    Rojek et al. (2022) Eq. 2's ``C dT/dt = P`` with ``C = m c(T)`` at first order. ``power`` ``[n]`` (W),
    ``mass`` ``[n]`` (kg); held particles reset to their values.
    """
    nodes, values = specific_heat.temperatures, specific_heat.values
    enthalpy = materials.integrate_table(temperature, nodes, values) + dt * power / mass
    new = materials.invert_table_integral(enthalpy, nodes, values).astype(temperature.dtype)
    return _held(new, fixed_mask, fixed_temperature)


def conduction_rates(scale, capacity):
    """``(scale / C, 1 / C)``: the factors of the conduction and of the heat power in :func:`explicit_update`
    with a network (``scale`` in units of the table's, ``C`` in J/K)."""
    return scale / capacity, 1.0 / capacity


@jax.custom_jvp
def _conduction_update(temperature, power, pulse, switch, capacity, dt, scale, conductance, neighbors, rate,
                       inverse_capacity):
    """``T + dt (P + w Q - s L T) / C`` (K) with a derivative cheap in reverse mode.

    ``Q`` is a loop-invariant pulse field and ``w`` its scalar switch at this
    step (zeros without one): kept apart so that a differentiated scan stores
    ``w`` per step and ``Q`` once, as a hand adjoint recomputes the pulse
    from the step index.

    The value uses ``s`` and ``C``; the derivative in them comes through
    ``rate = s / C`` and ``inverse_capacity = 1 / C`` (``s`` and ``C``
    themselves must carry no tangent: :func:`explicit_update` stops them), as
    ``T + dt (P + w Q) / C - dt (s / C) L T``. A loop that computes the two
    once outside its steps then accumulates their cotangents per particle,
    ``-dt ct L T`` and ``dt ct (P + w Q)``, one pass each that reads ``L T``
    once, where a scalar ``s`` would need a reduction at every step.

    JAX's own transpose of this update runs about ten kernels per step on a
    CPU (each cotangent its own pass, and a gather of ``dt / C * ct`` that
    XLA fuses so that it reads two arrays per slot). Here the tangent is one
    ``linear_call`` whose transpose (:func:`_conduction_transpose`) is
    written out: with ``v = dt ct / C``, ``ct_T = ct - L (s v)`` (``L``
    symmetric: the same gather as the forward, of one materialised array),
    ``ct_P = v``. The residuals per step are ``L T`` (when the rate is
    differentiated) and ``P``, ``w`` (when ``1 / C`` is; ``Q`` is
    loop-invariant). A tangent of ``dt``, of the switch or of the
    conductances (lifted conductances) falls back to JAX's derivative of the
    same formula.
    """
    return _conduction_formula(temperature, power, pulse, switch, capacity, dt, scale, conductance, neighbors)


def _conduction_formula(temperature, power, pulse, switch, capacity, dt, scale, conductance, neighbors):
    lt = network_laplacian(conductance, neighbors, temperature)
    return _conduction_value(temperature, power, pulse, switch, capacity, dt, scale, lt)


def _conduction_value(temperature, power, pulse, switch, capacity, dt, scale, lt):
    """``T + dt (P + w Q - s L T) / C`` from ``L T`` (``lt``): the value of :func:`_conduction_update`."""
    return temperature + dt * (power + switch * pulse - scale * lt) / capacity


def _factored_formula(temperature, power, pulse, switch, dt, conductance, neighbors, rate, inverse_capacity):
    """:func:`_conduction_formula` in the rates (its derivative; the value differs in rounding)."""
    lt = network_laplacian(conductance, neighbors, temperature)
    return temperature + dt * (power + switch * pulse) * inverse_capacity - dt * rate * lt


def _conduction_update_jvp(primals, tangents):
    temperature, power, pulse, switch, capacity, dt, scale, conductance, neighbors, rate, inverse_capacity = primals
    d_t, d_p, d_q, d_w, d_c, d_dt, d_s, d_k, _, d_r, d_b = tangents
    zero = lambda x: isinstance(x, jax.custom_derivatives.SymbolicZero)  # noqa: E731
    if not (zero(d_c) and zero(d_s)):
        raise ValueError("_conduction_update: differentiate scale and capacity through the rates "
                         "(thermal.explicit_update stops them)")
    lt = network_laplacian(conductance, neighbors, temperature)
    out = _conduction_value(temperature, power, pulse, switch, capacity, dt, scale, lt)
    if not (zero(d_dt) and zero(d_k) and zero(d_w)):
        args = (temperature, power, pulse, switch, dt, conductance)
        arg_tangents = (d_t, d_p, d_q, d_w, d_dt, d_k)
        rest = (rate, inverse_capacity)
        instantiate = [jnp.zeros(x.shape, x.dtype) if zero(d) else d
                       for x, d in zip(args + rest, arg_tangents + (d_r, d_b))]
        _, tangent = jax.jvp(lambda t, p, q, w, h, k, r, b: _factored_formula(t, p, q, w, h, k, neighbors, r, b),
                             args + rest, tuple(instantiate))
        return out, tangent
    present = [(k, d) for k, d in zip("tpqrb", (d_t, d_p, d_q, d_r, d_b)) if not zero(d)]
    if not present:
        return out, jnp.zeros_like(out)
    names = "".join(k for k, _ in present)
    # per-step residuals only as needed: L T (derivative in the rate), P and w (in 1 / C); Q is loop-invariant
    in_b = "b" in names
    residuals = (lt if "r" in names else None, power if in_b else None, pulse if in_b else None,
                 switch if (in_b or "q" in names) else None, capacity, dt, scale, conductance, neighbors)
    shapes = (jnp.shape(rate), jnp.shape(inverse_capacity))
    tangent, = linear_call(functools.partial(_conduction_tangent, names),
                           functools.partial(_conduction_transpose, names, shapes), residuals, [d for _, d in present])
    return out, tangent


def _conduction_tangent(names, residuals, linear):
    lt, power, pulse, switch, capacity, dt, scale, conductance, neighbors = residuals
    d = dict(zip(names, linear))
    d_power = 0.0
    if "t" in d:
        d_power = -scale * network_laplacian(conductance, neighbors, d["t"])
    if "p" in d:
        d_power = d_power + d["p"]
    if "q" in d:
        d_power = d_power + switch * d["q"]
    tangent = dt * d_power / capacity
    if "r" in d:
        tangent = tangent - dt * d["r"] * lt
    if "b" in d:
        tangent = tangent + dt * (power + switch * pulse) * d["b"]
    if "t" in d:
        tangent = tangent + d["t"]
    return [jnp.broadcast_to(tangent, capacity.shape)]


def _conduction_transpose(names, shapes, residuals, cotangents):
    lt, power, pulse, switch, capacity, dt, scale, conductance, neighbors = residuals
    rate_shape, inverse_shape = shapes
    (ct,) = cotangents
    v = dt * ct / capacity  # the cotangent of the power
    out = {"p": _unbroadcast(v, jnp.shape(power) if power is not None else ct.shape)}
    if "q" in names:
        out["q"] = _unbroadcast(switch * v, jnp.shape(pulse))
    if "t" in names:  # L symmetric: L^T (s v) = L (s v), one gather of one array
        sv = scale * v if jnp.ndim(scale) == 0 else materialized(scale * v)
        out["t"] = ct - gather_laplacian(conductance, neighbors, sv)
    if "r" in names:
        out["r"] = _unbroadcast(-dt * ct * lt, rate_shape)
    if "b" in names:
        out["b"] = _unbroadcast(dt * ct * (power + switch * pulse), inverse_shape)
    return [out[k] for k in names]


def _unbroadcast(x, shape):
    """Sum ``x`` ``[n]`` down to ``shape`` (``()`` or ``[n]``), the transpose of a broadcast."""
    return x if x.shape == tuple(shape) else jnp.sum(x).reshape(shape)


_conduction_update.defjvp(_conduction_update_jvp, symbolic_zeros=True)


def backward_euler_solve(temperature, laplacian_fn, wall_diagonal, wall_source, capacity, dt, fixed_mask=None,
                         fixed_temperature=None, tol=1e-13):
    """One backward Euler step: solve ``(C/dt + L + K_w) T' = C/dt T + K_w T_w`` by conjugate gradients.

    Unconditionally stable (the matrix is symmetric positive definite); held
    particles enter as Dirichlet values. ``laplacian_fn(x)`` applies the
    network Laplacian, ``wall_diagonal`` ``[n]`` is ``sum_w K_iw`` and
    ``wall_source`` ``[n]`` is ``sum_w K_iw T_w`` (None: no walls). ``tol``
    is CG's relative residual.
    """
    capacity = jnp.broadcast_to(jnp.asarray(capacity, temperature.dtype), temperature.shape)
    free = jnp.ones_like(temperature, dtype=bool) if fixed_mask is None else ~fixed_mask
    held = jnp.zeros_like(temperature) if fixed_mask is None else jnp.where(fixed_mask, fixed_temperature, 0.0)
    diagonal = capacity / dt if wall_diagonal is None else capacity / dt + wall_diagonal

    def matvec(x):  # identity on held rows, (C/dt + L + K_w) restricted to free ones
        x_free = jnp.where(free, x, 0.0)
        return jnp.where(free, diagonal * x_free + laplacian_fn(x_free), x)

    rhs = capacity / dt * temperature - laplacian_fn(held)
    if wall_source is not None:
        rhs = rhs + wall_source
    rhs = jnp.where(free, rhs, held)
    solution, _ = cg(matvec, rhs, x0=jnp.where(free, temperature, held), tol=tol, maxiter=10 * temperature.shape[0])
    return jnp.where(free, solution, held)


def held_solve(apply_fn, fixed_mask, held, inflow, tol, preconditioner=None):
    """``x`` with ``x = held`` where ``fixed_mask`` and ``(A x) = inflow`` elsewhere, by conjugate gradients
    (``A`` = ``apply_fn``, symmetric positive semi-definite; ``preconditioner(r)`` an approximate inverse, e.g.
    Jacobi's) to the relative residual ``tol``: the steady states of :mod:`sintercond.sim.steady` and the stages
    of :mod:`sintercond.sim.adaptive`."""
    def matvec(x):
        return jnp.where(fixed_mask, 0.0, apply_fn(jnp.where(fixed_mask, 0.0, x)))

    rhs = jnp.where(fixed_mask, 0.0, inflow - apply_fn(held))
    solution, _ = cg(matvec, rhs, tol=tol, maxiter=10 * fixed_mask.shape[0], M=preconditioner)
    return jnp.where(fixed_mask, held, solution)


def source_power(sources, state, params):
    """External heat powers ``[n]`` (W) of the sources ``sources`` declares, at the state's time and positions.

    ``sources``: the :class:`sintercond.simulate.Sources` sub-spec of the physics.

    Beam (nozzle Eq. 30 or laser Eq. 31 of Quintana-Ruiz & Campello 2020,
    at the beam's position along its path at time ``t``, depths from the
    current top surface), convection (Eqs. 37-39), radiation (Eq. 41), a
    prescribed pulse, and a user term. Zero (and nothing traced) when no
    source is on.
    """
    varying, pulse = source_power_parts(sources, state, params)
    terms = varying if pulse is None else varying + [pulse[1] * pulse[0]]
    temperature = state.particles.temperature
    if not terms:
        return jnp.zeros_like(temperature)
    return jnp.broadcast_to(functools.reduce(jnp.add, terms), temperature.shape).astype(
        jnp.result_type(temperature, *terms))


def source_power_parts(sources, state, params):
    """The terms of :func:`source_power`: ``(terms, pulse)``.

    ``terms``: a list of ``[n]`` (or scalar) powers (W) of the beam,
    convection, radiation and user sources; ``pulse``: None, or
    ``(field, switch)``, the prescribed pulse's loop-invariant ``[n]`` power
    (W) and its scalar on/off factor at the state's time. Kept apart for
    :func:`explicit_update`, whose reverse mode then stores one scalar per
    step for the pulse.
    """
    particles = state.particles
    positions, radii, temperature = particles.positions, particles.radii, particles.temperature
    t = state.time
    # a sum of the terms present, without a field of zeros to start from: inside a differentiated scan JAX
    # hoists such loop-invariant fields out of the loop, and the step then reads them from memory
    terms = []
    if sources.beam is not None:
        b = params.beam
        spot = heat_sources.beam_position(t, b.path, b.speed)
        surface = jnp.max(positions[:, 2] + radii)
        depth = heat_sources.beam_depth(positions, radii, spot, b.spot_radius, surface)
        law = heat_sources.laser_power if sources.beam == "laser" else heat_sources.nozzle_power
        switch = heat_sources.beam_switch(t, b.path, b.speed, b.segments_on, b.after_path)
        terms.append(switch * law(radii, depth, b.intensity, b.reach, b.absorptance))
    if sources.convection:
        c = params.convection
        terms.append(heat_sources.convection_power(radii, temperature, c.environment_temperature,
                                                   c.environment_conductivity, c.nusselt))
    if sources.radiation:
        r = params.radiation
        terms.append(heat_sources.radiation_power(radii, temperature, r.environment_temperature, r.emissivity))
    if sources.source is not None:
        terms.append(sources.source(state, t, params))
    pulse = None
    if sources.pulse:  # the pulse's switch a scalar factor (no field of zeros for where's other branch)
        pulse = (params.pulse.power, (t < params.pulse.duration).astype(temperature.dtype))
    return terms, pulse


def source_conductance(sources, radii, params, temperature_bound):
    """``G_i = -dQ_i/dT_i`` (W/K) of the temperature-dependent sources, an upper bound for ``T <= temperature_bound``.

    Convection (Quintana-Ruiz & Campello 2020, Eqs. 37-38) is linear,
    ``G = h 4 pi r^2 = 2 pi Nu k_E r``; radiation (Eq. 41) has
    ``dQ/dT = -16 pi eps sigma T^3 r^2``, largest at the highest temperature
    the run can reach. Added to the conductances in the stable step.
    """
    g = jnp.zeros_like(radii)
    if sources.convection:
        c = params.convection
        g = g + 2.0 * jnp.pi * c.nusselt * c.environment_conductivity * radii
    if sources.radiation:
        g = g + 16.0 * jnp.pi * params.radiation.emissivity * heat_sources.STEFAN_BOLTZMANN * temperature_bound**3 * radii**2
    return g


# Old names, kept for one release: functions that moved up a layer (they drive the simulator, which imports this
# module; resolved by name so that this module imports nothing above it, tests/test_layers.py) and the table's time
# step, renamed so that each time-step function has its own name (issue 24).
__getattr__ = old_names("sintercond.sim.thermal", {
    "simulate": ("sintercond.simulate", "simulate_table"),
    "steady_state": ("sintercond.sim.steady", "steady_state"),
    "steady_state_conductivity": ("sintercond.sim.steady", "steady_state_conductivity"),
    "steady_state_network_conductivity": ("sintercond.sim.steady", "steady_state_network_conductivity"),
    "stable_time_step": ("sintercond.sim.thermal", "table_time_step"),
    "check_time_step": ("sintercond.sim.thermal", "check_table_time_step"),
})
