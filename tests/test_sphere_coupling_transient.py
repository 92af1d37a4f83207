"""Necks coupled through their sphere in the explicit transient step (issue 40, ``Conduction.coupling="sphere"``).

References, all independent of the transient code: the isolated network where the coupling is exact (a chain, the
simple-cubic block heated along an axis); the steady coupled solver (sintercond.sim.steady, conjugate gradients on
the sphere and neck unknowns together) for a lattice run to steady state; conservation of heat; central
differences; float64 for float32; the alternating mode of a periodic BCC lattice, where the stability bound is
attained.
"""

import copy
import dataclasses
import functools
import sys
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from fullfield import lattice_block, overlap_for_neck, rizza_block

from sintercond import scene, simulate
from sintercond.laws.neck import max_overlap
from sintercond.sim import neck_growth
from sintercond.scene.build import build_model, scene_physics
from sintercond.scene.typed import typed_scene
from sintercond.sim.physics import Conduction, Physics
from sintercond.sim.rollout import rollout
from sintercond.sim.stability import thermal_time_step
from sintercond.sim.state import Params, PulseParams
from sintercond.sim.steady import steady_state_conductivity
from sintercond.sim.terms import coupling as coupling_term
from sintercond.contacts.sphere_coupling import outside_domain
from sintercond.state import particle_state

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
from fullfield_cells import RIZZA_NECKS  # noqa: E402

PARAMS = Params(jnp.array([1.0]), jnp.array([1.0]))


def physics(coupling, **kw):
    return Physics.create(conductance="lifted", coupling=coupling, **kw)


def start(coupling, centres, radii, temperature, *, fixed=None, held=None, axis=0, periodic_box=None, dt=None,
          params=PARAMS, **kw):
    """``(simulator, state, stable step)`` of a static packing; ``dt`` (s) default 0.9 of the stable step."""
    spec = physics(coupling, held=fixed is not None, **kw)
    contacts = simulate.lifted_contacts(spec, centres, radii, periodic_box=periodic_box, held=held, held_axis=axis)
    p = particle_state(centres, radii, temperature, 1.0, fixed=fixed, fixed_temperature=temperature)
    sim = simulate.simulator(spec)
    limit = float(thermal_time_step(sim, simulate.init_state(p, contacts, 1.0), params))
    return sim, simulate.init_state(p, contacts, 0.9 * limit if dt is None else dt), limit


@functools.cache
def compiled(sim, n):
    return jax.jit(lambda state, params: rollout(sim, state, params, n)[0])


def run(sim, state, n, params=PARAMS):
    """The state after ``n`` steps, one compiled program per simulator and ``n``."""
    return compiled(sim, n)(state, params)


def chain(radii, overlap):
    radii = np.asarray(radii, float)
    x = np.concatenate([[0.0], np.cumsum(radii[:-1] + radii[1:] - overlap)])
    return np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1), radii


def random_cluster(n, seed):
    """Spheres of radii 0.8-1.2 stuck one by one onto a random sphere of the cluster at 4 % overlap, kept where no
    other sphere overlaps them by more than 6 % (some loops form) and the necks stay apart (the domain)."""
    rng = np.random.default_rng(seed)
    centres, radii = [np.zeros(3)], [1.0]
    spec = physics("sphere")
    while len(radii) < n:
        i = rng.integers(len(radii))
        r = rng.uniform(0.8, 1.2)
        u = rng.normal(size=3)
        c = centres[i] + u / np.linalg.norm(u) * (radii[i] + r) * 0.96
        d = np.linalg.norm(np.array(centres) - c, axis=1)
        if np.any(d < (np.array(radii) + r) * 0.94) or not _necks_apart(np.array(centres + [c]),
                                                                        np.array(radii + [r])):
            continue
        centres.append(c)
        radii.append(r)
    centres, radii = np.array(centres), np.array(radii)
    simulate.lifted_contacts(spec, centres, radii)  # inside the domain
    return centres, radii


def _necks_apart(centres, radii, min_angle=50.0):
    """Every two contacts of a sphere at least ``min_angle`` degrees apart (discs of 4-6 % overlaps: < 40 deg)."""
    for s in range(len(radii)):
        d = centres - centres[s]
        dist = np.linalg.norm(d, axis=1)
        touching = (dist < radii + radii[s]) & (dist > 0)
        u = d[touching] / dist[touching, None]
        cos = np.clip(u @ u.T, -1, 1) - 2 * np.eye(len(u))
        if len(u) > 1 and np.degrees(np.arccos(cos.max())) < min_angle:
            return False
    return True


@pytest.fixture(scope="module")
def cluster():
    centres, radii = random_cluster(12, 3)
    temperature = 300.0 + 200.0 * np.random.default_rng(0).random(len(radii))
    return centres, radii, temperature


