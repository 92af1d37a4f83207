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
import sys
import time
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from sintercond.output import plots
from sintercond.sim import guards, neck_growth
from sintercond._deprecation import old_names
from sintercond.rollout import advance
from sintercond.output.io import (append_lammps, load_checkpoint, save_checkpoint, truncate_lammps, write_network_vtp, write_pvd,
                                  write_vtp)
from sintercond.beds.packing import packing_shrinkage
from sintercond.beds.packing_files import write_table
from sintercond.scene import SceneError, validate_scene
from sintercond.scene.validate import held_temperatures

from sintercond.scene.build import PackingBoxWarning, build_model, escaped_particles
from sintercond.output.observe import (Observation, _history_row, _probe_fn, contact_network, coordination,
                                       history_columns, moves, observe, read_history, state_time)


SLOW_OUTPUT_S = 2.0
"""Seconds above which writing one output (frames, history row, checkpoint) is logged, with its time."""

MAX_TEMPERATURE = 1e5
"""K; a run whose temperatures leave (0, MAX_TEMPERATURE] stops: no material of this field gets there."""


def physical_range_check(scene):
    """``check(state)`` for :func:`advance`: temperatures finite, > 0 K and <= :data:`MAX_TEMPERATURE`, and
    growing necks still within the time step's stability (:func:`sintercond.sim.neck_growth.check_stable`).

    The error names the step and the scene keys that can drive a run there.
    """
    causes = [key for key, section in (("beam.intensity", "beam"), ("convection.nusselt", "convection"),
                                       ("radiation.emissivity", "radiation")) if section in scene] + ["run.dt"]

    melting = scene["material"].get("melting_point")
    warned = []
    inputs = heat_inputs(scene)

    def check(state):
        neck_growth.check_stable(state)
        t = np.asarray(state.particles.temperature)  # on the host: op by op, JAX would compile each test
        bad = ~np.isfinite(t) | (t <= 0) | (t > MAX_TEMPERATURE)
        if bool(np.any(bad)):
            worst = float(np.max(np.where(np.isfinite(t), np.abs(t), np.inf)))
            raise FloatingPointError(
                f"temperature left the physical range (0, {MAX_TEMPERATURE:g}] K at step {int(state.step)} "
                f"(|T| up to {worst:.3g} K); likely cause: {', '.join(causes)} too large for the time step")
        if melting is not None and not warned:
            hottest = float(np.max(t))
            if hottest > melting:
                message = (f"T = {hottest:.6g} K at step {int(state.step)} (t = {state_time(state):.6g} s) is above "
                           f"material.melting_point = {melting:g} K: the model has no melting (no latent heat, no "
                           "liquid), so what follows is not physical")
                if scene["material"]["on_melting"] == "stop":
                    raise MeltingPointCrossed(message + f"; lower the heat input ({', '.join(inputs)}), or "
                                              'set material.on_melting = "warn" to go on')
                warned.append(int(state.step))
                warnings.warn(message, MeltingPointWarning, stacklevel=2)
                _log(f"warning: {message} (said once)")
    return check


def heat_inputs(scene) -> list[str]:
    """The keys of a scene that put heat in (a beam's power, held or conducting walls' and the surroundings'
    temperatures above the start, a preheating ramp's end): what a run that grows too hot can lower."""
    start = scene["initial"]["temperature"]
    keys = ["beam.intensity or beam.power"] if "beam" in scene else []
    hotter = {**held_temperatures(scene), **{f"walls[{k}].temperature": w["temperature"]
                                            for k, w in enumerate(scene["walls"]) if w["mode"] == "conducting"}}
    hotter.update({f"{section}.environment_temperature": scene[section]["environment_temperature"]
                   for section in ("convection", "radiation") if section in scene})
    keys += [key for key, value in hotter.items() if value > start]
    return keys or ["none is named in the scene: initial.temperature"]


class MeltingPointCrossed(FloatingPointError):
    """A run crossed ``material.melting_point`` with ``material.on_melting = "stop"`` (the default)."""


class MeltingPointWarning(UserWarning):
    """A run crossed ``material.melting_point`` with ``material.on_melting = "warn"``."""


