"""Scenes of Quintana-Ruiz & Campello (2020), Sect. 5, built for :mod:`sintercond.simulate`.

:func:`example_5_1` returns ``(sim, state, params, n_steps)``: the simulator,
its initial state, the differentiable parameters and the number of steps of
the paper's run, after refusing a step above the mechanical limit
(:func:`sintercond.sim.mechanics.check_mechanical_time_step`). :func:`example_5_3` runs the
whole example (pour, settle, heat, ``k*`` with and without softening) and
returns its figures.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import simulate
from sintercond.sim import mechanics
from sintercond.state import particle_state
from sintercond.laws.walls import PlaneWall

EXAMPLE_5_1 = dict(radius=1e-3, density=3000.0, specific_heat=100.0, conductivity=60.0, E0=1e6, nu=0.3,
                   theta_star=400.0, xi_con=1.0, floor_temperature=700.0, initial_temperature=300.0)
"""The data of Example 5.1 (SI units)."""


def example_5_1(softening=True, dt=2e-5, t_end=40.0, law="conductivity", neck_model="hertz", impact_velocity=0.05,
                skin_fraction=0.1):
    """One sphere on a conducting floor under gravity (Example 5.1): ``(sim, state, params, n_steps)``.

    A sphere (r = 1 mm, rho = 3000 kg/m^3, C = 100 J/(kg K), k = 60 W/(m K),
    E0 = 1 MPa, nu = 0.3, theta* = 400 K, xi_con = 1) at 300 K placed
    touching (zero overlap, at rest) the floor ``z = 0``, a rigid conducting
    :class:`sintercond.laws.walls.PlaneWall` held at 700 K; gravity ``-9.81 e_z``;
    no friction or rolling (nothing pushes sideways), no environment.

    Conduction to the floor: with the default ``law="conductivity"`` and
    ``neck_model="hertz"`` the wall limit is ``k pi a^2 / d`` with the Hertz
    contact area ``pi a^2 = pi r delta`` and ``d = r - delta`` the current
    centre-to-floor distance (:func:`sintercond.laws.walls.wall_conductance_from_neck`).
    MECHANICS.md reads the paper with ``d = r``; the two differ by
    ``delta / r`` (1.9e-3 unsoftened, 3.2e-3 fully softened at 700 K).

    Args:
      softening: Young's modulus follows Eq. 42 (rate 1, no floor).
      dt: time step (s); refused above the mechanical limit.
      t_end: the run's duration (s); ``n_steps = round(t_end / dt)``.
      law, neck_model: the conductance law and neck model.
      impact_velocity: approach speed (m/s) the time-step check assumes
        (the sphere starts at rest; it reaches ~5 mm/s).
      skin_fraction: the neighbour list's skin over the radius.
    """
    d = EXAMPLE_5_1
    r = d["radius"]
    positions = np.array([[0.0, 0.0, r]])
    particles = particle_state(positions, r, d["initial_temperature"], d["density"])
    floor = PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), "conducting", d["floor_temperature"])
    physics = simulate.Physics.create(law=law, neck_model=neck_model, conductance="lifted", contacts="dynamic",
                                      mechanics=True, walls=(floor,), softening=softening)
    contacts, fns = simulate.dynamic_contacts(positions, particles.radii, skin_fraction * r)
    f64 = lambda x: jnp.asarray(float(x), jnp.float64)  # noqa: E731
    params = simulate.Params(
        conductivity=jnp.asarray([d["conductivity"]]), specific_heat=jnp.asarray([d["specific_heat"]]),
        mechanics=mechanics.MechanicalParams(E0=f64(d["E0"]), nu=f64(d["nu"]), xi_con=f64(d["xi_con"]),
                                             xi_fric=f64(1.0), xi_rol=f64(0.0), mu=f64(0.0), mu_r=f64(0.0),
                                             theta_star=f64(d["theta_star"]), rate=f64(1.0), E_min=f64(0.0)))
    mechanics.check_mechanical_time_step(dt, physics.mechanics, particles, contacts.neighbors, params.mechanics, impact_velocity)
    state = simulate.init_state(particles, contacts, dt,
                                mechanics=mechanics.mechanical_state(physics.mechanics, positions, contacts))
    return simulate.simulator(physics, fns), state, params, int(round(t_end / dt))


def static_overlap(load, radius, modulus, nu):
    """Hertz overlap of a sphere pressed on a rigid plane, ``(3 F / (4 E* sqrt(r)))^(2/3)``, ``E* = E/(1 - nu^2)`` (m)."""
    return (3.0 * load / (4.0 * modulus / (1.0 - nu**2) * math.sqrt(radius))) ** (2.0 / 3.0)


# --------------------------------------------------------------------------
# Example 5.3: conduction through a poured 3-D assembly

EXAMPLE_5_3 = dict(particles=10_000, radius_mean=3e-3, radius_std=0.667e-3, truncation=3.0, lateral_size=0.1,
                   conductivity=100.0, specific_heat=100.0, density=1000.0, hot=1000.0, cold=300.0,
                   initial_temperature=300.0, duration=350.0, theta_star_softened=300.0)
"""The data of Example 5.3 (SI units); the contact material is :class:`sintercond.beds.settle.DemMaterial`'s default."""