# --------------------------------------------------------------------------
# (b) where the coupling is exact: the isolated network


@pytest.mark.slow
def test_chain_transient_is_the_isolated_one():
    """A chain of unequal spheres with one end held: two opposite necks a sphere carry any flows, the net flow's
    term (Eq. 5) keeps the pair law, and the coupled run is the isolated one to round-off (its stable step too)."""
    centres, radii = chain([1.0, 0.8, 1.2, 1.0, 0.9, 1.1], 0.08)
    temperature = np.array([500.0, 300, 420, 310, 330, 600])
    fixed = np.arange(6) == 0
    ends = {}
    for coupling in ("none", "sphere"):
        sim, state, limit = start(coupling, centres, radii, temperature, fixed=fixed, held=fixed.astype(int))
        ends[coupling] = (limit, np.asarray(run(sim, state, 300).particles.temperature))
    assert ends["sphere"][0] == pytest.approx(ends["none"][0], rel=1e-13)
    np.testing.assert_allclose(ends["sphere"][1], ends["none"][1], rtol=1e-13)
    assert np.ptp(ends["none"][1]) < 0.5 * np.ptp(temperature)  # it moved


@pytest.mark.slow
def test_simple_cubic_block_heated_along_an_axis_is_the_isolated_one():
    """A 4 x 3 x 3 simple-cubic block, insulated, each layer across x at its own temperature: the side necks carry
    nothing, the axial ones are opposite (or alone on an end sphere), so the coupled network is the isolated one.
    The step's neck balance lags one sweep (the side necks' temperatures follow the spheres' stored heat, Eq. 5):
    the coupled run is the isolated one to that lag, under 1 % of explicit Euler's own error (the isolated run
    against ten times smaller steps; measured 0.1 %, 0.38 mK against 0.38 K) and falling with the step (8.5 times
    smaller at a tenth of it); its steady state is exact (FCC test below)."""
    g = np.stack(np.meshgrid(np.arange(4), np.arange(3), np.arange(3), indexing="ij"), -1).reshape(-1, 3)
    centres, radii = g * 1.9, np.ones(len(g))
    temperature = np.array([300.0, 700.0, 350.0, 500.0])[g[:, 0]]
    dt = 0.9 * min(start(coupling, centres, radii, temperature)[2] for coupling in ("none", "sphere"))
    ends = {}
    for coupling, divide in (("none", 1), ("sphere", 1), ("none", 10), ("sphere", 10)):
        sim, state, _ = start(coupling, centres, radii, temperature, dt=dt / divide)
        ends[coupling, divide] = np.asarray(run(sim, state, 20 * divide).particles.temperature)
    euler = np.max(np.abs(ends["none", 1] - ends["none", 10]))
    lag = np.max(np.abs(ends["sphere", 1] - ends["none", 1]))
    assert lag < 0.01 * euler
    assert np.max(np.abs(ends["sphere", 10] - ends["none", 10])) < 0.2 * lag
    assert 1.0 < np.ptp(ends["none", 1]) < 0.9 * 400.0


# --------------------------------------------------------------------------
# (c) run to steady state: the steady coupled solver


@pytest.mark.slow
def test_fcc_block_runs_to_the_steady_coupled_field():
    """An FCC block (a/r = 0.22) between held layers, periodic across x, run 2500 explicit steps from a uniform
    interior: its field and k* equal steady_state_conductivity(..., coupling="sphere") (a separate solve of sphere
    and neck unknowns together) to 1e-10; the isolated network's k* is 13 % higher."""
    centres, radii, length, kw = lattice_block("FCC", 0.22)
    k_ref, field_ref = steady_state_conductivity(centres, radii, 1.0, coupling="sphere", field=True, **kw)
    x = centres[:, 0]
    hot, cold = np.isclose(x, x.min()), np.isclose(x, x.max())
    periods = np.array(kw["periodic_box"], float)
    periods[0] = 1e3
    temperature = np.where(hot, 400.0, np.where(cold, 300.0, 350.0))
    sim, state, _ = start("sphere", centres, radii, temperature, fixed=hot | cold,
                          held=np.where(hot, 1, np.where(cold, 2, 0)), periodic_box=periods)
    end = run(sim, state, 2500)
    np.testing.assert_allclose((np.asarray(end.particles.temperature) - 300.0) / 100.0, np.asarray(field_ref),
                               rtol=0, atol=1e-10)
    power = np.asarray(sim.heat_power_fn(end, sim.prepare_fn(end, PARAMS)))
    k_star = -power[hot].sum() / 100.0 * (x[cold].mean() - x[hot].mean()) / (2 * length) ** 2
    assert k_star == pytest.approx(k_ref, rel=1e-10)
    assert steady_state_conductivity(centres, radii, 1.0, coupling="none", **kw) > 1.1 * k_ref


