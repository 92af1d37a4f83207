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
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from sintercond import heat_sources, network, packing, plots, simulate
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


def build_model(scene, centres=None, radii=None) -> Model:
    """Packing, network, held particles, sources, time step and simulator of a validated scene."""
    if centres is None:
        centres, radii = build_packing(scene)
    m, c = scene["material"], scene["conduction"]
    physics = scene_physics(scene)
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
                                            [(_wall_penetration(centres, radii, axis, position), wall["temperature"])
                                             for _, axis, position, wall in conducting])
    params = scene_params(scene)
    sim = simulate.simulator(physics)
    state = simulate.init_state(particles, contacts, 1.0)
    run = scene["run"]
    limit = float(simulate.stable_time_step(sim, state, params))
    if run["dt"] == "auto":
        dt = 0.9 * limit if np.isfinite(limit) else run["duration"] / 1000
    else:
        dt = run["dt"]
        if dt > limit:
            raise SceneError(f"run.dt: dt = {dt:.6g} s exceeds the explicit stability limit min(C_i / sum_j K_ij) = "
                             f"{limit:.6g} s; use dt <= {limit:.6g} s or the implicit integrator")
    n_steps = max(1, int(np.ceil(run["duration"] / dt)))
    chunk = run["output_every"]
    n_steps = int(np.ceil(n_steps / chunk) * chunk)
    return Model(sim, params, simulate.init_state(particles, contacts, dt), n_steps, len(table.pairs()))


def _walls(scene):
    walls = list(scene.get("walls", []))
    if "floor_temperature" in scene.get("boundary", {}):
        walls.append({"axis": 2, "side": "min", "mode": "held", "temperature": scene["boundary"]["floor_temperature"]})
    return walls


def _apply_walls(scene, centres, radii):
    """Held walls become fixed particles; returns them and the conducting walls as ``(index, axis, position, wall)``.

    A wall plane lies at the packing's extreme along its axis, moved
    ``penetration`` mean radii into it; the particles it cuts touch it.
    """
    held = np.zeros(len(radii), bool)
    held_t = np.zeros(len(radii))
    conducting = []
    for index, wall in enumerate(_walls(scene)):
        axis, mode = wall["axis"], wall["mode"]
        if mode == "insulated":
            continue
        depth = wall.get("penetration", 0.02) * float(np.mean(radii))
        if wall["side"] == "min":
            position = float(np.min(centres[:, axis] - radii)) + depth
            touching = centres[:, axis] - radii <= position
        else:
            position = float(np.max(centres[:, axis] + radii)) - depth
            touching = centres[:, axis] + radii >= position
        if mode == "held":
            held |= touching
            held_t = np.where(touching, wall["temperature"], held_t)
        else:
            conducting.append((index, axis, position, wall))
    return held, held_t, conducting


def _wall_penetration(centres, radii, axis, position):
    """How far each sphere cuts the plane ``p[axis] = position`` (m; <= 0: not touching)."""
    return radii - np.abs(centres[:, axis] - position)


def _merged_wall_conductance(scene, centres, radii, conducting):
    """Per-particle wall conductance at unit conductivity and the conductance-weighted wall temperature."""
    if not conducting:
        return None, None
    c = scene["conduction"]
    k_wall = np.zeros(len(radii))
    t_wall = np.zeros(len(radii))
    for index, axis, position, wall in conducting:
        try:
            k_w = network.wall_conductance(centres, radii, 1.0, axis, position, c["law"], c.get("params"),
                                           c.get("neck_model"))
        except ValueError as err:
            raise SceneError(f"walls[{index}]: {err}") from None
        t_wall = np.where(k_w > 0, (k_wall * t_wall + k_w * wall["temperature"]) / np.maximum(k_wall + k_w, 1e-300),
                          t_wall)
        k_wall = k_wall + k_w
    return k_wall, t_wall


def advance(sim, state, params, n_steps, chunk, on_chunk=None, reallocate=None, progress=None):
    """The one host loop: advance ``n_steps`` in compiled chunks of ``chunk`` steps.

    After every chunk the host checks the state: a neighbour list that
    overflowed (``state.overflow``) is reallocated by ``reallocate(start,
    end) -> start`` and the chunk redone from its saved start, so no contact
    is lost; non-finite temperatures stop the run with the step. Then
    ``on_chunk(state)`` (outputs, checkpoints) runs; returning True stops
    early. The same compiled chunk runs on the same inputs whatever the
    history, so a run resumed from a checkpoint is bitwise identical to an
    uninterrupted one.

    Returns:
      ``(state, report)`` with the number of chunks and reallocations.
    """
    run_chunk = _compiled_chunk(sim, chunk)
    reallocations = chunks = 0
    target = int(state.step) + n_steps
    while int(state.step) < target:
        new = run_chunk(state, params)
        if bool(new.overflow):
            if reallocate is None:
                raise RuntimeError("the neighbour list overflowed and no reallocation was given")
            state = reallocate(state, new)
            reallocations += 1
            if reallocations > 100:
                raise RuntimeError("the neighbour list keeps overflowing; raise its capacity")
            continue
        if not bool(jnp.all(jnp.isfinite(new.particles.temperature))):
            raise FloatingPointError(f"non-finite temperature at step {int(new.step)}; reduce run.dt")
        state = new
        chunks += 1
        if progress is not None:
            progress(chunk)
        if on_chunk is not None and on_chunk(state):
            break
    return state, {"chunks": chunks, "reallocations": reallocations}