def example_5_3_radii(n, seed=0):
    """``[n]`` radii (m) from N(3 mm, 0.667 mm) truncated at 3 standard deviations (redrawn outside), Example 5.3."""
    from sintercond.beds.packing import truncated_normal_radii

    d = EXAMPLE_5_3
    return truncated_normal_radii(n, d["radius_mean"], d["radius_std"], d["truncation"], seed)


def example_5_3_bed(n=EXAMPLE_5_3["particles"], lateral_size=EXAMPLE_5_3["lateral_size"], seed=0, start="relaxed",
                    **settle):
    """The settled bed of Example 5.3: :func:`example_5_3_radii` poured by :func:`sintercond.beds.packing.pour`.

    Example 5.3's contact material (:class:`sintercond.beds.settle.DemMaterial`'s
    default) in an open box of side ``lateral_size`` (m); ``settle``: the
    keyword arguments of :func:`sintercond.beds.settle.dem_settle`. Returns a
    :class:`sintercond.beds.packing.Packing` with its ``settle`` report.
    """
    from sintercond.beds import packing, settle as settling

    return packing.pour(example_5_3_radii(n, seed), lateral_size, settling.DemMaterial(), seed=seed, start=start,
                        **settle)


@dataclasses.dataclass(frozen=True)
class ConductivityEstimate:
    """Three readings of ``k*`` along ``x`` (W/(m K)) of one packing, and the heat of the run (J), MECHANICS.md erratum 9.

    Attributes:
      k_steady: :func:`sintercond.sim.steady.steady_state_conductivity` (spheres
        touching ``x = 0`` held hot, ``x = L`` cold, no wall resistance; ``A = L H``) on the isolated network, the
        run's (its contacts move, which the coupled network does not follow yet).
      k_wall: the hot wall's power at the end of the run ``P L / (A (T_hot - T_cold))``
        (the wall contacts' resistance included; the steady flux once the run is long enough).
      k_paper: the paper's ``dQ / (grad T A dt)`` with ``dQ = sum m_i C dtheta_i`` the
        heat stored over the run ``dt`` (stored, not conducted, heat: erratum 9).
      heat_hot, heat_cold: heat into the bed through the hot and the cold wall over the run
        (``heat_hot + heat_cold = stored`` to round-off: the conduction network conserves heat).
      stored: ``sum m_i C (theta_i(end) - theta_i(0))``.
      steady_change: ``|P_hot - P_cold| / P_hot`` at the end: 0 at steady state.
      area: ``A = L H`` (m^2), ``H`` the bed's mean surface height.
    """

    k_steady: float
    k_wall: float
    k_paper: float
    heat_hot: float
    heat_cold: float
    stored: float
    steady_change: float
    area: float


@dataclasses.dataclass(frozen=True)
class Example53:
    """Example 5.3 reproduced: the poured bed, ``k*`` with and without softening, the Hashin-Shtrikman bounds.

    Attributes:
      packing: the settled bed (:class:`sintercond.beds.packing.Packing`, with its ``settle`` report).
      bounds: ``(lower, upper)`` Hashin-Shtrikman bounds (W/(m K)) at the bed's packing fraction (Eq. 48).
      unsoftened: :class:`ConductivityEstimate` of the settled bed (E = 1 MPa throughout).
      softened: the same after softening with ``theta* = 300 K`` (None if not asked).
      softened_packing: the bed re-settled under the softened moduli (None if not asked).
      softened_bounds: the bounds at the softened bed's packing fraction.
      iterations: ``k_steady`` after each softening pass (the quasi-static fixed point).
      seconds: run time of each phase (s).
    """

    packing: Any
    bounds: tuple
    unsoftened: ConductivityEstimate
    softened: ConductivityEstimate | None
    softened_packing: Any
    softened_bounds: tuple | None
    iterations: tuple
    seconds: dict


