"""What a run reports of a state: the rows of ``history.csv`` (:func:`history_columns`, :func:`observe`), the
heat through each wall, with mechanics the motion and contacts, with sintering the necks and k*, and the contact
network (:func:`contact_network`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from sintercond import simulate
from sintercond.beds import packing
from sintercond.contacts import network
from sintercond.laws import forces, walls
from sintercond.sim import mechanics, neck_growth, steady
from sintercond.sim.terms import mechanics as mechanics_term
from sintercond.laws.neck import NECK_MODELS

from sintercond.scene.build import _walls, scene_walls


HISTORY_COLUMNS = ("step", "time_s", "T_mean_K", "T_min_K", "T_max_K")
"""The columns of ``history.csv`` every run has, one row per output step (the LAMMPS "thermo" analogue)."""


MECHANICS_COLUMNS = ("kinetic_energy_J", "contacts", "wall_contacts", "max_overlap_m")
"""Columns a run with mechanics adds: translational plus rotational kinetic energy, touching particle pairs,
particles touching a wall, and the largest overlap of a pair or a wall contact."""


SINTERING_COLUMNS = ("mean_neck_ratio", "max_neck_ratio", "shrinkage")
"""Columns a run with ``[sintering]`` adds (:func:`sintercond.sim.neck_growth.neck_statistics`): the mean and largest
neck ratio ``a / min(r_i, r_j)`` over the contacts and the mean linear shrinkage of their approaches."""


PACKING_SHRINKAGE_COLUMNS = ("height_shrinkage", "volume_shrinkage")
"""Columns a sintering run whose particles move (many-body shrinkage, or the mechanics) adds: the relative loss of
the packing's height (along z) and of its volume since the start, from the best-fit homogeneous deformation of its
centres (:func:`sintercond.beds.packing.packing_shrinkage`)."""


K_STAR_COLUMNS = ("k_star_W_mK", "k_star_uncoupled")
"""Columns ``sintering.k_star_axis`` adds: the packing's k* (W/(m K), :func:`sintered_conductivity`) and how many
particles it keeps at the pair laws' halves because two of their necks' discs overlap
(:func:`conductivity_and_uncoupled`)."""


def moves(model) -> bool:
    """Whether the particles of ``model``'s sintering run move (:data:`PACKING_SHRINKAGE_COLUMNS` apply)."""
    physics = model.physics
    return physics.sintering is not None and (physics.mechanics is not None
                                              or physics.sintering.shrinkage == "many_body")


def history_columns(model) -> tuple:
    """The columns of ``history.csv`` of ``model``: :data:`HISTORY_COLUMNS`, :data:`MECHANICS_COLUMNS` with
    mechanics, :data:`SINTERING_COLUMNS` with sintering (and :data:`PACKING_SHRINKAGE_COLUMNS` where the particles
    move), :data:`K_STAR_COLUMNS` with ``sintering.k_star_axis``, and ``heat_wall{k}_W`` (the heat power into the packing
    through scene wall ``k``, W) for each held or conducting wall."""
    return (HISTORY_COLUMNS + (MECHANICS_COLUMNS if model.physics.mechanics is not None else ())
            + (SINTERING_COLUMNS if model.physics.sintering is not None else ())
            + (PACKING_SHRINKAGE_COLUMNS if moves(model) else ())
            + (K_STAR_COLUMNS if model.k_star_axis is not None else ())
            + tuple(spec[0] for spec in model.wall_heat))


_pair_neck_conductance = jax.jit(simulate.pair_neck_conductance, static_argnums=0)  # compiled once per run


def sintered_conductivity(model, state) -> float:
    """k* (W/(m K)) of a sintering state along ``model.k_star_axis``: one steady solve on its grown necks
    (:func:`sintercond.sim.steady.steady_state_network_conductivity`, on the network of ``model.k_star_coupling``:
    necks coupled through their sphere, those of a sphere whose necks' discs overlap at the pair law's halves), 0
    while no contact conducts, in the box of :func:`k_star_box`; with the mechanics NaN while no particle touches one
    of the box's two faces (an inertial bed bouncing off its floor: no heat to impose there). Each particle conducts
    at its conductivity (at its temperature with a property table)."""
    return conductivity_and_uncoupled(model, state)[0]