# --------------------------------------------------------------------------
# (d) heat conserved; sources unchanged


@pytest.mark.slow
def test_heat_is_conserved_on_an_insulated_cluster_with_a_pulse(cluster):
    """A random cluster of unequal spheres (loops included), insulated, one sphere given a pulse: sum_i C_i T_i
    grows by exactly the pulse's energy, to round-off, and the run is not the isolated one."""
    centres, radii, temperature = cluster
    n = len(radii)
    power = np.zeros(n)
    power[0] = 50.0
    params = dataclasses.replace(PARAMS, pulse=PulseParams(jnp.asarray(power), jnp.asarray(1e9)))
    ends = {}
    for coupling in ("none", "sphere"):
        sim, state, _ = start(coupling, centres, radii, temperature, pulse=True, params=params)
        end = run(sim, state, 200, params)
        capacity = np.asarray(end.particles.mass)
        heat_in = 200 * float(state.dt) * power.sum()
        ends[coupling] = np.asarray(end.particles.temperature)
        gained = np.sum(capacity * (ends[coupling] - temperature))
        assert gained == pytest.approx(heat_in, rel=1e-12), coupling
    assert np.max(np.abs(ends["sphere"] - ends["none"])) > 1e-3


@pytest.mark.slow
def test_property_tables_with_coupled_necks(cluster):
    """material tables with the coupled necks (the blocks follow kappa(T) at every step): a chain with a
    conductivity and a specific-heat table is the isolated chain with the same tables to round-off (the coupling is
    exact there); on a random cluster, tables flat at the constant values give the constant-property run to
    round-off, and a conductivity table that varies keeps sum_i C_i T_i of the insulated cluster to round-off while
    moving the field away from the constant run."""
    from sintercond.laws import materials

    kappa = materials.tabulated([300.0, 400.0, 600.0], [1.0, 1.6, 2.5])
    heat = materials.tabulated([300.0, 600.0], [1.0, 1.3])
    tables = Params(kappa, heat)
    centres, radii = chain([1.0, 0.8, 1.2, 1.0, 0.9, 1.1], 0.08)
    temperature = np.array([500.0, 300, 420, 310, 330, 590])
    ends = {}
    for coupling in ("none", "sphere"):
        sim, state, limit = start(coupling, centres, radii, temperature, params=tables, conductivity_table=True,
                                  specific_heat_table=True)
        ends[coupling] = (limit, np.asarray(run(sim, state, 300, tables).particles.temperature))
    assert ends["sphere"][0] == pytest.approx(ends["none"][0], rel=1e-13)
    np.testing.assert_allclose(ends["sphere"][1], ends["none"][1], rtol=1e-13)
    assert np.ptp(ends["none"][1]) < 0.5 * np.ptp(temperature)

    centres, radii, temperature = cluster
    flat = Params(materials.tabulated([200.0, 700.0], [1.0, 1.0]), materials.tabulated([200.0, 700.0], [1.0, 1.0]))
    runs = {}
    for name, params, kw in (("constant", PARAMS, {}),
                             ("flat", flat, {"conductivity_table": True, "specific_heat_table": True}),
                             ("varying", Params(kappa, PARAMS.specific_heat), {"conductivity_table": True})):
        sim, state, _ = start("sphere", centres, radii, temperature, params=params, dt=0.01, **kw)
        end = run(sim, state, 200, params)
        runs[name] = np.asarray(end.particles.temperature)
        capacity = np.asarray(end.particles.mass)
    np.testing.assert_allclose(runs["flat"], runs["constant"], rtol=1e-12)
    assert np.sum(capacity * runs["varying"]) == pytest.approx(np.sum(capacity * temperature), rel=1e-13)
    assert np.max(np.abs(runs["varying"] - runs["constant"])) > 1e-2


def dense_neck_solve(blocks, geometry, temperature):
    """``(necks, slot outflows [n, m])``: the neck temperatures balancing ``temperature``, by a dense solve
    assembled here from the packed blocks C_s, and each sphere's outflow through each table slot at them."""
    index, coupled = np.asarray(geometry.neck_index), np.asarray(geometry.coupled)
    p = geometry.neck_slots.shape[0]
    full = np.zeros(coupled.shape + coupled.shape[1:])
    for c, rows in zip(blocks, geometry.rows):
        w = c.shape[1]
        full[np.asarray(rows), :w, :w] = np.asarray(c)
    a_nn, a_ns = np.zeros((p, p)), np.zeros((p, len(temperature)))
    for s_, k in zip(*np.nonzero(coupled)):
        for m_ in np.flatnonzero(coupled[s_]):
            a_nn[index[s_, k], index[s_, m_]] += full[s_, k, m_]
        a_ns[index[s_, k], s_] -= full[s_, k][coupled[s_]].sum()
    necks = np.linalg.solve(a_nn, -a_ns @ temperature)
    return necks, np.einsum("nij,nj->ni", full, temperature[:, None] - necks[index])


