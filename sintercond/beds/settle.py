"""Settle a packing under gravity: the harmonic relaxation and the thermo-mechanical DEM.

Two ways to let a pile of spheres (e.g. the deposit of
:func:`sintercond.beds.packing.deposit_spheres`) come to rest under gravity, each
checked: a pile that has not settled within its budget raises
:class:`PackingError`; it is never returned half-fallen.

:func:`relax_under_gravity` (the default of :func:`sintercond.beds.packing.powder_bed` and scenes): damped dynamics of
gravity plus stiff harmonic repulsion between overlapping spheres and with
the floor and side walls (frictionless, so the pile collapses to a dense
random packing), on a pair list rebuilt on the host whenever a sphere
has moved half the skin, until the net force on every sphere is below
``force_tol`` of its weight. Contacts end up as small overlaps (the weight
of the pile over the stiffness, ~1e-3 of a radius), which
:func:`sintercond.laws.geometry.contacts` counts as contacts.

:func:`dem_settle` (``method="dem"``, :func:`sintercond.beds.packing.pour`): the real
thermo-mechanical DEM of :mod:`sintercond.sim.mechanics` instead: Hertz contacts
with damping, Mindlin friction with history, rolling resistance, gravity and
the plane walls of the box (:func:`box_walls`), stepped by
:mod:`sintercond.simulate` on the host loop :func:`sintercond.rollout.advance` at the automatic time step of
:func:`sintercond.sim.mechanics.mechanical_time_step`, until the kinetic energy and
the largest net force over a sphere's weight are below stated thresholds
(:data:`KINETIC_TOL`, :data:`FORCE_TOL`), reported in a :class:`SettleReport`
(``packing.settle``). The contact material is a :class:`DemMaterial`
(default: Quintana-Ruiz & Campello 2020, Example 5.3, E = 1 MPa: soft
contacts keep the step large and the pour cheap; nothing is stiffened or
softened behind the user's back). It costs ~1e3-1e4 DEM steps from a
relaxed pile, ~1e5 from the loose deposit, so ``"relax"`` stays the default
of :func:`sintercond.beds.packing.powder_bed` and scenes.

Everything here runs in float64 (NumPy, and JAX inside ``jax.enable_x64``)
whatever precision the thermal model uses: the packing of a scene does not
depend on ``SINTERCOND_ENABLE_X64``.

The geometry (sampled sizes, the deposit, the bed's figures, representative
volumes) and the beds built from it are :mod:`sintercond.beds.packing`'s; it
imports this module, never the other way.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import time
import typing

import jax
import jax.numpy as jnp
import numpy as np

from sintercond._validation import shown


class PackingError(ValueError):
    """A bed that cannot be built or did not settle; the message says which quantity and its range.

    Raised here and by :mod:`sintercond.beds.packing` (the same class: ``sintercond.beds.packing.PackingError``).
    """


def _pair_list(x, r, skin, capacity=0):
    """Pairs ``i < j`` closer than ``r_i + r_j + skin``, sorted by ``(i, j)``, padded to a power of two.

    From the host cell list (:func:`sintercond.contacts.neighbors.cell_list_pairs`, O(n)) with a relative reach
    covering the skin for the smallest pair, then the exact test: the pairs (and their order) the O(n^2) search
    found, which took most of a 3,290-sphere bed's build.
    """
    from sintercond.contacts.neighbors import cell_list_pairs

    i, j = cell_list_pairs(x, r, tolerance=skin / (2.0 * float(np.min(r))))
    near = np.sum((x[i] - x[j]) ** 2, axis=-1) < (r[i] + r[j] + skin) ** 2
    i, j = i[near], j[near]
    size = max(capacity, 1 << max(int(len(i)) - 1, 1).bit_length())
    pad = size - len(i)
    mask = np.concatenate([np.ones(len(i), bool), np.zeros(pad, bool)])
    return np.concatenate([i, np.zeros(pad, int)]), np.concatenate([j, np.zeros(pad, int)]), mask


class _Pile(typing.NamedTuple):
    """A pile the harmonic relaxation settles (g = 1, lengths in the caller's unit): radii, masses (here the
    inertias ``max(r^3, 1)``) and weights ``r^3`` ``[n]``, the candidate pairs ``i``, ``j`` ``[c]`` with ``mask``
    (real pairs), and the container's side ``size`` (the walls x, y in [0, size], the floor z = 0, no lid)."""

    radii: jax.Array
    mass: jax.Array
    weight: jax.Array
    i: jax.Array
    j: jax.Array
    mask: jax.Array
    size: jax.Array