def conductivity_and_uncoupled(model, state) -> tuple[float, int]:
    """``(k*, uncoupled)``: :func:`sintered_conductivity`, and how many particles have two coupled necks whose discs
    overlap (outside point coupling, :func:`sintercond.contacts.sphere_coupling.outside_domain`), whose pair laws'
    halves the coupled ``k*`` keeps; ``uncoupled`` is 0 with ``k_star_coupling = "none"``."""
    network_now = _conducting_network(model, state)
    if network_now is None:
        return 0.0, 0
    centres, pairs, pair_k, neck, kappa = network_now
    try:
        k_star, outside = steady.steady_state_network_conductivity(
            centres, model.radii, pairs, pair_k, axis=model.k_star_axis, box=k_star_box(model, centres),
            coupling=model.k_star_coupling, kappa=kappa, neck_radii=neck, beyond_domain="isolated", domain=True)
    except steady.NoFaceLayer:  # the moving packing left a face of its box (a bed bouncing off its floor)
        return float("nan"), 0
    return float(k_star), int(np.count_nonzero(np.asarray(outside)))


_sintered_pair_network = jax.jit(simulate.sintered_pair_network, static_argnums=0)
_particle_conductivity = jax.jit(simulate.particle_conductivity, static_argnums=0)


def _conducting_network(model, state):
    """``(centres [n, 3], pairs, K [c], neck [c], kappa [n] or None)`` of the contacts that conduct in ``state`` (host;
    ``kappa`` with ``k_star_coupling = "sphere"``), or
    None while none does: the half pair list where the packing has moved to with the mechanics, else the static
    table's pairs on their grown necks."""
    radii = model.radii
    kappa = None
    if model.k_star_coupling == "sphere":  # the coupled network's Green function scales as 1/kappa
        kappa = np.asarray(_particle_conductivity(model.physics, model.params, state.particles), np.float64)
    if state.mechanics is not None:
        geometry, neck, pair_k = _sintered_pair_network(model.physics, state, model.params)
        keep = np.asarray(geometry.touching) & (np.asarray(pair_k) > 0)
        i, j = np.asarray(geometry.i, np.int64)[keep], np.asarray(geometry.j, np.int64)[keep]
        centres = np.asarray(state.particles.positions, np.float64)
        overlap, neck = np.asarray(geometry.overlap)[keep], np.asarray(neck, np.float64)[keep]
        pair_k = np.asarray(pair_k)[keep]
    else:
        pair_k = np.asarray(_pair_neck_conductance(model.physics, state, model.params))
        i, j = np.asarray(state.contacts.pairs, np.int64).T
        centres, overlap, neck = model.centres, np.asarray(state.contacts.overlap), np.asarray(state.contacts.neck)
    if not np.any(pair_k > 0):
        return None
    pairs = network.ContactPairs(i, j, overlap, radii[i], radii[j], len(radii))
    return centres, pairs, pair_k, np.where(pair_k > 0, neck, 0.0), kappa


def k_star_box(model, centres):
    """The box the k* of ``model``'s packing at ``centres`` (m) is measured in
    (:func:`sintercond.beds.packing.measurement_box`, as ``sintercond effective``'s)."""
    return packing.measurement_box(centres, model.radii, model.k_star_axis, lattice=model.lattice,
                                  bed_size=model.bed_size)


class Observation(NamedTuple):
    """What a run reports of a state besides temperatures (host arrays): see :func:`observe`."""

    wall_heat: tuple  # W per held or conducting wall, in model.wall_heat order
    kinetic_energy: float = float("nan")
    pairs: Any = None  # [p, 2] touching particle pairs
    pair_overlap: Any = None  # [p] (m)
    wall_overlap: Any = None  # [n_walls, n] (m), > 0 touching
    velocity: Any = None  # [n, 3] (m/s)
    force: Any = None  # [n, 3] contact force (N), gravity excluded
    power: Any = None  # [n] net heat power into each particle from its contacts, walls and sources (W)


def state_time(state) -> float:
    """``step * dt`` (s) of ``state`` on the host: :attr:`sintercond.simulate.SimState.time`'s one multiplication in
    NumPy (the same number; op by op, JAX would compile it)."""
    dt = np.asarray(state.dt)
    return float(np.asarray(state.step).astype(dt.dtype) * dt)


def _probe_fn(model):
    """A jitted ``(state, params) -> (heat power [n] W, contact force [n, 3] N or None)`` for :func:`observe`. The
    contact force (gravity excluded): with inertia ``m (v(t + dt) - v(t)) / dt - m g``, one symplectic-Euler step of
    the simulator (Eq. 43); quasi-static, the resultant of the step's laws less ``m g``
    (:func:`sintercond.sim.terms.mechanics.resultant_forces`)."""
    sim, spec = model.sim, model.physics.mechanics

    def probe(state, params):
        prep = sim.prepare_fn(state, params)
        power = sim.heat_power_fn(state, prep)
        if spec is None:
            return power, None
        m = state.particles.mass[:, None]
        g = jnp.asarray(spec.gravity, m.dtype)
        if spec.quasi_static:
            resultant, _ = mechanics_term.resultant_forces(model.physics, state, params)
            return power, resultant - m * g
        after = sim.advance_fn(state, prep).mechanics.velocity
        return power, m * ((after - state.mechanics.velocity) / state.dt - g)

    return jax.jit(probe)