@pytest.mark.slow
def test_neck_sweeps_reach_a_dense_solve(cluster):
    """The step's neck balance (conjugate gradients from the isolated necks plus a correction) against a dense
    solve assembled here from the blocks C_s: with as many sweeps as necks, the correction found from a cold start
    and from one 0.01 K off gives the dense necks within 1e-12 of the temperature span (measured 2e-14), and the
    contact flows are then C_s (T_s - x) on both sides of each neck; one sweep lowers the residual."""
    centres, radii, temperature = cluster
    sim, state, _ = start("sphere", centres, radii, temperature)
    network = sim.prepare_fn(state, PARAMS).neck_blocks
    g = network.geometry
    exact, q = dense_neck_solve(network.blocks, g, temperature)
    q = q.reshape(-1)[np.asarray(g.neck_slots)]
    isolated = np.asarray(coupling_term.isolated_necks(network, jnp.asarray(temperature)))
    p = len(exact)
    for guess in (np.zeros(p), exact - isolated + 0.01):
        flow, correction, residual = coupling_term.neck_sweeps(network, jnp.asarray(temperature), jnp.asarray(guess), p)
        assert np.max(np.abs(isolated + np.asarray(correction) - exact)) < 1e-12 * np.ptp(temperature)
        assert float(residual) < 1e-10
        np.testing.assert_allclose(np.asarray(flow), q[:, 0], rtol=0, atol=1e-10 * np.abs(q).max())
        np.testing.assert_allclose(np.asarray(flow), -q[:, 1], rtol=0, atol=1e-10 * np.abs(q).max())
    assert float(coupling_term.neck_sweeps(network, jnp.asarray(temperature), jnp.zeros(p), 1)[2]) < 1.0


@pytest.mark.slow
def test_one_sweep_a_step_errs_far_less_than_explicit_euler(cluster, monkeypatch):
    """The lag of one sweep a step (module docstring of sintercond.sim.terms.coupling) against the balance solved
    at every step (as many sweeps as necks), on the cluster from its random field: under 1 % of explicit Euler's
    own error (the converged run against ten times smaller steps) after 30 steps at 0.9 of the stable step
    (measured 0.08 %: 0.27 mK against 0.36 K), and at least five times smaller at a tenth of the step (32)."""
    centres, radii, temperature = cluster
    _, state, _ = start("sphere", centres, radii, temperature)
    exact_sweeps = int(state.contacts.pairs.shape[0])
    ends = {}
    for sweeps, divide in ((exact_sweeps, 1), (exact_sweeps, 10), (1, 1), (1, 10)):
        monkeypatch.setattr(coupling_term, "NECK_SWEEPS", sweeps)
        sim, state, limit = start("sphere", centres, radii, temperature)
        state = dataclasses.replace(state, dt=jnp.asarray(0.9 * limit / divide))
        ends[sweeps, divide] = np.asarray(run(sim, state, 30 * divide).particles.temperature)
    euler = np.max(np.abs(ends[exact_sweeps, 1] - ends[exact_sweeps, 10]))
    lag = np.max(np.abs(ends[1, 1] - ends[exact_sweeps, 1]))
    assert 0.0 < lag < 0.01 * euler
    assert np.max(np.abs(ends[1, 10] - ends[exact_sweeps, 10])) < 0.2 * lag


# --------------------------------------------------------------------------
# (e) gradients


@pytest.mark.slow
def test_gradients_equal_central_differences(cluster):
    """d T_far(after 40 steps) / d (conductivity, Rojek's slope, one neck radius) on the cluster with a held sphere:
    equal to central differences (the neck sweeps and the carried correction differentiated as they are)."""
    centres, radii, temperature = cluster
    fixed = np.arange(len(radii)) == 0
    temperature = np.where(fixed, 600.0, 300.0)
    far = int(np.argmax(np.linalg.norm(centres - centres[0], axis=1)))
    sim, state, limit = start("sphere", centres, radii, temperature, fixed=fixed, held=fixed.astype(int))
    state = dataclasses.replace(state, dt=jnp.asarray(0.5 * limit))
    neck0 = state.contacts.neck
    k = 3

    def observe(kappa, slope, neck_k):
        contacts = dataclasses.replace(state.contacts, neck=neck0.at[k].set(neck_k))
        params = Params(kappa[None], jnp.array([1.0]), law={"slope": slope})
        end = run(sim, dataclasses.replace(state, contacts=contacts), 40, params)
        return end.particles.temperature[far]

    x0 = (jnp.asarray(1.0), jnp.asarray(1.064), neck0[k])
    grads = jax.grad(observe, argnums=(0, 1, 2))(*x0)
    for arg in range(3):
        eps = 1e-6 * float(x0[arg])
        up = [v + eps * (i == arg) for i, v in enumerate(x0)]
        down = [v - eps * (i == arg) for i, v in enumerate(x0)]
        fd = (float(observe(*up)) - float(observe(*down))) / (2 * eps)
        assert abs(fd) > 1e-3
        assert float(grads[arg]) == pytest.approx(fd, rel=1e-6), arg