def _net_force(x, v, pile: _Pile, stiffness, contact_damping):
    """Gravity (g = 1) plus damped harmonic repulsion of overlapping pairs, floor and side walls, ``[n, 3]``.

    Each contact is a spring ``stiffness * overlap`` and a normal dashpot
    ``2 zeta sqrt(stiffness m*)`` (``zeta = contact_damping``, ``m*`` the reduced
    mass; the walls take the sphere's mass): impacts lose energy, as they must
    for a pile to come to rest with a finite time step.
    """
    r, mass, weight, i, j, mask, size = pile
    d = x[i] - x[j]
    dist2 = jnp.sum(d**2, axis=1)
    safe = jnp.where(dist2 > 0, dist2, 1.0)
    n_ij = d / jnp.sqrt(safe)[:, None]
    in_contact = mask & (dist2 > 0) & (r[i] + r[j] > jnp.sqrt(safe))
    overlap = jnp.where(in_contact, r[i] + r[j] - jnp.sqrt(safe), 0.0)
    m_star = mass[i] * mass[j] / (mass[i] + mass[j])
    closing = jnp.sum((v[i] - v[j]) * n_ij, axis=1)
    dashpot = jnp.where(in_contact, 2.0 * contact_damping * jnp.sqrt(stiffness * m_star) * closing, 0.0)
    f = (stiffness * overlap - dashpot)[:, None] * n_ij
    force = jnp.zeros_like(x).at[i].add(f).at[j].add(-f)
    gamma = (2.0 * contact_damping * jnp.sqrt(stiffness * mass))[:, None]
    lo = r[:, None] - x  # > 0: overlaps the floor (z) or the x = 0, y = 0 walls, pushed +
    hi = (x + r[:, None] - size).at[:, 2].set(-1.0)  # > 0: overlaps a far wall, pushed -; no lid
    force = force + jnp.where(lo > 0, stiffness * lo - gamma * v, 0.0) - jnp.where(hi > 0, stiffness * hi + gamma * v, 0.0)
    return force.at[:, 2].add(-weight)


@jax.jit
def _damped_chunk(x, v, pile: _Pile, stiffness, damping, contact_damping, dt, steps):
    def step(_, carry):
        x, v = carry
        force = _net_force(x, v, pile, stiffness, contact_damping)
        v = v + dt * (force / pile.mass[:, None] - damping * v)
        return x + dt * v, v

    x_new, v_new = jax.lax.fori_loop(0, steps, step, (x, v))  # steps traced: one compilation per capacity
    static = _net_force(x_new, jnp.zeros_like(v_new), pile, stiffness, contact_damping)
    ratio = jnp.linalg.norm(static, axis=1) / pile.weight
    moved = jnp.max(jnp.linalg.norm(x_new - x, axis=1))
    return x_new, v_new, jnp.max(ratio), moved, jnp.argmax(ratio)


def sphere_text(index, centre, radius) -> str:
    """``sphere k at [x, y, z] m (radius r m)``: the sphere a settling figure is worst on, for its progress and
    its error (a net force of 1 weight is a sphere that touches nothing: falling, or bouncing)."""
    return f"sphere {int(index)} at {[float(f'{c:.4g}') for c in centre]} m (radius {float(radius):.3g} m)"


def _report(progress, *figures, worst):
    """``progress(*figures)``, with ``worst=`` where the callback takes it (a callback of the five figures alone, as
    documented before it was added, still works)."""
    parameters = inspect.signature(progress).parameters.values()
    if any(p.name == "worst" or p.kind is p.VAR_KEYWORD for p in parameters):
        progress(*figures, worst=worst)
    else:
        progress(*figures)