def heat_run(centres, radii, lateral_size, height, duration=EXAMPLE_5_3["duration"]):
    """Heat a frozen packing from the ``x`` walls for ``duration`` s; returns ``(ConductivityEstimate, final temperatures)``.

    Example 5.3's thermal data (k = 100 W/(m K), C = 100 J/(kg K), rho = 1000
    kg/m^3, particles at 300 K, walls ``x = 0`` at 1000 K and ``x = L`` at
    300 K). The paper holds the walls' temperatures; here the walls are
    conducting plane walls (:mod:`sintercond.laws.walls`): heat crosses each wall
    contact through ``k pi a^2 / d`` with the Hertz contact radius, the law
    (Eqs. 32-35) used between particles. The packing does not move (the
    static path, explicit Euler at 0.9 of the stable step, equal steps that
    end at ``duration``): exact for a settled bed whose modulus does not
    change with the temperature.
    """
    from sintercond.sim import steady
    from sintercond.laws.walls import PlaneWall

    d = EXAMPLE_5_3
    centres, radii = np.asarray(centres, np.float64), np.asarray(radii, np.float64)
    L, dT = float(lateral_size), d["hot"] - d["cold"]
    area = L * float(height)
    physics = simulate.Physics(conduction=simulate.Conduction(law="conductivity", neck_model="hertz", conductance="lifted",
                                                          conducting_walls=2))
    planes = [PlaneWall((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)), PlaneWall((L, 0.0, 0.0), (-1.0, 0.0, 0.0))]
    contacts = simulate.lifted_contacts(physics, centres, radii, [(np.asarray(w.penetration(centres, radii)), t)
                                                                  for w, t in zip(planes, (d["hot"], d["cold"]))])
    particles = particle_state(centres, radii, d["initial_temperature"], d["density"])
    params = simulate.Params(conductivity=jnp.asarray([d["conductivity"]]), specific_heat=jnp.asarray([d["specific_heat"]]))
    sim = simulate.simulator(physics)
    limit = float(simulate.thermal_time_step(sim, simulate.init_state(particles, contacts, 1.0), params))
    n_steps = max(1, int(math.ceil(duration / (0.9 * limit))))
    state = simulate.init_state(particles, contacts, duration / n_steps)
    wall_k = sim.prepare_fn(state, params).wall_conductance  # [2, n] (W/K)
    wall_t = jnp.asarray([d["hot"], d["cold"]])[:, None]
    powers = simulate.Observable(lambda s, k: jnp.sum(k * (wall_t - s.particles.temperature), axis=1), wall_k)
    final, saved = jax.jit(lambda s, p: simulate.rollout(sim, s, p, n_steps, simulate.SaveAt(1, powers),
                                                         checkpoint=False))(state, params)
    saved = np.asarray(saved)
    # explicit Euler: step k adds dt P(state_k); saved[k] is P after step k+1
    heat = float(state.dt) * (np.asarray(powers(state)) + saved[:-1].sum(axis=0))
    capacity = np.asarray(particles.mass) * d["specific_heat"]
    temperature = np.asarray(final.particles.temperature)
    stored = float(np.sum(capacity * (temperature - d["initial_temperature"])))
    k_steady = steady.steady_state_conductivity(centres, radii, d["conductivity"], axis=0, law="conductivity",
                                                 neck_model="hertz", box=(np.zeros(3), np.array([L, L, height])),
                                                 coupling="none")  # the run's network: its moving contacts step
    # on the isolated one, so the three readings compare one network
    p_hot, p_cold = saved[-1]
    estimate = ConductivityEstimate(
        k_steady=float(k_steady), k_wall=float(p_hot * L / (area * dT)),
        k_paper=stored / (dT / L * area * duration), heat_hot=float(heat[0]), heat_cold=float(heat[1]), stored=stored,
        steady_change=float(abs(p_hot + p_cold) / p_hot), area=area)
    return estimate, temperature


