"""Run a scene: build the packing and network, step in chunks, write outputs and checkpoints.

Outputs in the run directory: ``scene.json`` (the validated scene),
``packing.npz`` (centres, radii), ``vtp/step_XXXXXXXX.vtp`` (VTK PolyData,
ParaView) and/or ``dump.lammpstrj`` (LAMMPS dump, OVITO) every
``output_every`` steps, ``checkpoint.npz`` every ``checkpoint_every`` steps
(written to a temporary file and renamed, so a killed run leaves the last
complete checkpoint). :func:`resume` continues from it and gives results
identical to an uninterrupted run: the same compiled chunk runs on the same
inputs.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from sintercond import heat_sources, network, packing, plots, simulate, thermal, walls
from sintercond.io import append_lammps, load_checkpoint, save_checkpoint, truncate_lammps, write_vtp
from sintercond.scene import SceneError, validate_scene
from sintercond.state import particle_state


@dataclasses.dataclass(frozen=True)
class Model:
    """Everything a run needs, built from a scene: the simulator, its parameters and initial state."""

    sim: simulate.Simulator
    params: simulate.Params
    state: simulate.SimState
    n_steps: int
    contacts: int
    stable_step: float = float("inf")
    bed: dict = dataclasses.field(default_factory=dict)

    @property
    def physics(self) -> simulate.Physics:
        return self.sim.physics

    @property
    def dt(self) -> float:
        return float(self.state.dt)

    @property
    def centres(self) -> np.ndarray:
        return np.asarray(self.state.particles.positions)

    @property
    def radii(self) -> np.ndarray:
        return np.asarray(self.state.particles.radii)


def build_packing(scene):
    bed = packing.from_scene(scene["packing"])
    return bed.centres, bed.radii


def _nusselt(convection):
    if "reynolds" in convection:
        return float(heat_sources.whitaker_nusselt(convection["reynolds"], convection["prandtl"]))
    return convection.get("nusselt", 2.0)


def scene_physics(scene, walls=0) -> simulate.Physics:
    """The static physics spec of a validated scene."""
    c = scene["conduction"]
    beam = scene.get("beam")
    return simulate.Physics(
        law=c["law"], neck_model=c.get("neck_model"),
        # a contact resistance makes the law nonlinear in the conductivity: lift it from the necks
        conductance="lifted" if c.get("params", {}).get("contact_resistance", 0.0) else "table",
        held=any(w["mode"] == "held" for w in _walls(scene)), conducting_walls=walls,
        beam=None if beam is None else beam["kind"], convection="convection" in scene,
        radiation="radiation" in scene)


def scene_params(scene) -> simulate.Params:
    """The differentiable parameters of a validated scene."""
    m, beam, conv, rad = scene["material"], scene.get("beam"), scene.get("convection"), scene.get("radiation")
    f = jnp.asarray
    return simulate.Params(
        conductivity=f([m["conductivity"]]), specific_heat=f([m["specific_heat"]]),
        law={k: f(v) for k, v in scene["conduction"].get("params", {}).items()},
        beam=None if beam is None else simulate.BeamParams(
            intensity=f(beam["intensity"]), reach=f(beam["attenuation"] if beam["kind"] == "laser" else beam["max_depth"]),
            spot_radius=f(beam["spot_radius"]), absorptance=f(beam["absorptance"]), speed=f(beam["speed"]),
            path=f(beam["path"], dtype=float)),
        convection=None if conv is None else simulate.ConvectionParams(
            f(conv["environment_temperature"]), f(conv["environment_conductivity"]), f(_nusselt(conv))),
        radiation=None if rad is None else simulate.RadiationParams(f(rad["environment_temperature"]),
                                                                    f(rad["emissivity"])))


def build_model(scene, centres=None, radii=None, log=None) -> Model:
    """Packing, network, held particles, sources, time step and simulator of a validated scene.

    The time step: ``run.dt`` or, for ``"auto"``, 0.9 of the stable step
    ``min_i C_i / (sum_j K_ij + sum_w K_iw + G_i)`` where ``G_i`` linearises
    convection and radiation (:func:`sintercond.thermal.source_conductance`);
    then shortened to ``duration / n_steps`` so that the run ends exactly at
    ``run.duration``. ``log(message)`` reports each phase.
    """
    log = log or (lambda message: None)
    bed = {}
    if centres is None:
        log("packing: building the scene's packing")
        packed = packing.from_scene(scene["packing"])
        centres, radii = packed.centres, packed.radii
        bed = {k: v for k, v in packed.summary().items() if k != "particles"}
    m, c = scene["material"], scene["conduction"]
    physics = scene_physics(scene)
    log(f"network: contacts and conductances of {len(radii)} particles")
    try:
        table = network.contact_table(centres, radii, 1.0 if physics.conductance == "table" else m["conductivity"],
                                      c["law"], c.get("params"), c.get("neck_model"))
    except ValueError as err:
        raise SceneError(f"the packing does not fit the conduction model: {err}") from None
    fixed_mask, fixed_temperature, conducting = _apply_walls(scene, centres, radii)
    physics = dataclasses.replace(physics, conducting_walls=len(conducting) if physics.conductance == "lifted"
                                  else int(bool(conducting)))
    particles = particle_state(centres, radii, scene["initial"]["temperature"], m["density"], m["specific_heat"],
                               fixed=fixed_mask, fixed_temperature=fixed_temperature)
    if physics.conductance == "table":
        k_wall, t_wall = _merged_wall_conductance(scene, centres, radii, conducting)
        contacts = simulate.table_contacts(table, k_wall, t_wall)
    else:
        contacts = simulate.lifted_contacts(physics, centres, radii,
                                            [(penetration, wall.temperature) for _, wall, penetration in conducting])
    params = scene_params(scene)
    sim = simulate.simulator(physics)
    state = simulate.init_state(particles, contacts, 1.0)
    run = scene["run"]
    sources = thermal.source_conductance(physics, particles.radii, params, _highest_temperature(scene))
    limit = float(simulate.stable_time_step(sim, state, params, sources))
    if run["dt"] == "auto":
        dt = 0.9 * limit if np.isfinite(limit) else run["duration"]
    else:
        dt = run["dt"]
        if dt > limit:
            raise SceneError(f"run.dt: dt = {dt:.6g} s exceeds the explicit stability limit "
                             f"min(C_i / (sum_j K_ij + G_i)) = {limit:.6g} s (G_i: linearised convection and "
                             f"radiation); use dt <= {limit:.6g} s or the implicit integrator")
    n_steps = max(1, int(np.ceil(run["duration"] / dt * (1 - 1e-12))))
    dt = run["duration"] / n_steps  # equal steps that end at the duration, none above the stable one
    return Model(sim, params, simulate.init_state(particles, contacts, dt), n_steps, len(table.pairs()), limit, bed)


def _highest_temperature(scene) -> float:
    """The highest temperature a scene names (initial, walls, environment): where radiation is stiffest."""
    temperatures = [scene["initial"]["temperature"]] + [w["temperature"] for w in _walls(scene) if "temperature" in w]
    temperatures += [scene[k]["environment_temperature"] for k in ("convection", "radiation") if k in scene]
    return float(max(temperatures))


def _walls(scene):
    walls = list(scene.get("walls", []))
    if "floor_temperature" in scene.get("boundary", {}):
        walls.append({"axis": 2, "side": "min", "mode": "held", "temperature": scene["boundary"]["floor_temperature"]})
    return walls


def scene_walls(scene, centres, radii) -> list[walls.PlaneWall]:
    """The scene's walls as :class:`~sintercond.walls.PlaneWall` (insulated ones included).

    A wall plane lies at the packing's extreme along its axis, moved
    ``penetration`` mean radii into it; its normal points into the packing.
    """
    planes = []
    for wall in _walls(scene):
        axis, depth = wall["axis"], wall.get("penetration", 0.02) * float(np.mean(radii))
        normal = np.zeros(3)
        if wall["side"] == "min":
            normal[axis] = 1.0
            position = float(np.min(centres[:, axis] - radii)) + depth
        else:
            normal[axis] = -1.0
            position = float(np.max(centres[:, axis] + radii)) - depth
        point = np.zeros(3)
        point[axis] = position
        planes.append(walls.PlaneWall(tuple(point), tuple(normal), wall["mode"], wall.get("temperature")))
    return planes


def _apply_walls(scene, centres, radii):
    """Held walls become fixed particles; returns them and the conducting walls as ``(index, wall, penetration)``."""
    held = np.zeros(len(radii), bool)
    held_t = np.zeros(len(radii))
    conducting = []
    for index, wall in enumerate(scene_walls(scene, centres, radii)):
        penetration = np.asarray(wall.penetration(centres, radii))
        if wall.mode == "held":
            touching = penetration >= 0
            held |= touching
            held_t = np.where(touching, wall.temperature, held_t)
        elif wall.mode == "conducting":
            conducting.append((index, wall, penetration))
    return held, held_t, conducting


def _merged_wall_conductance(scene, centres, radii, conducting):
    """Per-particle wall conductance at unit conductivity and the conductance-weighted wall temperature."""
    if not conducting:
        return None, None
    c = scene["conduction"]
    k_wall = np.zeros(len(radii))
    t_wall = np.zeros(len(radii))
    for index, wall, penetration in conducting:
        try:
            k_w = np.asarray(walls.wall_conductance(c["law"], radii, penetration, 1.0, params=c.get("params"),
                                                    neck_model=c.get("neck_model")))
        except ValueError as err:
            raise SceneError(f"walls[{index}]: {err}") from None
        if not np.all(np.isfinite(k_w)):
            raise SceneError(f"walls[{index}].penetration: the wall cuts a particle deeper than the neck model "
                             f"allows for a plane (r/3 for the volume-conserving neck)")
        t_wall = np.where(k_w > 0, (k_wall * t_wall + k_w * wall.temperature) / np.maximum(k_wall + k_w, 1e-300),
                          t_wall)
        k_wall = k_wall + k_w
    return k_wall, t_wall


def advance(sim, state, params, n_steps, chunk, on_chunk=None, reallocate=None, progress=None, check=None):
    """The one host loop: advance ``n_steps`` in compiled chunks of ``chunk`` steps (the last one may be shorter).

    After every chunk the host checks the state: a neighbour list that
    overflowed (``state.overflow``) is reallocated by ``reallocate(start,
    end) -> start`` and the chunk redone from its saved start, so no contact
    is lost; ``check(state)`` raises on an unphysical state (default:
    non-finite temperatures). Then ``on_chunk(state)`` (outputs,
    checkpoints) runs; returning True stops early. The same compiled chunk
    runs on the same inputs whatever the history, so a run resumed from a
    checkpoint is bitwise identical to an uninterrupted one.

    Returns:
      ``(state, report)`` with the number of chunks and reallocations.
    """
    compiled = {}
    reallocations = chunks = 0
    target = int(state.step) + n_steps
    check = check or _finite_temperatures
    while int(state.step) < target:
        length = min(chunk, target - int(state.step))
        if length not in compiled:
            compiled[length] = _compiled_chunk(sim, length)
        new = compiled[length](state, params)
        if bool(new.overflow):
            if reallocate is None:
                raise RuntimeError("the neighbour list overflowed and no reallocation was given")
            state = reallocate(state, new)
            reallocations += 1
            if reallocations > 100:
                raise RuntimeError("the neighbour list keeps overflowing; raise its capacity")
            continue
        check(new)
        state = new
        chunks += 1
        if progress is not None:
            progress(length)
        if on_chunk is not None and on_chunk(state):
            break
    return state, {"chunks": chunks, "reallocations": reallocations}


def _finite_temperatures(state):
    if not bool(jnp.all(jnp.isfinite(state.particles.temperature))):
        raise FloatingPointError(f"non-finite temperature at step {int(state.step)}; reduce the time step")


@functools.lru_cache(maxsize=16)
def _compiled_chunk(sim, chunk):
    """The jitted chunk of ``sim`` (hashable), kept across :func:`advance` calls: a second run does not recompile."""
    def run_chunk(state, params):
        return simulate.rollout(sim, state, params, chunk, simulate.SaveAt(chunk, _nothing), checkpoint=False)[0]

    return jax.jit(run_chunk)


def _nothing(state):
    return ()


MAX_TEMPERATURE = 1e5
"""K; a run whose temperatures leave (0, MAX_TEMPERATURE] stops: no material of this field gets there."""


def physical_range_check(scene):
    """``check(state)`` for :func:`advance`: temperatures finite, > 0 K and <= :data:`MAX_TEMPERATURE`.

    The error names the step and the scene keys that can drive a run there.
    """
    causes = [key for key, section in (("beam.intensity", "beam"), ("convection.nusselt", "convection"),
                                       ("radiation.emissivity", "radiation")) if section in scene] + ["run.dt"]

    def check(state):
        t = state.particles.temperature
        bad = ~jnp.isfinite(t) | (t <= 0) | (t > MAX_TEMPERATURE)
        if bool(jnp.any(bad)):
            worst = float(jnp.max(jnp.where(jnp.isfinite(t), jnp.abs(t), jnp.inf)))
            raise FloatingPointError(
                f"temperature left the physical range (0, {MAX_TEMPERATURE:g}] K at step {int(state.step)} "
                f"(|T| up to {worst:.3g} K); likely cause: {', '.join(causes)} too large for the time step")
    return check


HISTORY_COLUMNS = ("step", "time_s", "T_mean_K", "T_min_K", "T_max_K")
"""Columns of ``history.csv``, one row per output step (the LAMMPS "thermo" analogue)."""


def _history_row(state) -> str:
    t = np.asarray(state.particles.temperature)
    values = (float(state.time), float(t.mean()), float(t.min()), float(t.max()))  # Python floats: plain repr
    return f"{int(state.step)}," + ",".join(repr(v) for v in values) + "\n"


def read_history(out) -> dict:
    """``history.csv`` of a run as a dict of arrays; ``time`` (s) and the temperatures (K), for the history plot."""
    data = np.genfromtxt(Path(out) / "history.csv", delimiter=",", names=True, ndmin=1)
    return {"time": data["time_s"], **{name: data[name] for name in HISTORY_COLUMNS[2:]}}


def _log(message):
    print(f"sintercond: {message}", file=sys.stderr, flush=True)


def _clear_outputs(out):
    """A new run into ``out`` first removes the outputs an earlier run left there."""
    for f in (out / "vtp").glob("step_*.vtp") if (out / "vtp").exists() else []:
        f.unlink()
    for name in ("dump.lammpstrj", "checkpoint.npz", "history.csv", "summary.json"):
        if (out / name).exists():
            (out / name).unlink()


def run_scene(scene, out_dir, progress=True, stop_after_chunks=None, _start=None):
    """Run a validated scene into ``out_dir``; returns ``(final temperatures, summary dict)``.

    Prints each phase (packing, network, compile) and, before stepping, the
    step count and the stable step. ``stop_after_chunks`` stops early as a
    kill would, right after that many chunks (for tests of resume).
    """
    out = Path(out_dir)
    if _start is None:
        out.mkdir(parents=True, exist_ok=True)
        _clear_outputs(out)
        (out / "scene.json").write_text(json.dumps(scene, indent=1))
        model = build_model(scene, log=_log)
        np.savez(out / "packing.npz", centres=model.centres, radii=model.radii)
        (out / "bed.json").write_text(json.dumps(model.bed))
        (out / "history.csv").write_text(",".join(HISTORY_COLUMNS) + "\n" + _history_row(model.state))
        _write_outputs(scene, out, model, model.state)
        state = model.state
    else:
        model, state = _start
    run = scene["run"]
    chunk = run["output_every"]
    chunks_done = 0
    _log(f"{len(model.radii)} particles, {model.contacts} contacts; stable step {model.stable_step:.4g} s, "
         f"dt {model.dt:.4g} s, {model.n_steps} steps to {model.n_steps * model.dt:.6g} s; compiling the step")

    def on_chunk(s):
        nonlocal chunks_done
        step = int(s.step)
        _write_outputs(scene, out, model, s)
        with open(out / "history.csv", "a") as f:
            f.write(_history_row(s))
        if step % run["checkpoint_every"] == 0 or step >= model.n_steps:
            save_checkpoint(out, s)
        chunks_done += 1
        return stop_after_chunks is not None and chunks_done >= stop_after_chunks and step < model.n_steps

    wall = time.perf_counter()
    bar = tqdm(total=model.n_steps, initial=int(state.step), unit="step", disable=not progress, desc="sintercond run")
    try:
        state, _ = advance(model.sim, state, model.params, model.n_steps - int(state.step), chunk, on_chunk,
                           progress=bar.update, check=physical_range_check(scene))
    finally:
        bar.close()
    temperature = state.particles.temperature
    if int(state.step) < model.n_steps:
        return temperature, None
    elapsed = time.perf_counter() - wall
    summary = {
        "particles": len(model.radii), "contacts": model.contacts, **model.bed, "steps": int(state.step),
        "dt_s": model.dt, "stable_step_s": model.stable_step, "simulated_s": int(state.step) * model.dt,
        "wall_s": elapsed, "T_min_K": float(temperature.min()), "T_mean_K": float(temperature.mean()),
        "T_max_K": float(temperature.max()),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    plots.write_run_pictures(out, model.centres, model.radii, temperature, summary, history=read_history(out))
    return temperature, summary


def _write_outputs(scene, out, model, state):
    formats = scene["run"]["formats"]
    step = int(state.step)
    t = float(state.time)
    temperature = state.particles.temperature
    if "vtp" in formats:
        (out / "vtp").mkdir(exist_ok=True)
        write_vtp(out / "vtp" / f"step_{step:08d}.vtp", model.centres, model.radii, temperature, step, t)
    if "lammps" in formats:
        append_lammps(out / "dump.lammpstrj", model.centres, model.radii, temperature, step)


def resume(out_dir, progress=True, stop_after_chunks=None):
    """Continue the run in ``out_dir`` from its last checkpoint (the whole state).

    A finished run (its ``summary.json`` at the checkpoint's step) is not
    rebuilt: its final temperatures and summary are returned as they are.
    """
    out = Path(out_dir)
    if not (out / "checkpoint.npz").exists():
        raise SceneError(f"{str(out)!r} has no checkpoint.npz to resume from")
    saved = np.load(out / "checkpoint.npz")
    step = int(saved["step"])
    if (out / "summary.json").exists():
        summary = json.loads((out / "summary.json").read_text())
        if summary.get("steps") == step:
            _log(f"the run in {out} is finished (step {step}); nothing to resume")
            return jnp.asarray(saved["temperature"]), summary
    scene = validate_scene(json.loads((out / "scene.json").read_text()))
    packed = np.load(out / "packing.npz")
    model = build_model(scene, packed["centres"], packed["radii"], log=_log)
    if (out / "bed.json").exists():
        model = dataclasses.replace(model, bed=json.loads((out / "bed.json").read_text()))
    state = load_checkpoint(out / "checkpoint.npz", model.state)
    # outputs written after the checkpoint by the interrupted run are redone
    for f in (out / "vtp").glob("step_*.vtp") if (out / "vtp").exists() else []:
        if int(f.stem.split("_")[1]) > step:
            f.unlink()
    if (out / "dump.lammpstrj").exists():
        truncate_lammps(out / "dump.lammpstrj", step)
    if (out / "history.csv").exists():
        lines = (out / "history.csv").read_text().splitlines(keepends=True)
        (out / "history.csv").write_text("".join([lines[0]] + [r for r in lines[1:] if int(r.split(",")[0]) <= step]))
    return run_scene(scene, out, progress, stop_after_chunks, _start=(model, state))


def summary_table(summary) -> str:
    width = max(len(k) for k in summary)
    return "\n".join(f"{k:<{width}}  {v:.6g}" if isinstance(v, float) else f"{k:<{width}}  {v}" for k, v in summary.items())