def run_check(scene, model, state):
    """The ``check(state)`` of a scene's run from ``state``: :func:`physical_range_check`, and with mechanics
    :func:`sintercond.sim.guards.motion_guard` at the speed the step was sized for (``physics.impact_velocity``)."""
    temperatures = physical_range_check(scene)
    if model.sized_speed is None:
        return temperatures
    motion = guards.motion_guard(model.sim, state, model.params, model.sized_speed, "physics.impact_velocity")

    def check(new):
        temperatures(new)
        motion(new)

    return check


def _warn_escaped(scene, model, state) -> list:
    """Warn (:class:`~sintercond.scene.build.PackingBoxWarning`) and log if particles of a moving packing left the
    box it was made in (:func:`~sintercond.scene.build.escaped_particles`); returns them."""
    out = escaped_particles(scene, np.asarray(state.particles.positions), model.radii)
    if out.size:
        fix = ("physics.container = false lets it spread: drop it, or give [[walls]] on the open faces"
               if not scene["physics"]["container"] else "give [[walls]] on its open faces")
        message = (f"{out.size} of {len(model.radii)} particles (particle {int(out[0])} first) left the packing's "
                   f"box by step {int(state.step)} (t = {state_time(state):.6g} s): the bed spreads, and its "
                   f"figures (shrinkage, density, k*) are not the bed's; {fix}")
        warnings.warn(message, PackingBoxWarning, stacklevel=2)
        _log(f"warning: {message} (said once)")
    return out.tolist()


def _log(message):
    print(f"sintercond: {message}", file=sys.stderr, flush=True)


def _clear_outputs(out):
    """A new run into ``out`` first removes the outputs an earlier run left there."""
    for f in _frames(out, "step") + _frames(out, "network"):
        f.unlink()
    for name in ("dump.lammpstrj", "checkpoint.npz", "history.csv", "summary.json", "frames.pvd", "network.pvd",
                 plots.STATE_PICTURE, plots.HISTORY_PLOT):
        if (out / name).exists():
            (out / name).unlink()