def relax_under_gravity(centres, radii, lateral_size, *, max_steps=None, stiffness=None, damping=0.3, contact_damping=0.3,
                        force_tol=2e-3, skin=1.0, progress=None):
    """Let spheres settle under gravity; returns ``(settled centres, residual force over weight)``.

    Damped dynamics (semi-implicit Euler, viscous damping ``damping`` per unit
    time) of gravity plus damped harmonic contacts (:func:`_net_force`) with
    the other spheres, the floor and the side walls, in float64 whatever the JAX default. Lengths are scaled by
    the mean radius inside, weights by the cube of the radius, gravity is 1; the inertia of a sphere is its
    weight, or a mean sphere's if larger (the settled packing does not depend on it; the step does);
    ``stiffness`` is the contact stiffness over the weight of a mean sphere per
    radius (default ``1e4`` per ten layers of the pile), so overlaps are about
    (layers above) / stiffness radii. The pair list holds pairs within
    ``skin`` mean radii of contact and is rebuilt whenever a sphere may have
    moved half of it. Stops when the net force on every sphere is below
    ``force_tol`` of its weight. ``progress(phase, steps, max_steps, figure, target)`` is called after every
    chunk with the largest net force over a weight (``figure``) and ``force_tol`` (``target``), and ``worst``,
    the sphere it is on (:func:`sphere_text`).

    Raises:
      PackingError: the pile did not settle within ``max_steps`` (default:
        enough for the pile to fall its own height three times and settle).
    """
    radii = np.asarray(radii, dtype=np.float64)
    scale = float(np.mean(radii))
    r_np = radii / scale
    x_np = np.asarray(centres, dtype=np.float64) / scale
    size = float(lateral_size) / scale
    top = float(np.max(x_np[:, 2] + r_np))
    if stiffness is None:
        stiffness = 1e4 * max(1.0, top / 20.0)
    # the static packing does not depend on the inertia: spheres lighter than a mean one move as a mean one,
    # so the smallest spheres no longer set the step (20-60 um: 1.8 times larger)
    inertia = np.maximum(r_np**3, 1.0)
    # stable for the lightest inertia with 12 contacts: springs need dt sqrt(12 k / m) < 2, dashpots
    # dt 12 (2 zeta sqrt(k m / 2)) / m < 2; dt = sqrt(m_min / k) / 4 keeps both below 1.3
    dt = 0.25 * float(np.sqrt(np.min(inertia) / stiffness))
    if max_steps is None:  # terminal speed g / damping: fall the pile's height three times, then 200 damping times
        max_steps = int((3 * top / (1.0 / damping) + 200.0 / damping) / dt)
    with jax.enable_x64(True):
        r, mass, weight = jnp.asarray(r_np), jnp.asarray(inertia), jnp.asarray(r_np**3)
        x, v = jnp.asarray(x_np), jnp.zeros((len(r_np), 3), jnp.float64)
        size = jnp.float64(size)
        args = tuple(jnp.float64(a) for a in (stiffness, damping, contact_damping, dt))
        done, capacity, residual, worst = 0, 0, math.inf, 0
        chunk = 64
        while done < max_steps:
            i, j, mask = _pair_list(np.asarray(x), r_np, skin, capacity)
            capacity = len(i)
            pile = _Pile(r, mass, weight, jnp.asarray(i), jnp.asarray(j), jnp.asarray(mask), size)
            x_new, v_new, residual, moved, worst = _damped_chunk(x, v, pile, *args, jnp.int32(chunk))
            if float(moved) > 0.5 * skin and chunk > 1:  # a pair may have been missed: redo it shorter
                chunk //= 2
                continue
            x, v, done = x_new, v_new, done + chunk
            residual, worst = float(residual), int(worst)
            if progress is not None:
                _report(progress, "relaxing", done, max_steps, residual, force_tol,
                        worst=sphere_text(worst, np.asarray(x)[worst] * scale, radii[worst]))
            if residual < force_tol:
                break
            chunk = min(2 * chunk, 4096) if float(moved) < 0.2 * skin else chunk
        settled = np.asarray(x) * scale
    if not residual < force_tol:
        raise PackingError(f"the bed did not settle within {max_steps} steps: the largest net force is "
                           f"{residual:.3g} of a sphere's weight (allowed < {force_tol:g}), on "
                           f"{sphere_text(worst, settled[worst], radii[worst])}")
    return settled, residual


# --------------------------------------------------------------------------
# settling with the thermo-mechanical DEM (Quintana-Ruiz & Campello 2020)


@dataclasses.dataclass(frozen=True)
class DemMaterial:
    """Contact material of a DEM pour (SI units); the defaults are Example 5.3's.

    Quintana-Ruiz & Campello (2020), Sect. 5.3: rho = 1000 kg/m^3, E = 1 MPa,
    nu = 0.3, mu = 0.05 and mu_r = 0.2 between particles, 0 against the walls,
    xi_con = xi_fric = 1, xi_rol = 0.2. The laws are those of
    :mod:`sintercond.sim.mechanics` (Hertz with damping, Eqs. 2-6; Mindlin
    stick-slip with its spring, Eqs. 7-13; rolling resistance, Eqs. 15-20;
    rigid walls of Remark 1).

    Attributes:
      density: kg/m^3, > 0.
      E: Young's modulus (Pa), > 0; with ``theta_star`` the modulus below the
        softening onset (Eq. 42, erratum 6 of MECHANICS.md: rate 1, no floor).
      nu: Poisson ratio, in [0, 0.5).
      mu, mu_r: friction and rolling-resistance coefficients between particles, >= 0.
      mu_wall, mu_r_wall: the same against the walls, >= 0.
      xi_con, xi_fric, xi_rol: damping ratios of Eqs. 6, 11, 18, >= 0.
      theta_star: softening onset (K), > 0; used only when settling with ``softening=True``.
    """

    density: float = 1000.0
    E: float = 1e6
    nu: float = 0.3
    mu: float = 0.05
    mu_r: float = 0.2
    mu_wall: float = 0.0
    mu_r_wall: float = 0.0
    xi_con: float = 1.0
    xi_fric: float = 1.0
    xi_rol: float = 0.2
    theta_star: float = 400.0

    def __post_init__(self):
        ranges = {"density": (0.0, False), "E": (0.0, False), "theta_star": (0.0, False)}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if (isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer))
                    or not math.isfinite(value)):
                raise PackingError(f"DemMaterial.{field.name} must be a finite number; got {shown(value)}")
            low, closed = ranges.get(field.name, (0.0, True))
            if value < low or (value == low and not closed):
                raise PackingError(f"DemMaterial.{field.name} must be {'>=' if closed else '>'} {low:g}; got {shown(value)}")
        if not self.nu < 0.5:
            raise PackingError(f"DemMaterial.nu must be in [0, 0.5); got {shown(self.nu)}")

    def mechanical_params(self):
        """The :class:`sintercond.sim.mechanics.MechanicalParams` of this material (float64 scalars)."""
        from sintercond.sim.mechanics import MechanicalParams

        f = lambda x: jnp.asarray(float(x), jnp.float64)  # noqa: E731
        return MechanicalParams(E0=f(self.E), nu=f(self.nu), xi_con=f(self.xi_con), xi_fric=f(self.xi_fric),
                                xi_rol=f(self.xi_rol), mu=f(self.mu), mu_r=f(self.mu_r), mu_wall=f(self.mu_wall),
                                mu_r_wall=f(self.mu_r_wall), theta_star=f(self.theta_star), rate=f(1.0), E_min=f(0.0))