def _plane_penetration(plane, positions, radii, t):
    """``r - (x - p(t)) . n`` (m) of each particle on a plane wall whose point moves at its velocity."""
    point = np.asarray(plane.point) + t * np.asarray(plane.velocity)
    return radii - (positions - point) @ np.asarray(plane.normal)


def observe(scene, model, state, probe) -> Observation:
    """Heat through each held or conducting wall, and with mechanics the motion and the contacts, of ``state``.

    Heat into the packing through a conducting wall: ``sum_i K_iw (T_w - T_i)``
    with ``K_iw`` the wall conductance of the scene's law at the current
    penetration (:func:`sintercond.laws.walls.wall_conductance`); through a held
    wall: the power its held particles lose to the rest,
    ``-sum_i P_i`` over them (what holds them at their temperature).
    With mechanics: the contact force ``m (v(t + dt) - v(t)) / dt - m g``
    (one symplectic-Euler step of the simulator, Eq. 43; quasi-static, the
    resultant of the step's laws less ``m g``, :func:`_probe_fn`), kinetic energy
    ``sum m v^2/2 + I omega^2/2`` (``I = (2/5) m r^2``), touching pairs and
    wall contacts.
    """
    p = state.particles
    positions, radii, temperature = (np.asarray(x) for x in (p.positions, p.radii, p.temperature))
    index, conductivity = simulate.conductivity_lookup(model.physics, model.params, p)
    kappa = np.asarray(conductivity)[np.asarray(index)]
    needs_power = (any(spec[2] == "held" for spec in model.wall_heat) or model.physics.mechanics is not None
                   or "vtp" in scene["run"]["formats"])
    power, motion = probe(state, model.params) if needs_power else (None, None)
    planes = list(model.planes) or scene_walls(scene, np.asarray(model.state.particles.positions), radii)
    if model.physics.mechanics is not None:
        planes = list(model.physics.mechanics.walls)
    t = state_time(state)
    conducting_power = np.zeros(len(radii))
    wall_h = [_plane_penetration(plane, positions, radii, t) for plane in planes]
    flows = {}
    c = scene["conduction"]
    for k, wall in enumerate(_walls(scene)):
        if wall["mode"] == "conducting":
            k_w = np.asarray(walls.wall_conductance(c["law"], radii, wall_h[k], kappa, params=c.get("params"),
                                                    neck_model=c.get("neck_model")))
            q = k_w * (wall["temperature"] - temperature)
            conducting_power += q if model.physics.mechanics is not None else 0.0  # the thermal simulator's P_i holds it
            flows[k] = float(np.sum(q))
    for _, k, mode, mask in model.wall_heat:
        if mode == "held":
            flows[k] = -float(np.sum((np.asarray(power) + conducting_power)[mask]))
    heat = tuple(flows[spec[1]] for spec in model.wall_heat)
    total = None if power is None else np.asarray(power) + conducting_power
    if model.physics.mechanics is None:
        return Observation(heat, power=total)
    m = np.asarray(p.mass)
    v, omega = np.asarray(state.mechanics.velocity), np.asarray(state.mechanics.spin)
    inertia = forces.SOLID_SPHERE_INERTIA * m * radii**2
    kinetic = float(0.5 * np.sum(m * np.sum(v * v, axis=1)) + 0.5 * np.sum(inertia * np.sum(omega * omega, axis=1)))
    force = np.asarray(motion)
    pairs, overlap = _touching_pairs(positions, radii, np.asarray(state.contacts.neighbors))
    return Observation(heat, kinetic, pairs, overlap, np.stack(wall_h) if wall_h else np.zeros((0, len(radii))),
                       v, force, total)


def _touching_pairs(positions, radii, neighbors):
    """Touching pairs ``[p, 2]`` (each once, ``i < j``) among the listed candidates, and their overlaps (m)."""
    n = len(radii)
    rows = np.broadcast_to(np.arange(n)[:, None], neighbors.shape)
    listed = (neighbors < n) & (neighbors != rows)
    i, j = rows[listed], neighbors[listed]
    lo, hi = np.unique(np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1), axis=0).T if len(i) else (i, j)
    overlap = radii[lo] + radii[hi] - np.linalg.norm(positions[hi] - positions[lo], axis=1)
    touching = overlap > 0
    return np.stack([lo[touching], hi[touching]], axis=1), overlap[touching]


def coordination(n, pairs):
    """Contacts per particle ``[n]`` (particle pairs only, walls not counted)."""
    return np.bincount(np.ravel(pairs), minlength=n)