def _compiled_chunk(sim, chunk):
    def run_chunk(state, params):
        return simulate.rollout(sim, state, params, chunk, simulate.SaveAt(chunk, _nothing), checkpoint=False)[0]

    return jax.jit(run_chunk)


def _nothing(state):
    return ()


def run_scene(scene, out_dir, progress=True, stop_after_chunks=None, _start=None):
    """Run a validated scene into ``out_dir``; returns ``(final temperatures, summary dict)``.

    ``stop_after_chunks`` stops early as a kill would, right after that many
    chunks (for tests of resume).
    """
    out = Path(out_dir)
    if _start is None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "scene.json").write_text(json.dumps(scene, indent=1))
        model = build_model(scene)
        np.savez(out / "packing.npz", centres=model.centres, radii=model.radii)
        if (out / "dump.lammpstrj").exists():
            (out / "dump.lammpstrj").unlink()
        _write_outputs(scene, out, model, model.state)
        state = model.state
    else:
        model, state = _start
    run = scene["run"]
    chunk = run["output_every"]
    chunks_done = 0

    def on_chunk(s):
        nonlocal chunks_done
        step = int(s.step)
        _write_outputs(scene, out, model, s)
        if step % run["checkpoint_every"] == 0 or step >= model.n_steps:
            save_checkpoint(out, s)
        chunks_done += 1
        return stop_after_chunks is not None and chunks_done >= stop_after_chunks and step < model.n_steps

    wall = time.perf_counter()
    bar = tqdm(total=model.n_steps, initial=int(state.step), unit="step", disable=not progress, desc="sintercond run")
    try:
        state, _ = advance(model.sim, state, model.params, model.n_steps - int(state.step), chunk, on_chunk,
                           progress=bar.update)
    finally:
        bar.close()
    temperature = state.particles.temperature
    if int(state.step) < model.n_steps:
        return temperature, None
    elapsed = time.perf_counter() - wall
    summary = {
        "particles": len(model.radii), "contacts": model.contacts, "steps": int(state.step),
        "dt_s": model.dt, "simulated_s": int(state.step) * model.dt, "wall_s": elapsed,
        "T_min_K": float(temperature.min()), "T_mean_K": float(temperature.mean()), "T_max_K": float(temperature.max()),
    }
    plots.write_run_pictures(out, model.centres, model.radii, temperature, summary)
    return temperature, summary


def _write_outputs(scene, out, model, state):
    formats = scene["run"]["formats"]
    step = int(state.step)
    t = step * model.dt
    temperature = state.particles.temperature
    if "vtp" in formats:
        (out / "vtp").mkdir(exist_ok=True)
        write_vtp(out / "vtp" / f"step_{step:08d}.vtp", model.centres, model.radii, temperature, step, t)
    if "lammps" in formats:
        append_lammps(out / "dump.lammpstrj", model.centres, model.radii, temperature, step)


def resume(out_dir, progress=True, stop_after_chunks=None):
    """Continue the run in ``out_dir`` from its last checkpoint (the whole state)."""
    out = Path(out_dir)
    if not (out / "checkpoint.npz").exists():
        raise SceneError(f"{str(out)!r} has no checkpoint.npz to resume from")
    scene = validate_scene(json.loads((out / "scene.json").read_text()))
    packed = np.load(out / "packing.npz")
    model = build_model(scene, packed["centres"], packed["radii"])
    state = load_checkpoint(out / "checkpoint.npz", model.state)
    step = int(state.step)
    # outputs written after the checkpoint by the interrupted run are redone
    for f in (out / "vtp").glob("step_*.vtp") if (out / "vtp").exists() else []:
        if int(f.stem.split("_")[1]) > step:
            f.unlink()
    if (out / "dump.lammpstrj").exists():
        truncate_lammps(out / "dump.lammpstrj", step)
    return run_scene(scene, out, progress, stop_after_chunks, _start=(model, state))


def summary_table(summary) -> str:
    width = max(len(k) for k in summary)
    return "\n".join(f"{k:<{width}}  {v:.6g}" if isinstance(v, float) else f"{k:<{width}}  {v}" for k, v in summary.items())