KINETIC_TOL = 1e-5
"""Default settled threshold on kinetic energy (translation + rotation) over ``sum_i m_i g r_i``."""

FORCE_TOL = 0.05
"""Default settled threshold on ``max_i |F_i| / (m_i g)``, the net force on a sphere over its weight."""


@dataclasses.dataclass(frozen=True)
class SettleReport:
    """How a DEM settle ended; returned with every packing it builds (all SI).

    Attributes:
      steps: DEM steps taken; time: simulated time (s); dt: the step (s) (a stiffened bed's: its stiff stage's).
      kinetic_ratio: kinetic energy (translation + rotation) over ``sum_i m_i g r_i``
        at the end; ``kinetic_tol`` the threshold it met.
      force_ratio: ``max_i |F_i| / (m_i g)`` at the end, ``F_i`` the net force
        (contacts, walls, gravity) taken from one probe step as ``m_i dv_i / dt``
        (exact for symplectic Euler); ``force_tol`` the threshold it met.
      max_overlap: largest sphere-sphere or sphere-wall overlap over the radius.
      step_overlap: overlap (m) the time step was sized for (:func:`sintercond.sim.mechanics.mechanical_time_step`).
      v_rel: approach speed (m/s) the time step was sized for.
      reallocations: neighbour-list reallocations; wall_seconds: run time (s).
      soft_modulus: the Young's modulus (Pa) of the soft stage a stiffened bed settled at first
        (:func:`stiffen`), or None; soft_steps: that stage's steps; stiffen_residual: the relative residual of
        the stiffened overlaps (:func:`stiffened_positions`).
    """

    steps: int
    time: float
    dt: float
    kinetic_ratio: float
    kinetic_tol: float
    force_ratio: float
    force_tol: float
    max_overlap: float
    step_overlap: float
    v_rel: float
    reallocations: int
    wall_seconds: float
    soft_modulus: float | None = None
    soft_steps: int = 0
    stiffen_residual: float = 0.0

    def summary(self) -> dict:
        """The figures as a flat dict with units in the keys."""
        soft = {} if self.soft_modulus is None else {"settle_soft_modulus_Pa": self.soft_modulus,
                                                     "settle_soft_steps": self.soft_steps,
                                                     "settle_stiffen_residual": self.stiffen_residual}
        return {"settle_steps": self.steps, "settle_time_s": self.time, "settle_dt_s": self.dt,
                "settle_kinetic_ratio": self.kinetic_ratio, "settle_kinetic_tol": self.kinetic_tol,
                "settle_force_ratio": self.force_ratio, "settle_force_tol": self.force_tol,
                "settle_max_overlap": self.max_overlap, "settle_wall_s": self.wall_seconds} | soft


class DemSettled(typing.NamedTuple):
    """A settled DEM state and what continues it (``sim``, ``params``, ``neighbor_fns`` for :func:`sintercond.rollout.advance`).

    The state is float64 (the settle runs under ``jax.enable_x64`` whatever
    the default); continue it with 64-bit floats on.
    """

    centres: np.ndarray
    state: typing.Any
    sim: typing.Any
    params: typing.Any
    neighbor_fns: typing.Any
    report: SettleReport
    material: DemMaterial | None = None