def run_scene(scene, out_dir, progress=True, stop_after_chunks=None, _start=None, pictures=True):
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
        if "output_every" not in scene["run"]:  # the intervals the build chose: a resume keeps them
            scene = {**scene, "run": {**scene["run"], "output_every": model.output_every,
                                      "checkpoint_every": model.checkpoint_every}}
            (out / "scene.json").write_text(json.dumps(scene, indent=1))
        np.savez(out / "packing.npz", centres=model.centres, radii=model.radii)
        (out / "bed.json").write_text(json.dumps(model.bed))
        probe = _probe_fn(model)
        obs = observe(scene, model, model.state, probe)
        header = ",".join(history_columns(model)) + "\n"
        (out / "history.csv").write_text(header + _history_row(model, model.state, obs))
        _write_outputs(scene, out, model, model.state, obs)
        state = model.state
    else:
        model, state = _start
        probe = _probe_fn(model)
    chunk, checkpoint_every = model.output_every, model.checkpoint_every
    chunks_done = 0
    _log(f"{len(model.radii)} particles, {model.contacts} contacts; stable step {model.stable_step:.4g} s, "
         f"dt {model.dt:.4g} s, {model.n_steps} steps to {model.n_steps * model.dt:.6g} s; compiling the step")

    last = [int(state.step)]
    written = [0.0]  # s spent on the outputs between chunks
    escaped = []  # warned once

    def on_chunk(s):
        nonlocal chunks_done
        step = int(s.step)
        if chunks_done == 0:  # the first chunk carries the compile
            _log(f"compiled the step and ran steps {last[0]:,} to {step:,} in {time.perf_counter() - wall:.1f} s")
        crossed = step // checkpoint_every > last[0] // checkpoint_every  # an extension's steps
        last[0] = step  # are off the output grid: checkpoint once a multiple of checkpoint_every is passed
        start = time.perf_counter()
        obs = observe(scene, model, s, probe)
        if model.physics.mechanics is not None and not escaped:
            escaped.extend(_warn_escaped(scene, model, s))
        _write_outputs(scene, out, model, s, obs)
        with open(out / "history.csv", "a") as f:
            f.write(_history_row(model, s, obs))
        if crossed or step >= model.n_steps:
            save_checkpoint(out, s)  # the lists' capacities are the shapes of their leaves
        writing = time.perf_counter() - start
        written[0] += writing
        if writing > SLOW_OUTPUT_S:
            _log(f"outputs of step {step:,} written in {writing:.1f} s ({', '.join(scene['run']['formats'])}"
                 f"{', checkpoint' if crossed or step >= model.n_steps else ''}); {chunk:,} "
                 "steps between outputs (run.output_every)")
        chunks_done += 1
        return stop_after_chunks is not None and chunks_done >= stop_after_chunks and step < model.n_steps

    wall = time.perf_counter()
    bar = tqdm(total=model.n_steps, initial=int(state.step), unit="step", disable=not progress, desc="sintercond run")
    try:
        state, report = advance(model.sim, state, model.params, model.n_steps - int(state.step), chunk, on_chunk,
                           reallocate=model.reallocate, progress=bar.update, check=run_check(scene, model, state))
    finally:
        bar.close()
    temperature = np.asarray(state.particles.temperature)
    if int(state.step) < model.n_steps:
        return temperature, None
    elapsed = time.perf_counter() - wall
    summary = {
        "particles": len(model.radii), "contacts": model.contacts, **model.bed, "steps": int(state.step),
        "dt_s": model.dt, "stable_step_s": model.stable_step, "simulated_s": int(state.step) * model.dt,
        "wall_s": elapsed, "outputs_s": written[0], "T_min_K": float(temperature.min()), "T_mean_K": float(temperature.mean()),
        "T_max_K": float(temperature.max()), "integrator": model.physics.conduction.integrator,
    }
    if model.physics.conduction.integrator == "implicit":  # this call's adaptive steps (a resume counts its own)
        summary.update({"implicit_steps": report.accepted, "rejected_steps": report.rejected})
    if model.physics.mechanics is not None:
        history = read_history(out)
        summary.update({"quasi_static": model.physics.mechanics.quasi_static, "thermal_step_s": model.limits["thermal"],
                        "mechanical_step_s": model.limits.get("mechanical"),  # None: quasi-static, no inertia
                        "kinetic_energy_J": float(history["kinetic_energy_J"][-1]),
                        "final_contacts": int(history["contacts"][-1]),
                        "max_overlap_m": float(history["max_overlap_m"][-1])})
    if model.physics.sintering is not None:
        summary.update({name: float(value) for name, value in neck_growth.neck_statistics(state).items()})
        if moves(model):
            summary.update(packing_shrinkage(state.sintering.start_positions, state.particles.positions))
        if state.sintering.balance_iterations is not None and model.physics.conduction.integrator == "explicit":
            summary["balance_iterations"] = int(state.sintering.balance_iterations)  # the last update's solve
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    if pictures:
        start = time.perf_counter()
        plots.write_run_pictures(out, np.asarray(state.particles.positions), model.radii, temperature, summary,
                                 history=read_history(out))
        if time.perf_counter() - start > SLOW_OUTPUT_S:
            _log(f"pictures drawn in {time.perf_counter() - start:.1f} s (--no-pictures skips them)")
    return temperature, summary


def written_outputs(out) -> str:
    """What a finished run left in ``out``, for the closing line of ``sintercond run``."""
    out = Path(out)
    listed = [(plots.STATE_PICTURE, "a picture of the last state"), (plots.HISTORY_PLOT, "the history plotted"),
              ("frames.pvd", "the frames as a time series for ParaView"),
              ("network.pvd", "the contact network's frames for ParaView"), ("vtp", "one VTP frame per output"),
              ("dump.lammpstrj", "for OVITO"), ("history.csv", "one row per output"),
              ("summary.json", "the summary"), ("checkpoint.npz", "for --resume")]
    return "; ".join(f"{name}{'/' if name == 'vtp' else ''}: {what}" for name, what in listed if (out / name).exists())