# --------------------------------------------------------------------------
# (f) float32


@pytest.mark.slow
def test_float32_agrees_with_float64(cluster):
    """With x64 off the cluster heated from a held sphere agrees with float64 to 1e-5 of the temperature span
    (measured 1.8e-7)."""
    centres, radii, _ = cluster
    fixed = np.arange(len(radii)) == 0
    temperature = np.where(fixed, 600.0, 300.0)
    sim, state, _ = start("sphere", centres, radii, temperature, fixed=fixed, held=fixed.astype(int))
    t64 = np.asarray(run(sim, state, 100).particles.temperature)
    with jax.enable_x64(False):
        sim32, state32, _ = start("sphere", centres.astype(np.float32), radii.astype(np.float32),
                                  temperature.astype(np.float32), fixed=fixed, held=fixed.astype(int),
                                  dt=float(state.dt), params=Params(jnp.array([1.0]), jnp.array([1.0])))
        end32 = run(sim32, state32, 100, Params(jnp.array([1.0]), jnp.array([1.0])))
        assert end32.particles.temperature.dtype == jnp.float32
        t32 = np.asarray(end32.particles.temperature, np.float64)
    assert np.max(np.abs(t32 - t64)) / 300.0 < 1e-5
    assert np.max(np.abs(t64 - 300.0)[~fixed]) > 10.0


# --------------------------------------------------------------------------
# (g) refusals


def test_bad_coupling_and_unsupported_combinations_are_refused():
    for bad in ("spheres", None, 1):
        with pytest.raises(ValueError, match=r"Conduction.coupling must be one of \['none', 'sphere'\]"):
            Conduction(conductance="lifted", coupling=bad)
    with pytest.raises(ValueError, match=r"coupling='sphere' needs Conduction.conductance='lifted'"):
        Physics.create(coupling="sphere")
    with pytest.raises(ValueError, match=r"coupling='sphere' needs Conduction.integrator='explicit'"):
        Physics.create(conductance="lifted", integrator="implicit", coupling="sphere")
    with pytest.raises(ValueError, match=r"coupling='sphere' needs Conduction.conducting_walls=0"):
        Physics.create(conductance="lifted", conducting_walls=1, coupling="sphere")
    with pytest.raises(ValueError, match=r"coupling='sphere'.*Physics.contacts='dynamic' is not supported"):
        Physics.create(conductance="lifted", contacts="dynamic", coupling="sphere")
    with pytest.raises(ValueError, match=r"coupling='sphere'.*Physics.contacts='dynamic' is not supported"):
        Physics.create(conductance="lifted", contacts="dynamic", coupling="sphere", mechanics=True)
    with pytest.raises(ValueError, match=r"coupling='sphere'.*Physics.sintering=.*many_body.*is not supported"):
        Physics.create(law="rojek", neck_model="volume_conserving", conductance="lifted", coupling="sphere",
                       sintering=neck_growth.Sintering(shrinkage="many_body"))


@pytest.mark.slow
def test_necks_too_close_are_refused_when_the_contacts_are_built():
    """FCC at a/r = 0.55: neighbouring necks 60 deg apart, their discs 66.7 deg wide."""
    centres, radii, _, _ = lattice_block("FCC", 0.55, cells=1)
    with pytest.raises(ValueError, match=r"on particle \d+ the necks of contacts .* 60 deg apart.*66\.7"):
        simulate.lifted_contacts(physics("sphere"), centres, radii)


def test_contacts_built_without_the_coupling_are_refused():
    centres, radii = chain([1.0, 1.0], 0.05)
    contacts = simulate.lifted_contacts(physics("none"), centres, radii)
    state = simulate.init_state(particle_state(centres, radii, 300.0, 1.0), contacts, 1.0)
    with pytest.raises(ValueError, match=r"coupling='sphere' needs SimState.contacts built for it"):
        rollout(simulate.simulator(physics("sphere")), state, PARAMS, 2)