def box_walls(lateral_size):
    """The five insulated walls of an open square box ``[0, L]^2`` with its floor at ``z = 0``.

    Order: floor, ``x = 0``, ``x = L``, ``y = 0``, ``y = L``
    (:class:`sintercond.laws.walls.PlaneWall`, normals into the box).
    """
    from sintercond.laws.walls import PlaneWall

    L = float(lateral_size)
    return (PlaneWall((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), PlaneWall((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
            PlaneWall((L, 0.0, 0.0), (-1.0, 0.0, 0.0)), PlaneWall((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
            PlaneWall((0.0, L, 0.0), (0.0, -1.0, 0.0)))


def dem_physics(walls, softening=False, wall_friction=True, wall_rolling=True):
    """The :class:`sintercond.simulate.Physics` of a DEM settle: Hertz, Mindlin, rolling, gravity ``-9.81 e_z``, ``walls``.

    Conduction is the paper's (``law="conductivity"``, Hertz contact radius,
    Eqs. 32-35); while settling every particle is held at its temperature, so
    no heat moves. ``wall_friction``/``wall_rolling`` False: frictionless
    walls (``Mechanics.wall_friction``; :func:`dem_settle` sets them from
    ``DemMaterial.mu_wall``/``mu_r_wall``).
    """
    from sintercond import simulate

    return simulate.Physics.create(law="conductivity", neck_model="hertz", conductance="lifted", contacts="dynamic",
                                   mechanics=True, walls=tuple(walls), gravity=(0.0, 0.0, -GRAVITY), friction=True,
                                   rolling=True, wall_friction=wall_friction, wall_rolling=wall_rolling,
                                   softening=softening, held=True)


GRAVITY = 9.81
"""m/s^2."""


def _hertz_plane_overlap(load, radius, modulus, nu):
    """Overlap (m) of a sphere pressed on a rigid plane by ``load`` (N), ``(3 F / (4 E* sqrt(r)))^(2/3)``, E* = E/(1-nu^2)."""
    return (3.0 * load / (4.0 * modulus / (1.0 - nu**2) * math.sqrt(radius))) ** (2.0 / 3.0)


def _overlaps(centres, radii, walls):
    """Largest sphere-sphere and sphere-wall overlap over the (smaller) radius."""
    i, j, real = _pair_list(centres, radii, 0.0)
    i, j = i[real], j[real]
    pair = (radii[i] + radii[j] - np.linalg.norm(centres[i] - centres[j], axis=1)) / np.minimum(radii[i], radii[j])
    wall = [np.asarray(w.penetration(centres, radii)) / radii for w in walls]
    return float(max(np.max(pair, initial=0.0), *(np.max(w, initial=0.0) for w in wall)))


def dem_settle(centres, radii, walls, material=DemMaterial(), temperature=300.0, softening=False, *,
               kinetic_tol=KINETIC_TOL, force_tol=FORCE_TOL, max_time=2.0, check_every=1000, skin_fraction=0.1,
               v_rel=None, progress=None, soft_modulus=None) -> DemSettled:
    """Let spheres fall and settle under gravity with the real contact laws; returns a :class:`DemSettled`.

    The coupled step of :mod:`sintercond.simulate` (``Physics(mechanics=Mechanics(...))``,
    :func:`dem_physics`): Hertz normal force with damping, Mindlin friction
    with history, rolling resistance, gravity ``g = 9.81 m/s^2 (-z)`` and the
    plane ``walls``, symplectic Euler, in compiled chunks of ``check_every``
    steps (the loop of :func:`sintercond.rollout.advance`, with the settled
    figures computed in the same compiled chunk;
    a neighbour list that overflowed is reallocated with
    :func:`sintercond.simulate.reallocate_neighbors` and the chunk redone).
    Every particle is held at
    ``temperature`` (K, scalar or ``[n]``): no heat moves; with
    ``softening`` the moduli follow Eq. 42 at those temperatures.

    The time step is automatic: :func:`sintercond.sim.mechanics.mechanical_time_step`
    (Eq. 47 and the tangential and rolling bounds, erratum 8) at the approach
    speed ``v_rel`` (default: free fall from the highest sphere to the floor,
    at least over one mean diameter) and at the larger of that collision's
    overlap and the Hertz overlap of the largest sphere on a plane under the
    weight of a solid column of the pile's height on its cross-section
    ``(2 r_max)^2`` (the static load at the bottom).

    Settled means, checked every ``check_every`` steps: kinetic energy
    (translation and rotation) below ``kinetic_tol * sum_i m_i g r_i`` and
    every net force below ``force_tol`` of that sphere's weight (the net
    force is read off one probe step, ``m dv/dt``). ``progress(phase, steps, max_steps, figure, 1.0)``, if
    given, is called at every check with the larger of the two figures over its threshold.

    Soft pour, then stiffen (``soft_modulus``): a pile comes to rest in some tens of milliseconds of physical time,
    whatever its stiffness, while the step shrinks as the stiffness grows (a 45-105 um Ti6Al4V bed at 110 GPa
    takes some 5e-9 s steps: millions of steps). With ``soft_modulus`` (Pa, below ``material.E``) the pile settles
    at that modulus first, and :func:`stiffen` then carries it to ``material``: Hertz-Mindlin contacts are
    homogeneous, so the same forces and torques hold at the stiff modulus with every deformation (normal overlap,
    tangential and rolling spring) scaled by ``(soft_modulus / E)^(2/3)``; the stiff DEM then only damps what the
    geometric change leaves (``max_time`` is the budget of each stage).

    Args:
      centres: ``[n, 3]`` start positions (m), at rest, no sphere below the floor.
      radii: ``[n]`` (m).
      walls: :class:`sintercond.laws.walls.PlaneWall` s (e.g. :func:`box_walls`).
      material: :class:`DemMaterial`.
      max_time: simulated time (s) allowed to settle.
      soft_modulus: Young's modulus (Pa) of a soft pour first, ``0 < soft_modulus < material.E``, or None.

    Raises:
      PackingError: bad input (naming it), or not settled within ``max_time``
        (naming the quantity that missed its threshold and its value).
    """
    if not isinstance(material, DemMaterial):
        raise PackingError(f"material must be a DemMaterial; got {type(material).__name__}")
    options = dict(kinetic_tol=kinetic_tol, force_tol=force_tol, max_time=max_time, check_every=check_every,
                   progress=progress)
    if soft_modulus is not None:
        if (isinstance(soft_modulus, bool) or not isinstance(soft_modulus, (int, float))
                or not 0.0 < soft_modulus < material.E):
            raise PackingError(f"soft_modulus must be a number in (0, E = {material.E:g}) Pa; got {shown(soft_modulus)}")
        if softening:
            raise PackingError("soft_modulus needs softening=False: the stiffening scales every contact by one "
                               "modulus ratio, which softening would make differ from particle to particle")
        soft = dem_settle(centres, radii, walls, dataclasses.replace(material, E=float(soft_modulus)), temperature,
                          skin_fraction=skin_fraction, v_rel=v_rel, **options)
        return stiffen(soft, material, **options)
    _check_settle_options(kinetic_tol, force_tol, max_time, check_every, skin_fraction)
    start = time.perf_counter()
    centres = np.asarray(centres, np.float64)
    radii = np.broadcast_to(np.asarray(radii, np.float64), (len(centres),))
    from sintercond import simulate
    from sintercond.sim import mechanics
    from sintercond.state import particle_state

    with jax.enable_x64(True):
        temperature = np.broadcast_to(np.asarray(temperature, np.float64), radii.shape)
        try:
            particles = particle_state(centres, radii, temperature, material.density, fixed=True)
        except ValueError as err:
            raise PackingError(str(err)) from None
        physics = dem_physics(walls, softening, material.mu_wall > 0, material.mu_r_wall > 0)
        r_max = float(radii.max())
        contacts, fns = simulate.dynamic_contacts(centres, radii, skin_fraction * float(radii.mean()),
                                                  capacity_multiplier=1.5, margin=np.full(3, 2.0 * r_max))
        if v_rel is None:
            top = float(np.max(centres[:, 2] + radii))
            v_rel = math.sqrt(2.0 * GRAVITY * max(top - float(np.min(centres[:, 2] - radii)), 4.0 * float(radii.mean())))
        state = simulate.init_state(particles, contacts, 1.0,
                                    mechanics=mechanics.mechanical_state(physics.mechanics, centres, contacts))
        return _settle(simulate.simulator(physics, fns), physics, state, fns, material, float(v_rel), start,
                       "settling (DEM)", **options)


def _check_settle_options(kinetic_tol, force_tol, max_time, check_every, skin_fraction=0.1):
    for name, value in (("kinetic_tol", kinetic_tol), ("force_tol", force_tol), ("max_time", max_time),
                        ("skin_fraction", skin_fraction)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise PackingError(f"{name} must be a finite number > 0; got {shown(value)}")
    if not (isinstance(check_every, int) and check_every >= 1):
        raise PackingError(f"check_every must be an int >= 1; got {check_every!r}")


def _settle(sim, physics, state, fns, material, v_rel, start, phase, *, kinetic_tol, force_tol, max_time, check_every,
            progress, soft=None) -> DemSettled:
    """Step ``state`` (float64, under ``jax.enable_x64``) at ``material`` until settled (:func:`dem_settle`'s rule).

    The time step is sized here, at ``v_rel`` and the static column's overlap; ``soft``: the
    ``(modulus, steps)`` of the soft stage it was stiffened from, for the report.
    """
    from sintercond import simulate
    from sintercond.sim import mechanics
    from sintercond.laws.forces import effective_mass, hertz_collision_overlap
    from sintercond.rollout import ListOverflow, advance

    particles, contacts = state.particles, state.contacts
    centres, radii = np.asarray(particles.positions), np.asarray(particles.radii)
    mp = material.mechanical_params()
    r_max = float(radii.max())
    column = material.density * GRAVITY * float(np.max(centres[:, 2] + radii)) * (2.0 * r_max) ** 2
    static = _hertz_plane_overlap(column, r_max, material.E, material.nu)
    m_max = 4.0 / 3.0 * math.pi * r_max**3 * material.density
    collision = float(hertz_collision_overlap(r_max, effective_mass(m_max, jnp.inf), material.E / (1 - material.nu**2),
                                              v_rel))
    step_overlap = max(static, collision)
    step_fn = mechanics.mechanical_time_step
    dt = float(step_fn(physics.mechanics, particles, contacts.neighbors, mp, v_rel, step_overlap))
    dt = min(dt, float(step_fn(physics.mechanics, particles, contacts.neighbors, mp, v_rel, None)))
    state = dataclasses.replace(state, dt=jnp.asarray(dt, state.time.dtype))
    params = simulate.Params(conductivity=jnp.asarray([1.0]), specific_heat=jnp.asarray([1.0]), mechanics=mp)
    energy_scale = float(jnp.sum(particles.mass * GRAVITY * particles.radii))
    max_steps = check_every * int(math.ceil(max_time / dt / check_every))
    figures = {"kinetic": math.inf, "force": math.inf, "worst": "no sphere yet"}

    def settled(s, measured):
        kinetic, force, worst = measured
        k = int(worst)
        figures.update(kinetic=float(kinetic) / energy_scale, force=float(force),
                       worst=sphere_text(k, np.asarray(s.particles.positions[k]), radii[k]))
        if progress is not None:  # settled when both are below their thresholds: the larger ratio below 1
            _report(progress, phase, int(s.step), max_steps,
                    max(figures["kinetic"] / kinetic_tol, figures["force"] / force_tol), 1.0, worst=figures["worst"])
        return figures["kinetic"] < kinetic_tol and figures["force"] < force_tol

    first, began = int(state.step), float(state.time)
    try:
        state, loop = advance(sim, state, params, max_steps, check_every, settled,
                              reallocate=simulate.reallocate_neighbors(fns), check=_finite_positions,
                              measure=_settle_figures)
    except ListOverflow:
        raise PackingError("the DEM neighbour list keeps overflowing") from None
    final = np.asarray(state.particles.positions)
    steps = int(state.step) - first
    if not (figures["kinetic"] < kinetic_tol and figures["force"] < force_tol):
        missed = []
        if not figures["kinetic"] < kinetic_tol:
            missed.append(f"kinetic energy {figures['kinetic']:.3g} of sum m g r (allowed < {kinetic_tol:g})")
        if not figures["force"] < force_tol:
            missed.append(f"largest net force {figures['force']:.3g} of a sphere's weight (allowed < {force_tol:g}), "
                          f"on {figures['worst']}")
        what = ("the DEM bed did not settle" if soft is None else
                f"the DEM bed settled at {soft[0]:g} Pa did not settle once stiffened to {material.E:g} Pa")
        raise PackingError(f"{what} within {max_time:g} s ({steps} steps of {dt:.3g} s): " + " and ".join(missed))
    soft_modulus, soft_steps, residual = (None, 0, 0.0) if soft is None else soft
    report = SettleReport(steps, float(state.time) - began, dt, figures["kinetic"], float(kinetic_tol),
                          figures["force"], float(force_tol), _overlaps(final, radii, physics.mechanics.walls),
                          step_overlap, float(v_rel), loop.reallocations, time.perf_counter() - start,
                          soft_modulus, soft_steps, residual)
    return DemSettled(final, state, sim, params, fns, report, material)


STIFFEN_ITERATIONS = 3
"""Gauss-Newton passes of :func:`stiffen`'s displacement: each solves the contacts' overlaps to first order in the
displacement, so the normals that turn with it leave a remainder of second order (the overlaps are ~1e-2 of a
radius), which the next pass removes."""


def stiffened_positions(centres, radii, pairs, walls, ratio, iterations=STIFFEN_ITERATIONS):
    """Positions (m) at which every touching pair and sphere-wall overlap is ``ratio`` times its value at
    ``centres`` and no other pair or sphere-wall overlaps, and the relative residual of those overlaps.

    The displacements are the least-norm solution of the linear system ``n_ij . (u_j - u_i) = h_ij - h'_ij`` of the
    pairs (``n_ij`` from ``i`` to ``j``, ``h`` the overlap) and ``n_w . u_i = p_iw - p'_iw`` of the walls
    (``p`` the penetration), by LSQR (:func:`scipy.sparse.linalg.lsqr`), repeated ``iterations`` times from the
    moved positions. A pair (or sphere and wall) apart at ``centres`` that the displacements would bring into
    contact joins the system at zero overlap (touching, no force), and the solve is repeated until none is left
    (an active set). A packing of more contacts than its particles' degrees of freedom in some region has no exact
    solution there: the residual says how far the least-squares one is (``|h' - h_target|`` over
    ``|h_target|``, all contacts).

    Args:
      centres: ``[n, 3]`` (m); radii ``[n]`` (m); pairs ``[c, 2]`` candidate pairs (padding ``(n, n)`` ignored);
      walls: :class:`sintercond.laws.walls.PlaneWall` s; ratio: in (0, 1].
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import lsqr

    x0 = np.array(centres, np.float64)
    r = np.asarray(radii, np.float64)
    n = len(r)
    pairs = np.asarray(pairs)
    pairs = pairs[(pairs[:, 0] < n) & (pairs[:, 1] < n) & (pairs[:, 0] != pairs[:, 1])]
    wall_normals = np.array([np.asarray(w.normal, np.float64) for w in walls]).reshape(-1, 3)

    def overlaps(x):  # [c] pair overlaps, [c, 3] normals i -> j, [n_walls, n] penetrations
        d = x[pairs[:, 1]] - x[pairs[:, 0]]
        dist = np.linalg.norm(d, axis=1)
        wall = np.array([np.asarray(w.penetration(x, r), np.float64) for w in walls]).reshape(-1, n)
        return r[pairs[:, 0]] + r[pairs[:, 1]] - dist, d / dist[:, None], wall

    h0, _, p0 = overlaps(x0)
    pair_target, wall_target = ratio * np.maximum(h0, 0.0), ratio * np.maximum(p0, 0.0)
    active, active_wall = h0 > 0, p0 > 0
    if not (active.any() or active_wall.any()):
        return x0, 0.0

    def solve(active, active_wall):
        x = x0.copy()
        for _ in range(iterations):
            h, normal, p = overlaps(x)
            k = np.flatnonzero(active)
            i, j = pairs[k, 0], pairs[k, 1]
            w, m = np.nonzero(active_wall)
            rows = np.concatenate([np.repeat(np.arange(len(k)), 6), np.repeat(len(k) + np.arange(len(m)), 3)])
            cols = np.concatenate([np.concatenate([3 * j[:, None] + np.arange(3), 3 * i[:, None] + np.arange(3)],
                                                  axis=1).ravel(), (3 * m[:, None] + np.arange(3)).ravel()])
            vals = np.concatenate([np.concatenate([normal[k], -normal[k]], axis=1).ravel(), wall_normals[w].ravel()])
            matrix = coo_matrix((vals, (rows, cols)), shape=(len(k) + len(m), 3 * n)).tocsr()
            rhs = np.concatenate([h[k] - pair_target[k], p[w, m] - wall_target[w, m]])
            x = x + lsqr(matrix, rhs, atol=1e-14, btol=1e-14, iter_lim=60 * n)[0].reshape(n, 3)
        return x

    for _ in range(n):
        x = solve(active, active_wall)
        h, _, p = overlaps(x)
        new, new_wall = (h > 0) & ~active, (p > 0) & ~active_wall
        if not (new.any() or new_wall.any()):
            break
        active, active_wall = active | new, active_wall | new_wall
    now = np.concatenate([h[active], p[active_wall]])
    target = np.concatenate([pair_target[active], wall_target[active_wall]])
    return x, float(np.linalg.norm(now - target) / np.linalg.norm(target))


def stiffen(settled: DemSettled, material: DemMaterial, *, kinetic_tol=KINETIC_TOL, force_tol=FORCE_TOL, max_time=2.0,
            check_every=1000, progress=None) -> DemSettled:
    """A bed settled at a soft modulus (:func:`dem_settle`) carried to ``material``'s, and settled again.

    Hertz normal forces go as ``E* sqrt(r*) h^(3/2)`` and the Mindlin tangential and rolling stiffnesses as
    ``G* sqrt(r* h)`` (Eqs. 2, 7, 15; ``E*``, ``G*`` proportional to ``E`` at one Poisson ratio), each force capped
    by Coulomb's ``mu F_n``: scaling every overlap, tangential spring and rolling spring by
    ``lambda = (E_soft / E)^(2/3)`` leaves every force and torque as it was. The settled bed is moved to overlaps
    ``lambda`` times its own (:func:`stiffened_positions`), its springs scaled by ``lambda``, at rest, and the DEM
    at ``material`` settles what the moved normals and an over-constrained region's least-squares residual leave
    (at the stiff step, sized as :func:`dem_settle` sizes it).

    ``material`` must be the settled bed's own but for ``E`` (larger). The report's ``steps`` are the stiff
    stage's, ``soft_steps`` and ``soft_modulus`` the soft stage's, ``stiffen_residual`` the moved overlaps'.
    """
    soft = settled.material
    if (soft is None or not isinstance(material, DemMaterial) or dataclasses.replace(soft, E=material.E) != material
            or not material.E > soft.E):
        raise PackingError("stiffen takes the DemMaterial of the soft settle with a larger E only; got "
                           f"{material!r} for a bed settled at {soft!r}")
    _check_settle_options(kinetic_tol, force_tol, max_time, check_every)
    start = time.perf_counter()
    ratio = (soft.E / material.E) ** (2.0 / 3.0)
    state = settled.state
    with jax.enable_x64(True):
        walls = settled.sim.physics.mechanics.walls
        x, residual = stiffened_positions(state.particles.positions, state.particles.radii,
                                          state.contacts.pairs.pairs, walls, ratio)
        motion = state.mechanics
        scaled = lambda s: None if s is None else s * ratio  # noqa: E731
        motion = dataclasses.replace(motion, velocity=jnp.zeros_like(motion.velocity), spin=jnp.zeros_like(motion.spin),
                                     spring=scaled(motion.spring), rolling=scaled(motion.rolling),
                                     wall_spring=scaled(motion.wall_spring), wall_rolling=scaled(motion.wall_rolling))
        particles = dataclasses.replace(state.particles, positions=jnp.asarray(x, state.particles.positions.dtype))
        state = dataclasses.replace(state, particles=particles, mechanics=motion)
        return _settle(settled.sim, settled.sim.physics, state, settled.neighbor_fns, material, settled.report.v_rel,
                       start, "stiffening (DEM)", kinetic_tol=kinetic_tol, force_tol=force_tol, max_time=max_time,
                       check_every=check_every, progress=progress,
                       soft=(soft.E, settled.report.steps + settled.report.soft_steps, residual))


def _settle_figures(sim, state, params):
    """:func:`dem_settle`'s figures of a chunk's end state, from one probe step: ``((kinetic energy (J), largest net
    force over weight, the sphere it is on), the probe step overflowed)``; the net force is ``m dv/dt`` over that
    step."""
    probe = sim.step_fn(state, params)
    p, v, w = state.particles, state.mechanics.velocity, state.mechanics.spin
    kinetic = 0.5 * jnp.sum(p.mass[:, None] * v**2) + 0.5 * jnp.sum(0.4 * p.mass[:, None] * p.radii[:, None]**2 * w**2)
    force = p.mass[:, None] * (probe.mechanics.velocity - v) / state.dt
    ratio = jnp.linalg.norm(force, axis=1) / (p.mass * GRAVITY)
    return (kinetic, jnp.max(ratio), jnp.argmax(ratio)), probe.overflow


def _finite_positions(state):
    if not bool(jnp.all(jnp.isfinite(state.particles.positions))):
        raise PackingError(f"non-finite positions at DEM step {int(state.step)}")