def _write_outputs(scene, out, model, state, obs: Observation):
    """The frame of ``state``: positions, radii, temperatures, and with mechanics velocity, contact force and
    coordination (contacts per particle)."""
    formats = scene["run"]["formats"]
    step = int(state.step)
    t = state_time(state)
    temperature = state.particles.temperature
    positions = np.asarray(state.particles.positions)
    fields = {}
    if model.physics.mechanics is not None:
        fields = {"velocity": obs.velocity, "force": obs.force,
                  "coordination": coordination(len(model.radii), obs.pairs)}
    if model.physics.sintering is not None:
        fields["neck_ratio"] = np.asarray(neck_growth.particle_neck_ratio(state))
    p = state.particles  # both formats carry the same fields
    fields = {**fields, "held": np.asarray(p.fixed, np.int64) if p.fixed is not None else
              np.zeros(len(model.radii), np.int64), "material": np.asarray(p.material, np.int64)}
    if obs.power is not None:
        fields["heat_power"] = np.asarray(obs.power)
    if "lammps" in formats:
        append_lammps(out / "dump.lammpstrj", positions, model.radii, temperature, step, fields, t)
    if "vtp" in formats:
        (out / "vtp").mkdir(exist_ok=True)
        write_vtp(out / "vtp" / f"step_{step:08d}.vtp", positions, model.radii, temperature, step, t, fields,
                  encoding=scene["run"]["vtp_encoding"])
        if scene["run"]["contact_network"]:
            pairs, per_contact = contact_network(model, state)
            write_network_vtp(out / "vtp" / f"network_{step:08d}.vtp", positions, pairs, step, t, per_contact,
                              encoding=scene["run"]["vtp_encoding"])
        write_frames_pvd(out, model.dt)


def _frames(out, kind):
    """The VTP frames ``out/vtp/{kind}_*.vtp`` (``step``: particles, ``network``: contacts), in step order."""
    return sorted((out / "vtp").glob(f"{kind}_*.vtp")) if (out / "vtp").exists() else []


def write_frames_pvd(out, dt):
    """``out/frames.pvd`` (and ``out/network.pvd`` with contact-network frames): every frame in ``out/vtp`` at its
    physical time ``step * dt`` (ParaView's time series)."""
    for kind, name in (("step", "frames.pvd"), ("network", "network.pvd")):
        frames = _frames(out, kind)
        if frames or kind == "step":
            write_pvd(out / name, [(float(np.float64(int(f.stem.split("_")[1])) * dt), f"vtp/{f.name}")
                                   for f in frames])


def resume(out_dir, progress=True, stop_after_chunks=None, pictures=True, duration=None):
    """Continue the run in ``out_dir`` from its last checkpoint (the whole state).

    A finished run (its ``summary.json`` at the checkpoint's step) is not
    rebuilt: its final temperatures and summary are returned as they are,
    unless ``duration`` (s) extends it: the run then goes on with its own time
    step to the first step at or after ``duration`` (``scene.json`` records the
    new duration), its outputs appended to the ones it has.
    """
    out = Path(out_dir)
    if not (out / "checkpoint.npz").exists():
        raise SceneError(f"{str(out)!r} has no checkpoint.npz to resume from")
    saved = np.load(out / "checkpoint.npz")
    step = int(saved["step"])
    raw = json.loads((out / "scene.json").read_text())
    if raw["run"].get("integrator") in (None, "auto"):  # the run keeps the integrator it started with
        raw["run"]["integrator"] = "implicit" if ".adaptive_step" in saved.files else "explicit"
    if duration is not None:
        done = step * float(saved[".dt"])
        if not duration > done:
            raise SceneError(f"--duration {duration:g} s must exceed the {done:.6g} s the run in {out} has simulated")
        raw["run"]["duration"] = float(duration)
    elif (out / "summary.json").exists():
        summary = json.loads((out / "summary.json").read_text())
        if summary.get("steps") == step:
            _log(f"the run in {out} is finished (step {step}); nothing to resume (--duration S extends it)")
            return jnp.asarray(saved["temperature"]), summary
    packed = np.load(out / "packing.npz")
    _packing_from_run_folder(raw, out, packed, saved)
    scene = validate_scene(raw)
    model = build_model(scene, packed["centres"], packed["radii"], log=_log)
    if (out / "bed.json").exists():
        model = dataclasses.replace(model, bed=json.loads((out / "bed.json").read_text()))
    state = load_checkpoint(out / "checkpoint.npz", model.state)
    if (out / "history.csv").exists():  # before anything in the folder changes
        header = (out / "history.csv").read_text().partition("\n")[0].strip()
        columns = ",".join(history_columns(model))
        if header != columns:
            raise SceneError(f"the run in {out} wrote history.csv with the columns {header!r}; this version writes "
                             f"{columns!r} for it: run the scene anew (or resume it with the version that started "
                             "it)")
    if duration is not None or float(state.dt) != model.dt:
        # the run keeps its own step (an extension, or the resume of an interrupted one): the steps taken stay valid
        dt = float(state.dt)
        model = dataclasses.replace(model, n_steps=max(step, int(np.ceil(scene["run"]["duration"] / dt * (1 - 1e-12)))),
                                    state=dataclasses.replace(model.state, dt=state.dt))
    if duration is not None:
        (out / "scene.json").write_text(json.dumps(scene, indent=1))
        for name in ("summary.json", plots.STATE_PICTURE, plots.HISTORY_PLOT):
            if (out / name).exists():
                (out / name).unlink()
    # outputs written after the checkpoint by the interrupted run are redone
    for f in _frames(out, "step") + _frames(out, "network"):
        if int(f.stem.split("_")[1]) > step:
            f.unlink()
    if (out / "vtp").exists():
        write_frames_pvd(out, model.dt)
    if (out / "dump.lammpstrj").exists():
        truncate_lammps(out / "dump.lammpstrj", step)
    if (out / "history.csv").exists():
        lines = (out / "history.csv").read_text().splitlines(keepends=True)
        (out / "history.csv").write_text("".join([lines[0]] + [r for r in lines[1:] if int(r.split(",")[0]) <= step]))
    return run_scene(scene, out, progress, stop_after_chunks, _start=(model, state), pictures=pictures)


