"""The scene reference (Markdown), generated from the schema: ``docs/scenes.md``
(``python -m sintercond.scene > docs/scenes.md``)."""

from __future__ import annotations



from sintercond.laws.conductance import CONDUCTANCE_LAWS
from sintercond.laws.sintering import KINETIC_LAWS
from sintercond.scene.schema import (
    MAX_FRAMES, MAX_LATTICE_PARTICLES, MAX_LISTED_SPHERES, MAX_MEMORY_BYTES, MAX_OUTPUT_BYTES, MAX_STEPS, _LAW_PARAMS,
    _PACKING, _SCHEMA, _SINTERING_PARAMS, _WALL, _describe,
)


def scene_reference() -> str:
    """The scene reference (Markdown), generated from the schema: ``docs/scenes.md``."""
    lines = ["# Scene reference", "",
             "Generated from `sintercond.scene` by `python -m sintercond.scene > docs/scenes.md`;",
             "`tests/test_bad_input.py` checks that it is current. SI units. Every key is checked before anything",
             "is built; an error names the key and the allowed range.", ""]

    def table(title, schema, note=""):
        lines.extend([f"## {title}", ""] + ([note, ""] if note else []) + [
            "| key | required | allowed | unit | default | meaning |", "| --- | --- | --- | --- | --- | --- |"])
        for name, key in schema.items():
            default = "" if key.default is None else str(key.default).replace("'", '"')
            lines.append(f"| `{name}` | {'yes' if key.required else 'no'} | {_describe(key)} | {key.unit} | "
                         f"{default} | {key.doc} |")
        lines.append("")

    table("[packing] kind = \"powder_bed\"", _PACKING["powder_bed"],
          "A random bed at rest under gravity (`sintercond.beds.packing.powder_bed`): rolled, at most 1,000,000 particles "
          "(the default); relaxed or DEM-poured, at most 20,000.")
    table("[packing] kind = \"simple_cubic\"", _PACKING["simple_cubic"],
          "Sphere centres at `radius + spacing * (i, j, k)`.")
    table("[packing] kind = \"poured\"", _PACKING["poured"],
          "Spheres of normally distributed radii poured into an open square box and settled with the DEM "
          "(`sintercond.beds.packing.pour`: Hertz, Mindlin, rolling resistance, gravity, the box walls) with the contact "
          "material of `[mechanics]` and `material.density`; settled means kinetic energy and force balance below "
          "the thresholds the summary reports. Example 5.3's bed (`quintana2020_5_3`).")
    table("[packing] kind = \"file\"", _PACKING["file"],
          "A packing read from a file (a CT scan, a LIGGGHTS or LAMMPS pour, another code): "
          "`sintercond.beds.packing_files`. The particles are used as they are; `sintercond effective` measures k* "
          "between the face layers of its bounding box.")
    table("[packing] kind = \"spheres\"", _PACKING["spheres"],
          f"Spheres listed one by one (at most {MAX_LISTED_SPHERES}), e.g. one sphere on a floor.")
    for section in ("material", "conduction"):
        table(f"[{section}]", _SCHEMA[section])
    table("[conduction.params]", _LAW_PARAMS, "Keys the chosen law takes: " + "; ".join(
        f"`{name}`: {', '.join(law.default_params) or 'none'}" for name, law in sorted(CONDUCTANCE_LAWS.items())))
    for section in ("initial", "boundary"):
        table(f"[{section}]", _SCHEMA[section])
    table("[[walls]]", _WALL, "Any number of walls; a face without one is insulated. `history.csv` reports the "
          "heat power into the packing through each held or conducting wall as `heat_wall{k}_W`, `k` its index "
          "among the `[[walls]]` (the `[boundary]` floor comes last).")
    for section in ("beam", "convection", "radiation"):
        table(f"[{section}]", _SCHEMA[section])
    table("[physics]", _SCHEMA["physics"],
          "The physics of the run. With `mechanics = true` every wall pushes (a rigid plane of infinite radius and "
          "mass, Remark 1), rubs (`mechanics.wall_friction`) and, by its mode, conducts: `conducting` walls exchange "
          "heat through the contact they make, `held` walls hold the particles touching them at the start at "
          "their temperature (those particles still move), `insulated` walls only push. The time step "
          '`run.dt = "auto"` is 0.9 x the smallest of the thermal limit, the mechanical one '
          "(`sintercond.sim.mechanics.mechanical_time_step`: Eq. 47 and the tangential and rotational bounds of "
          "MECHANICS.md erratum 8 at the unsoftened modulus and the approach speed `impact_velocity` plus the "
          "fastest wall's normal speed), the step in which a moving wall advances a tenth of the smallest radius, "
          "and the step in which a beam's spot advances a fifth of its radius; a larger `run.dt` is refused, "
          "naming the limit and its key. While it runs, a contact approaching faster than the step was sized for, "
          "or kinetic energy growing beyond what gravity and the initial overlaps can supply, stops the run "
          "naming `physics.impact_velocity`. With `mechanics.quasi_static = true` (sintering) nothing is inertial: "
          "the mechanical bound, `impact_velocity` and that guard do not apply, and no wall pushes.")
    table("[mechanics]", _SCHEMA["mechanics"],
          "The contact material (Quintana-Ruiz & Campello 2020, Eqs. 2-20), with `physics.mechanics = true`. "
          "Walls are rigid (`E* = E/(1 - nu^2)`).")
    table("[softening]", _SCHEMA["softening"],
          "Thermal softening of Young's modulus (Eq. 42, MECHANICS.md erratum 6), with `physics.mechanics = true`.")
    table("[sintering]", _SCHEMA["sintering"],
          "Necks that grow with each contact's temperature history (`sintercond.sim.neck_growth`): each contact's "
          "volume-conserving neck (Rojek et al. 2022, Eqs. 23-27) grows by the kinetic law, and the conductance "
          "law is applied to the grown neck at every step; with `shrinkage = \"many_body\"` the contacts' force "
          "balance also moves the particles (else the packing stays). Touching "
          "spheres (a lattice with `radius = spacing/2`) start from point contacts. `history.csv` gains the mean "
          "and largest neck ratio a/min(r_i, r_j) and the mean linear shrinkage (h - h_0)/(r_i + r_j) of the "
          "contacts (h their approach H(a), or from the positions with many-body shrinkage), and where the "
          "particles move the packing's `height_shrinkage` and `volume_shrinkage` (its best-fit homogeneous "
          "deformation F: 1 - F_zz and 1 - det F; docs/simulator.md, shrinkage of a packing); the "
          "VTP frames each particle's mean neck ratio. The automatic time step is taken on the necks at the law's "
          "cap (they only grow).")
    table("[sintering.params]", _SINTERING_PARAMS, "Keys the chosen law takes: " + "; ".join(
        f"`{name}`: {', '.join(law.default_params)}" for name, law in sorted(KINETIC_LAWS.items())))
    table("[preheating]", _SCHEMA["preheating"],
          "A stepped temperature ramp of the held particles (Rizza & Galati 2024, Eq. 6, with the step count inside "
          "its int(): `T(t) = T_0 + (T_end - T_0) min(ceil(steps t / duration), steps) / steps`), e.g. the plate "
          "of a PBF-EB bed along its preheating, or an isothermal cell (`hold = \"all\"`).")
    table("[run]", _SCHEMA["run"])
    lines.extend(["## Limits", "",
                  f"- at most {MAX_LATTICE_PARTICLES} lattice particles and 20000 powder-bed particles, "
                  f"about {MAX_MEMORY_BYTES / 1e9:g} GB;",
                  f"- at most {MAX_STEPS:g} steps, {MAX_FRAMES} output frames and {MAX_OUTPUT_BYTES / 1e9:g} GB of "
                  "output, estimated from the scene (`sintercond.scene.estimate_run`); "
                  "`run.override_limits = true` lifts these three.", ""])
    return "\n".join(lines)

