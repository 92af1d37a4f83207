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

from sintercond import heat_sources, network, packing, thermal
from sintercond.io import append_lammps, save_checkpoint as _save_checkpoint, truncate_lammps as _truncate_lammps
from sintercond.io import write_vtp  # noqa: F401  (moved to sintercond.io; kept importable here)
from sintercond.scene import SceneError, validate_scene
from sintercond.state import ParticleState, particle_state


@dataclasses.dataclass(frozen=True)
class Model:
    """Everything a run needs, built from a scene."""

    state: ParticleState
    table: network.ContactTable
    source: object
    dt: float
    n_steps: int

    @property
    def centres(self) -> np.ndarray:
        return np.asarray(self.state.positions)

    @property
    def radii(self) -> np.ndarray:
        return np.asarray(self.state.radii)


def build_packing(scene):
    bed = packing.from_scene(scene["packing"])
    return bed.centres, bed.radii


@dataclasses.dataclass(frozen=True, eq=False)
class _Source:
    """Heat-source term (a static argument under jit, hashed by identity): beam, convection, radiation.

    ``eq=False`` keeps hashing O(1): one compiled chunk per run, not a hash of
    every particle's coordinates at every call.
    """

    radii: jax.Array
    centres: jax.Array
    beam: tuple | None
    convection: tuple | None
    radiation: tuple | None
    surface_z: float

    def __call__(self, temperature, t):
        radii = self.radii
        power = jnp.zeros_like(temperature)
        if self.beam is not None:
            kind, intensity, reach, spot, absorptance, speed, path = self.beam
            spot_xy = heat_sources.beam_position(t, jnp.asarray(path), speed)
            depth = heat_sources.beam_depth(self.centres, radii, spot_xy, spot, self.surface_z)
            if kind == "laser":
                power = power + heat_sources.laser_power(radii, depth, intensity, reach, absorptance)
            else:
                power = power + heat_sources.nozzle_power(radii, depth, intensity, reach, absorptance)
        if self.convection is not None:
            t_env, k_env, nusselt = self.convection
            power = power + heat_sources.convection_power(radii, temperature, t_env, k_env, nusselt)
        if self.radiation is not None:
            t_env, emissivity = self.radiation
            power = power + heat_sources.radiation_power(radii, temperature, t_env, emissivity)
        return power


def _nusselt(convection):
    if "reynolds" in convection:
        return float(heat_sources.whitaker_nusselt(convection["reynolds"], convection["prandtl"]))
    return convection.get("nusselt", 2.0)


def build_model(scene, centres=None, radii=None) -> Model:
    """Packing, network, capacities, held particles, sources and time step of a validated scene."""
    if centres is None:
        centres, radii = build_packing(scene)
    m, c = scene["material"], scene["conduction"]
    try:
        table = network.contact_table(centres, radii, m["conductivity"], c["law"], c.get("params"), c.get("neck_model"))
    except ValueError as err:
        raise SceneError(f"the packing does not fit the conduction model: {err}") from None
    table, fixed_mask, fixed_temperature = _apply_walls(scene, centres, radii, table)
    state = particle_state(centres, radii, scene["initial"]["temperature"], m["density"], m["specific_heat"],
                           fixed=fixed_mask, fixed_temperature=fixed_temperature)
    capacity = state.capacity
    beam = scene.get("beam")
    conv = scene.get("convection")
    rad = scene.get("radiation")
    source = None
    if beam or conv or rad:
        source = _Source(
            radii=jnp.asarray(radii), centres=jnp.asarray(centres),
            beam=None if beam is None else (
                beam["kind"], beam["intensity"], beam["attenuation"] if beam["kind"] == "laser" else beam["max_depth"],
                beam["spot_radius"], beam["absorptance"], beam["speed"], tuple(map(tuple, beam["path"]))),
            convection=None if conv is None else (conv["environment_temperature"], conv["environment_conductivity"],
                                                  _nusselt(conv)),
            radiation=None if rad is None else (rad["environment_temperature"], rad["emissivity"]),
            surface_z=float(np.max(centres[:, 2] + radii)),
        )
    run = scene["run"]
    limit = float(thermal.stable_time_step(capacity, table))
    if run["dt"] == "auto":
        dt = 0.9 * limit if np.isfinite(limit) else run["duration"] / 1000
    else:
        try:
            dt = run["dt"]
            thermal.check_time_step(dt, capacity, table)
        except ValueError as err:
            raise SceneError(f"run.dt: {err}") from None
    n_steps = max(1, int(np.ceil(run["duration"] / dt)))
    chunk = run["output_every"]
    n_steps = int(np.ceil(n_steps / chunk) * chunk)
    return Model(state, table, source, dt, n_steps)