# --------------------------------------------------------------------------
# (h) the scene key


SCENE = {
    "packing": {"kind": "simple_cubic", "counts": [4, 2, 2], "spacing": 1e-4, "radius": 0.52e-4},
    "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
    "conduction": {"law": "rojek", "coupling": "sphere"},
    "initial": {"temperature": 300.0},
    "walls": [{"axis": 0, "side": "min", "mode": "held", "temperature": 400.0}],
    "run": {"duration": 1e-3, "dt": "auto", "output_every": 5, "formats": ["vtp"]},
}


def test_scene_key_round_trip_and_refusals():
    checked = scene.validate_scene(copy.deepcopy(SCENE))
    assert checked["conduction"]["coupling"] == "sphere"
    assert typed_scene(checked).as_dict()["conduction"]["coupling"] == "sphere"
    spec = scene_physics(checked)
    assert (spec.conduction.coupling, spec.conduction.conductance) == ("sphere", "lifted")
    default = copy.deepcopy(SCENE)
    del default["conduction"]["coupling"]
    assert scene_physics(scene.validate_scene(default)).conduction.coupling == "none"
    bad = copy.deepcopy(SCENE)
    bad["conduction"]["coupling"] = "spheres"
    with pytest.raises(scene.SceneError, match=r"conduction.coupling"):
        scene.validate_scene(bad)
    for key, section in (("walls", [{"axis": 0, "side": "max", "mode": "conducting", "temperature": 350.0}]),
                         ("sintering", {"law": "grain_boundary", "shrinkage": "many_body"})):
        bad = copy.deepcopy(SCENE)
        bad[key] = section
        with pytest.raises(scene.SceneError, match=r"conduction.coupling = \"sphere\" is not supported"):
            scene.validate_scene(bad)


@pytest.mark.slow
def test_scene_builds_with_the_coupled_bound():
    """The scene builds the coupled step (held face mirrored across x), its thermal bound the coupled one, and a
    run.dt 1.1 times that bound is refused as the isolated bound's is."""
    model = build_model(scene.validate_scene(copy.deepcopy(SCENE)))
    assert model.physics.conduction.coupling == "sphere"
    assert model.state.contacts.sphere is not None
    bound = model.limits["thermal"]
    too_long = copy.deepcopy(SCENE)
    too_long["run"]["dt"] = 1.1 * bound
    with pytest.raises(scene.SceneError, match=r"run.dt: dt = .* exceeds the explicit stability limit"):
        build_model(scene.validate_scene(too_long))
    sintered = copy.deepcopy(SCENE)  # SC necks 90 deg apart: at the cap their discs overlap, now they do not
    sintered["sintering"] = {"law": "grain_boundary"}
    model = build_model(scene.validate_scene(sintered))
    geometry, radii = model.state.contacts.sphere, jnp.asarray(model.radii)
    assert not np.asarray(outside_domain(geometry, model.state.contacts.table_neck, radii)).any()
    at_cap = neck_growth.necks_at_cap(model.physics.sintering, model.params.sintering, model.state.contacts,
                                      model.radii)
    assert np.asarray(outside_domain(geometry, at_cap.table_neck, radii)).sum() > 0


# --------------------------------------------------------------------------
# (i) the stable step


def periodic_bcc(a_over_r=0.22, cells=2):
    """Equal spheres (r = 1) of a BCC lattice, ``cells`` cells a side, periodic: 8 necks a sphere."""
    length = (2.0 - overlap_for_neck(a_over_r)) * 2.0 / np.sqrt(3.0)
    g = np.stack(np.meshgrid(*[np.arange(cells)] * 3, indexing="ij"), -1).reshape(-1, 3).astype(float)
    centres = np.concatenate([g, g + 0.5]) * length
    sign = np.concatenate([np.ones(len(g)), -np.ones(len(g))])
    return centres, np.ones(len(centres)), np.full(3, cells * length), sign


@pytest.mark.slow
def test_stable_step_is_attained_on_the_bipartite_bcc_lattice():
    """Periodic BCC: the alternating mode (corners +1, centres -1, every neck at 0 by symmetry) has the largest
    rate, 1^T C_s 1 / C_s, so at the bound 2 C_s / (1^T C_s 1) it neither grows nor decays (stable) and at 1.1 times
    the bound it grows by 1.2 a step (unstable). The coupled bound differs from the isolated one."""
    centres, radii, box, sign = periodic_bcc()
    noise = 1e-3 * np.random.default_rng(1).standard_normal(len(radii))
    temperature = 300.0 + sign + noise
    _, _, isolated = start("none", centres, radii, temperature, periodic_box=box)
    sim, state, limit = start("sphere", centres, radii, temperature, periodic_box=box)
    assert abs(limit / isolated - 1.0) > 0.05
    amplitude = []
    for factor in (1.0, 1.1):
        end = run(sim, dataclasses.replace(state, dt=jnp.asarray(factor * limit)), 60)
        t = np.asarray(end.particles.temperature)
        amplitude.append(np.max(np.abs(t - t.mean())))
    assert amplitude[0] <= np.max(np.abs(temperature - temperature.mean())) * (1 + 1e-9)
    assert amplitude[0] > 0.9  # the alternating mode is not damped at the bound: the bound is attained
    assert amplitude[1] > 1e3