def _packing_from_run_folder(raw, out, packed, saved):
    """A file packing whose file has moved since the run started is read from the run folder: ``raw``'s packing
    then points at ``out/packing.csv``, the table of ``packing.npz`` (m; with ``initial.from_file``, the
    checkpoint's temperatures as its column, which the checkpoint then replaces anyway)."""
    packing = raw["packing"]
    if packing["kind"] != "file" or Path(packing["path"]).is_file():
        return
    table = out / "packing.csv"
    write_table(table, packed["centres"], packed["radii"],
                temperature=saved["temperature"] if raw["initial"].get("from_file") else None)
    _log(f"the packing file {packing['path']} is gone; resuming from the run folder's packing ({table})")
    raw["packing"] = {**packing, "path": str(table), "format": "table", "length_unit": "m"}


def summary_table(summary) -> str:
    width = max(len(k) for k in summary)
    return "\n".join(f"{k:<{width}}  {v:.6g}" if isinstance(v, float) else f"{k:<{width}}  {v}" for k, v in summary.items())


# the model build moved to sintercond.scene.build and the history rows to sintercond.output.observe (issue 24)
__getattr__ = old_names("sintercond.run", {
    "Model": ("sintercond.scene.build", "Model"),
    "PROGRESS_EVERY_S": ("sintercond.scene.build", "PROGRESS_EVERY_S"),
    "SettlingProgress": ("sintercond.scene.build", "SettlingProgress"),
    "build_packing": ("sintercond.scene.build", "build_packing"),
    "scene_physics": ("sintercond.scene.build", "scene_physics"),
    "mechanics_on": ("sintercond.scene.build", "mechanics_on"),
    "contact_material": ("sintercond.scene.build", "contact_material"),
    "mechanical_params": ("sintercond.scene.build", "mechanical_params"),
    "dem_material": ("sintercond.scene.build", "dem_material"),
    "mechanical_physics": ("sintercond.scene.build", "mechanical_physics"),
    "scene_params": ("sintercond.scene.build", "scene_params"),
    "scene_walls": ("sintercond.scene.build", "scene_walls"),
    "FEW_WALL_CONTACTS": ("sintercond.scene.build", "FEW_WALL_CONTACTS"),
    "wall_contacts": ("sintercond.scene.build", "wall_contacts"),
    "WallContactWarning": ("sintercond.scene.build", "WallContactWarning"),
    "RAMP_STEP_FRACTION": ("sintercond.scene.build", "RAMP_STEP_FRACTION"),
    "HISTORY_COLUMNS": ("sintercond.output.observe", "HISTORY_COLUMNS"),
    "MECHANICS_COLUMNS": ("sintercond.output.observe", "MECHANICS_COLUMNS"),
    "SINTERING_COLUMNS": ("sintercond.output.observe", "SINTERING_COLUMNS"),
    "sintered_conductivity": ("sintercond.output.observe", "sintered_conductivity"),
})