def example_5_3(n=EXAMPLE_5_3["particles"], lateral_size=EXAMPLE_5_3["lateral_size"], seed=0, softening=True,
                iterations=2, start="relaxed", duration=EXAMPLE_5_3["duration"], **settle) -> Example53:
    """Example 5.3: pour ``n`` spheres into an open box, settle them, heat from the ``x`` walls, read ``k*``.

    The data (:data:`EXAMPLE_5_3`, :class:`sintercond.beds.settle.DemMaterial`):
    radii N(3 mm, 0.667 mm) truncated at 3 sigma, k = 100 W/(m K),
    C = 100 J/(kg K), rho = 1000 kg/m^3, E = 1 MPa, nu = 0.3, mu = 0.05 and
    mu_r = 0.2 between particles, 0 at the walls, xi_con = xi_fric = 1,
    xi_rol = 0.2; walls ``x = 0`` at 1000 K and ``x = L`` at 300 K, particles
    at 300 K, 350 s.

    Readings (MECHANICS.md erratum 9):

    1. Pour and settle (:func:`sintercond.beds.packing.pour`, ``start``; the
       settle thresholds go in ``settle``).
    2. Heat the settled bed (:func:`heat_run`, the static path: the
       unsoftened bed does not move when heated) and read ``k*`` three ways.
    3. Softened (``theta* = 300 K``, Eq. 42 with rate 1): quasi-static
       fixed point. The bed is re-settled with the DEM under the moduli
       ``E(theta)`` of the last run's final temperatures (held while it
       settles), then heated again on its new contacts, ``iterations``
       times. The heat's time scale (~1e2 s) is far above the bed's
       mechanical relaxation (~1e-2 s), so the steady state is this fixed
       point; ``k_paper`` of the softened bed is read on the frozen softened
       geometry (an approximation of the coupled transient, which would cost
       ~1e7 DEM steps).

    The paper's numbers do not fit together: 10 000 spheres of mean radius
    3 mm at a solid fraction 0.54 fill 0.24 m of a 0.1 m x 0.1 m box, not a
    0.1 m cube. Here ``n`` spheres go into an open box of side
    ``lateral_size`` and fill what they fill; ``A = L H`` with ``H`` the
    bed's mean surface height.

    Returns:
      :class:`Example53`.
    """
    from sintercond.beds import packing, settle as settling
    from sintercond.laws import effective

    d = EXAMPLE_5_3
    seconds = {}
    t0 = time.perf_counter()
    bed = example_5_3_bed(n, lateral_size, seed, start, **settle)
    radii = bed.radii
    seconds["pour"] = time.perf_counter() - t0
    bounds = tuple(float(b) for b in effective.hashin_shtrikman_bounds(0.0, d["conductivity"], bed.packing_fraction))
    t0 = time.perf_counter()
    plain, temperature = heat_run(bed.centres, radii, lateral_size, bed.height, duration)
    seconds["heat"] = time.perf_counter() - t0
    softened = soft_bed = soft_bounds = None
    history = []
    if softening:
        t0 = time.perf_counter()
        material = settling.DemMaterial(theta_star=d["theta_star_softened"])
        centres = bed.centres
        settle = {"v_rel": math.sqrt(2.0 * settling.GRAVITY * 2.0 * float(np.mean(radii))), **settle}
        for _ in range(iterations):
            result = settling.dem_settle(centres, radii, settling.box_walls(lateral_size), material, temperature,
                                         softening=True, **settle)
            centres = result.centres
            soft_bed = dataclasses.replace(packing._bed(centres, radii, lateral_size), settle=result.report,
                                           residual_force=result.report.force_ratio)
            softened, temperature = heat_run(centres, radii, lateral_size, soft_bed.height, duration)
            history.append(softened.k_steady)
        soft_bounds = tuple(float(b) for b in effective.hashin_shtrikman_bounds(0.0, d["conductivity"],
                                                                                soft_bed.packing_fraction))
        seconds["softened"] = time.perf_counter() - t0
    return Example53(bed, bounds, plain, softened, soft_bed, soft_bounds, tuple(history), seconds)