def _history_row(model, state, obs: Observation) -> str:
    t = np.asarray(state.particles.temperature)
    values = [state_time(state), float(t.mean()), float(t.min()), float(t.max())]  # Python floats: plain repr
    if model.physics.mechanics is not None:
        touching_walls = int(np.sum(np.any(obs.wall_overlap > 0, axis=0))) if len(obs.wall_overlap) else 0
        largest = float(max(np.max(obs.pair_overlap, initial=0.0), np.max(obs.wall_overlap, initial=0.0)))
        values += [obs.kinetic_energy, len(obs.pairs), touching_walls, largest]
    if model.physics.sintering is not None:
        stats = neck_growth.neck_statistics(state)
        values += [float(stats[name]) for name in SINTERING_COLUMNS]
    if moves(model):
        strain = packing.packing_shrinkage(state.sintering.start_positions, state.particles.positions)
        values += [strain[name] for name in PACKING_SHRINKAGE_COLUMNS]
    if model.k_star_axis is not None:
        values += list(conductivity_and_uncoupled(model, state))
    values += list(obs.wall_heat)
    return f"{int(state.step)}," + ",".join(repr(v) if isinstance(v, float) else str(v) for v in values) + "\n"


def read_history(out) -> dict:
    """``history.csv`` of a run as a dict of arrays: ``time`` (s) and every other column by its name (for the plot)."""
    data = np.genfromtxt(Path(out) / "history.csv", delimiter=",", names=True, ndmin=1)
    return {"time": data["time_s"], **{name: data[name] for name in data.dtype.names if name not in ("step", "time_s")}}


def contact_network(model, state) -> tuple:
    """The contacts of ``state`` and what each carries: ``(pairs [p, 2], fields)``, pairs ``i < j``.

    ``fields``: ``neck_radius`` (m, the neck the conductance law takes), ``conductance`` (W/K) and ``heat_flow``
    (W, ``K (T_i - T_j)``: from ``i`` to ``j``); the contacts the static table lists (touching within the
    packing's tolerance, point contacts of a sintering lattice included), or the touching pairs of a moving
    packing's list. With mechanics also ``force`` ``[p, 3]`` (N, on ``i`` from ``j``,
    :func:`sintercond.simulate.contact_forces`) and ``normal_force`` (N, its component along the line of centres,
    > 0 pushing the two apart): the force chains.
    """
    physics, p = model.physics, state.particles
    radii, temperature = np.asarray(p.radii), np.asarray(p.temperature)
    index, kappa = simulate.conductivity_lookup(physics, model.params, p)
    law = simulate.merged_law_params(physics, model.params)
    forces = {}
    if physics.contacts == "dynamic":
        geometry = mechanics.pair_geometry(p.positions, p.radii, state.contacts.pairs.pairs)
        keep = np.asarray(geometry.touching & geometry.valid)
        if physics.mechanics is not None:
            force = np.asarray(jax.jit(simulate.contact_forces, static_argnums=0)(physics, state, model.params)[1])[keep]
            forces = {"force": force, "normal_force": -np.sum(force * np.asarray(geometry.normal)[keep], axis=1)}
        pairs = np.stack([np.asarray(geometry.i), np.asarray(geometry.j)], axis=1)[keep]
        k = np.asarray(simulate.pair_conductance(physics, p.radii, index, geometry, kappa, law))[keep]
        overlap = np.asarray(geometry.overlap)[keep]
        neck = np.asarray(NECK_MODELS[physics.neck](radii[pairs[:, 0]], radii[pairs[:, 1]], overlap))
    else:
        if physics.conduction.conductance == "table":
            neighbors = np.asarray(state.contacts.neighbors)
            rows = np.broadcast_to(np.arange(len(radii))[:, None], neighbors.shape)
            lower = (rows < neighbors) & (neighbors < len(radii))
            pairs = np.stack([rows[lower], neighbors[lower]], axis=1)
            k = np.asarray(state.contacts.conductance)[lower] * float(np.asarray(kappa)[0])
            centres = np.asarray(p.positions)
            overlap = np.maximum(radii[pairs[:, 0]] + radii[pairs[:, 1]]
                                 - np.linalg.norm(centres[pairs[:, 0]] - centres[pairs[:, 1]], axis=1), 0.0)
            neck = np.asarray(NECK_MODELS[physics.neck](radii[pairs[:, 0]], radii[pairs[:, 1]], overlap))
        else:
            pairs = np.asarray(state.contacts.pairs, np.int64)
            k = np.asarray(simulate.pair_neck_conductance(physics, state, model.params))
            neck = np.asarray(state.contacts.neck)
    flow = k * (temperature[pairs[:, 0]] - temperature[pairs[:, 1]])
    return pairs, {"neck_radius": neck, "conductance": k, "heat_flow": flow, **forces}

