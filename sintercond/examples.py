"""Scenes of Quintana-Ruiz & Campello (2020), Sect. 5, built for :mod:`sintercond.simulate`.

Each builder returns ``(sim, state, params, n_steps)``: the simulator, its
initial state, the differentiable parameters and the number of steps of the
paper's run, after refusing a step above the mechanical limit
(:func:`sintercond.mechanics.check_time_step`).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from sintercond import mechanics, simulate
from sintercond.state import particle_state
from sintercond.walls import PlaneWall

EXAMPLE_5_1 = dict(radius=1e-3, density=3000.0, specific_heat=100.0, conductivity=60.0, E0=1e6, nu=0.3,
                   theta_star=400.0, xi_con=1.0, floor_temperature=700.0, initial_temperature=300.0)
"""The data of Example 5.1 (SI units)."""


def example_5_1(softening=True, dt=2e-5, t_end=40.0, law="conductivity", neck_model="hertz", impact_velocity=0.05,
                skin_fraction=0.1):
    """One sphere on a conducting floor under gravity (Example 5.1): ``(sim, state, params, n_steps)``.

    A sphere (r = 1 mm, rho = 3000 kg/m^3, C = 100 J/(kg K), k = 60 W/(m K),
    E0 = 1 MPa, nu = 0.3, theta* = 400 K, xi_con = 1) at 300 K placed
    touching (zero overlap, at rest) the floor ``z = 0``, a rigid conducting
    :class:`sintercond.walls.PlaneWall` held at 700 K; gravity ``-9.81 e_z``;
    no friction or rolling (nothing pushes sideways), no environment.

    Conduction to the floor: with the default ``law="conductivity"`` and
    ``neck_model="hertz"`` the wall limit is ``k pi a^2 / d`` with the Hertz
    contact area ``pi a^2 = pi r delta`` and ``d = r - delta`` the current
    centre-to-floor distance (:func:`sintercond.walls.wall_conductance_from_neck`).
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
    physics = simulate.Physics(law=law, neck_model=neck_model, conductance="lifted", contacts="dynamic",
                               mechanics=True, walls=(floor,), softening=softening)
    contacts, fns = simulate.dynamic_contacts(positions, particles.radii, skin_fraction * r)
    f64 = lambda x: jnp.asarray(float(x), jnp.float64)  # noqa: E731
    params = simulate.Params(
        conductivity=jnp.asarray([d["conductivity"]]), specific_heat=jnp.asarray([d["specific_heat"]]),
        mechanics=mechanics.MechanicalParams(E0=f64(d["E0"]), nu=f64(d["nu"]), xi_con=f64(d["xi_con"]),
                                             xi_fric=f64(1.0), xi_rol=f64(0.0), mu=f64(0.0), mu_r=f64(0.0),
                                             theta_star=f64(d["theta_star"]), rate=f64(1.0), E_min=f64(0.0)))
    mechanics.check_time_step(dt, physics, particles, contacts.neighbors, params.mechanics, impact_velocity)
    state = simulate.init_state(particles, contacts, dt,
                                mechanics=mechanics.mechanical_state(physics, positions, contacts))
    return simulate.simulator(physics, fns), state, params, int(round(t_end / dt))


def static_overlap(load, radius, modulus, nu):
    """Hertz overlap of a sphere pressed on a rigid plane, ``(3 F / (4 E* sqrt(r)))^(2/3)``, ``E* = E/(1 - nu^2)`` (m)."""
    return (3.0 * load / (4.0 * modulus / (1.0 - nu**2) * math.sqrt(radius))) ** (2.0 / 3.0)