def _walls(scene):
    walls = list(scene.get("walls", []))
    if "floor_temperature" in scene.get("boundary", {}):
        walls.append({"axis": 2, "side": "min", "mode": "held", "temperature": scene["boundary"]["floor_temperature"]})
    return walls


def _apply_walls(scene, centres, radii, table):
    """Held walls become fixed particles, conducting walls per-particle couplings of the table."""
    held = np.zeros(len(radii), bool)
    held_t = np.zeros(len(radii))
    k_wall = np.zeros(len(radii))
    t_wall = np.zeros(len(radii))
    c = scene["conduction"]
    for k, wall in enumerate(_walls(scene)):
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
            try:
                k_w = network.wall_conductance(centres, radii, scene["material"]["conductivity"], axis, position,
                                               c["law"], c.get("params"), c.get("neck_model"))
            except ValueError as err:
                raise SceneError(f"walls[{k}]: {err}") from None
            t_wall = np.where(k_w > 0, (k_wall * t_wall + k_w * wall["temperature"]) / np.maximum(k_wall + k_w, 1e-300),
                              t_wall)
            k_wall = k_wall + k_w
    if k_wall.any():
        table = table.with_walls(k_wall, t_wall)
    return table, held, held_t


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
        temperature = model.state.temperature
        step = 0
        if (out / "dump.lammpstrj").exists():
            (out / "dump.lammpstrj").unlink()
        _write_outputs(scene, out, model, temperature, step)
    else:
        model, temperature, step = _start
    run = scene["run"]
    chunk = run["output_every"]

    state = model.state

    def advance(t, start_step):
        return thermal.simulate(t, model.table, state.capacity, model.dt, n_steps=chunk, save_every=chunk,
                                fixed_mask=state.fixed, fixed_temperature=state.fixed_temperature,
                                source=model.source, start_step=start_step)[0]

    advance = jax.jit(advance)
    wall = time.perf_counter()
    chunks_done = 0
    bar = tqdm(total=model.n_steps, initial=step, unit="step", disable=not progress, desc="sintercond run")
    while step < model.n_steps:
        temperature = advance(temperature, step)
        step += chunk
        bar.update(chunk)
        if not bool(jnp.all(jnp.isfinite(temperature))):
            bar.close()
            raise FloatingPointError(f"non-finite temperature at step {step}; reduce run.dt")
        _write_outputs(scene, out, model, temperature, step)
        if step % run["checkpoint_every"] == 0 or step >= model.n_steps:
            _save_checkpoint(out, temperature, step)
        chunks_done += 1
        if stop_after_chunks is not None and chunks_done >= stop_after_chunks and step < model.n_steps:
            bar.close()
            return temperature, None
    bar.close()
    elapsed = time.perf_counter() - wall
    summary = {
        "particles": len(model.radii), "contacts": int(len(model.table.pairs())), "steps": step,
        "dt_s": model.dt, "simulated_s": step * model.dt, "wall_s": elapsed,
        "T_min_K": float(temperature.min()), "T_mean_K": float(temperature.mean()), "T_max_K": float(temperature.max()),
    }
    return temperature, summary


def _write_outputs(scene, out, model, temperature, step):
    formats = scene["run"]["formats"]
    t = step * model.dt
    if "vtp" in formats:
        (out / "vtp").mkdir(exist_ok=True)
        write_vtp(out / "vtp" / f"step_{step:08d}.vtp", model.centres, model.radii, temperature, step, t)
    if "lammps" in formats:
        append_lammps(out / "dump.lammpstrj", model.centres, model.radii, temperature, step)


def resume(out_dir, progress=True, stop_after_chunks=None):
    """Continue the run in ``out_dir`` from its last checkpoint."""
    out = Path(out_dir)
    if not (out / "checkpoint.npz").exists():
        raise SceneError(f"{str(out)!r} has no checkpoint.npz to resume from")
    scene = validate_scene(json.loads((out / "scene.json").read_text()))
    packed = np.load(out / "packing.npz")
    model = build_model(scene, packed["centres"], packed["radii"])
    state = np.load(out / "checkpoint.npz")
    step = int(state["step"])
    # outputs written after the checkpoint by the interrupted run are redone
    for f in (out / "vtp").glob("step_*.vtp") if (out / "vtp").exists() else []:
        if int(f.stem.split("_")[1]) > step:
            f.unlink()
    if (out / "dump.lammpstrj").exists():
        _truncate_lammps(out / "dump.lammpstrj", step)
    return run_scene(scene, out, progress, stop_after_chunks, _start=(model, jnp.asarray(state["temperature"]), step))


def summary_table(summary) -> str:
    width = max(len(k) for k in summary)
    return "\n".join(f"{k:<{width}}  {v:.6g}" if isinstance(v, float) else f"{k:<{width}}  {v}" for k, v in summary.items())