@pytest.mark.slow
def test_fcc_block_is_stable_at_the_bound():
    """FCC (not bipartite; 12 necks a sphere): at the bound a random field's capacity-weighted variance never grows
    (energy stability of explicit Euler), and stays bounded."""
    centres, radii, _, kw = lattice_block("FCC", 0.22)
    periods = np.array(kw["periodic_box"], float)
    periods[0] = 1e3
    temperature = 300.0 + 10.0 * np.random.default_rng(2).standard_normal(len(radii))
    sim, state, limit = start("sphere", centres, radii, temperature, periodic_box=periods)
    state = dataclasses.replace(state, dt=jnp.asarray(limit))
    _, saved = rollout(sim, state, PARAMS, 100, simulate.SaveAt(1, lambda s: s.particles.temperature))
    t = np.asarray(saved)
    variance = np.sum((t - temperature.mean()) ** 2, axis=1)
    assert np.all(np.diff(variance) <= 1e-12 * variance[0])


# --------------------------------------------------------------------------
# (j) no NaN


@pytest.mark.slow
def test_no_nan_at_fourteen_necks():
    """Rizza & Galati's BCC cell (14 necks on a corner sphere, unequal spheres) between held layers: finite
    temperatures and gradient."""
    centres, radii, _, kw = rizza_block(*RIZZA_NECKS[9.5])
    x = centres[:, 0]
    hot, cold = np.isclose(x, x.min()), np.isclose(x, x.max())
    periods = np.array(kw["periodic_box"], float)
    periods[0] = 1e3
    temperature = np.where(hot, 400.0, 300.0)
    sim, state, _ = start("sphere", centres, radii, temperature, fixed=hot | cold,
                          held=np.where(hot, 1, np.where(cold, 2, 0)), periodic_box=periods)

    def mean_free(kappa):
        end = run(sim, state, 20, Params(kappa[None], jnp.array([1.0])))
        return jnp.mean(jnp.where(jnp.asarray(hot | cold), 0.0, end.particles.temperature))

    value, grad = jax.value_and_grad(mean_free)(jnp.asarray(1.0))
    assert np.isfinite(float(value)) and np.isfinite(float(grad)) and float(grad) > 0


@pytest.mark.slow
def test_no_nan_at_the_neck_cap():
    """A chain at the neck model's cap (a = r): finite temperatures and gradient, still the isolated chain."""
    centres, radii = chain([1.0] * 5, float(max_overlap(1.0, 1.0)))
    temperature = np.array([300.0, 500.0, 320.0, 310.0, 600.0])
    ends = []
    for coupling in ("none", "sphere"):
        sim, state, _ = start(coupling, centres, radii, temperature)
        ends.append(jax.value_and_grad(lambda k: run(sim, state, 30, Params(k[None], jnp.array([1.0])))
                                       .particles.temperature[0])(jnp.asarray(1.0)))
    assert np.isfinite(float(ends[1][1]))
    assert float(ends[1][0]) == pytest.approx(float(ends[0][0]), rel=1e-13)
    assert float(ends[1][1]) == pytest.approx(float(ends[0][1]), rel=1e-9)


# --------------------------------------------------------------------------
# sintering: necks that grow (independent contacts)

KINETICS = {"A": 1e-16, "activation_energy": 100.0}  # necks of a few um in a second at 1000-1200 K (Ti6Al4V)


def sintering_chain(coupling, rebuild_at_cap=True):
    """Four unequal spheres in a row touching at points (no neck yet), 1000-1200 K: ``(sim, state, params)``."""
    radii = np.array([40e-6, 30e-6, 35e-6, 38e-6])
    x = np.zeros((4, 3))
    x[1:, 0] = np.cumsum(radii[:-1] + radii[1:])
    spec = Physics.create(law="rojek", neck_model="volume_conserving", conductance="lifted", coupling=coupling,
                          sintering=neck_growth.Sintering("grain_boundary"))
    params = Params(conductivity=[7.0], specific_heat=[560.0], sintering=dict(KINETICS))
    particles = particle_state(x, radii, np.array([1200.0, 1000.0, 1150.0, 1050.0]), 4430.0)
    contacts = simulate.lifted_contacts(spec, x, radii)
    if coupling == "sphere" and rebuild_at_cap:
        cap = neck_growth.necks_at_cap(spec.sintering, params.sintering, contacts, radii)
        contacts = simulate.coupled_contacts(contacts, x, radii, np.asarray(cap.neck), beyond_domain="isolated")
    state = simulate.init_state(particles, contacts, 2e-4,  # half the limit on the necks at the cap
                                sintering=neck_growth.neck_state(contacts, particles.temperature))
    return simulate.simulator(spec), state, params


@pytest.mark.slow
def test_growing_necks_of_a_chain_are_the_isolated_ones():
    """Necks grown from point contacts (coupled once they conduct, the blocks recomputed every step): the coupled
    chain's temperatures and necks are the isolated chain's to round-off."""
    ends = {}
    for coupling in ("none", "sphere"):
        sim, state, params = sintering_chain(coupling)
        ends[coupling] = run(sim, state, 300, params)
    assert not bool(ends["none"].sintering.unstable)
    np.testing.assert_allclose(np.asarray(ends["sphere"].contacts.neck), np.asarray(ends["none"].contacts.neck),
                               rtol=1e-12)
    assert float(np.min(ends["none"].contacts.neck)) > 1e-7  # they grew
    np.testing.assert_allclose(np.asarray(ends["sphere"].particles.temperature),
                               np.asarray(ends["none"].particles.temperature), rtol=1e-13)


@pytest.mark.slow
def test_growing_necks_need_the_geometry_at_the_cap():
    """Built on the necks now (point contacts: none coupled) the run is refused before it compiles. An FCC block
    whose necks at the kinetic law's cap overlap is refused by default and accepted with beyond_domain="isolated"
    (what the scene build passes for sintering): the domain is then taken at each step's necks (inside it now,
    outside it at the cap)."""
    sim, state, params = sintering_chain("sphere", rebuild_at_cap=False)
    with pytest.raises(ValueError, match=r"contact \(0, 1\) is not in the coupled geometry.*necks_at_cap"):
        rollout(sim, state, params, 2)
    centres, radii, _, _ = lattice_block("FCC", 0.22, cells=1)
    spec = Physics.create(law="rojek", neck_model="volume_conserving", conductance="lifted", coupling="sphere",
                          sintering=neck_growth.Sintering("grain_boundary"))
    contacts = simulate.lifted_contacts(spec, centres, radii)
    cap = neck_growth.necks_at_cap(spec.sintering, dict(KINETICS), contacts, radii)
    with pytest.raises(ValueError, match=r"closer than their discs' angular half-widths"):
        simulate.coupled_contacts(contacts, centres, radii, np.asarray(cap.neck))
    contacts = simulate.coupled_contacts(contacts, centres, radii, np.asarray(cap.neck), beyond_domain="isolated")
    outside = outside_domain(contacts.sphere, contacts.table_neck, jnp.asarray(radii))
    assert not np.asarray(outside).any()
    outside = outside_domain(contacts.sphere, cap.table_neck, jnp.asarray(radii))
    assert np.asarray(outside).all()


@pytest.mark.slow
def test_necks_grown_beyond_the_domain_step_as_the_isolated_network():
    """An FCC block whose necks have grown to a/r = 0.55 (neighbouring necks 60 deg apart, their discs 66.7 deg
    wide: every sphere outside the domain) steps as the isolated network to round-off (each sphere keeps its pair
    laws' halves, so the neck balance is the isolated one), and heat is conserved."""
    centres, radii, _, kw = lattice_block("FCC", 0.22, cells=1)
    periods = np.array(kw["periodic_box"], float)
    periods[0] = 1e3
    temperature = 300.0 + 100.0 * np.random.default_rng(3).random(len(radii))
    ends = {}
    for coupling in ("none", "sphere"):
        sim, state, _ = start(coupling, centres, radii, temperature, periodic_box=periods)
        grown = dataclasses.replace(state.contacts, neck=jnp.full(state.contacts.neck.shape, 0.55))
        state = dataclasses.replace(state, contacts=grown, dt=jnp.asarray(1e-3))
        if coupling == "sphere":
            assert np.asarray(outside_domain(grown.sphere, grown.table_neck,
                                                           jnp.asarray(radii))).all()
        ends[coupling] = np.asarray(run(sim, state, 50).particles.temperature)
    np.testing.assert_allclose(ends["sphere"], ends["none"], rtol=1e-13)
    assert np.sum(ends["sphere"]) == pytest.approx(np.sum(temperature), rel=1e-13)  # unit capacities
