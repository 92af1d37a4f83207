"""Scene files (TOML): what a thermal run simulates, validated before anything is built or compiled.

A scene has the sections ``[packing]`` (``kind = "powder_bed"``,
``"simple_cubic"`` or ``"spheres"``), ``[material]``, ``[conduction]`` (with
``[conduction.params]``), ``[initial]``, optional ``[boundary]``,
``[[walls]]``, ``[beam]``, ``[convection]``, ``[radiation]``, the
thermo-mechanical ``[physics]`` (``mechanics = true``: particles move under
contact forces, gravity and walls; Quintana-Ruiz & Campello 2020),
``[mechanics]`` (the contact material) and ``[softening]`` (Eq. 42), and
``[run]``.
SI units throughout (m, s, K, W, kg). The reference of every key (type,
range, unit, default, meaning) is ``docs/scenes.md``, generated from the
schema below (:func:`scene_reference`); ``sintercond/data/default_scene.toml``
is a complete example (the scene ``sintercond run`` uses without arguments).

Every key is checked (unknown keys, wrong types, out-of-range values,
inconsistent combinations raise :class:`SceneError` naming the key and the
allowed range), and the work of the run is estimated from the scene alone
(:func:`estimate_run`: particles, steps, output frames and bytes, memory) and
refused beyond the documented limits, all before a packing is built.
"""

from __future__ import annotations

import copy
import difflib
import functools
import importlib.resources
import math
import tomllib
from pathlib import Path
from typing import NamedTuple

import numpy as np

from sintercond.conductance import CONDUCTANCE_LAWS
from sintercond.mechanics import PARAMETER_RANGES, validate_mechanical_params
from sintercond.neck import NECK_MODELS
from sintercond.sintering import KINETIC_LAWS


class SceneError(ValueError):
    """An invalid scene: the message names the key and the allowed range."""


class Key(NamedTuple):
    """One scene key: its type, allowed range, unit, default and meaning (the scene reference is made from these)."""

    kind: type  # float, int, str, bool, list or dict
    rule: tuple | None  # (text, predicate) or None
    required: bool
    unit: str = ""
    default: object = None
    doc: str = ""


def _within(low, high, unit="", low_open=False):
    text = f"in {'(' if low_open else '['}{low:g}, {high:g}]" + (f" {unit}" if unit else "")
    return text, (lambda v: (low < v if low_open else low <= v) and v <= high)


def _choice(*options):
    return "one of " + ", ".join(repr(o).replace("'", '"') for o in options), (lambda v: v in options)


def _parameter(field):
    """The scene rule of a :class:`sintercond.mechanics.MechanicalParams` field: the Python API's range."""
    low, high, unit = PARAMETER_RANGES[field]
    return _within(low, high, unit)


# scene key -> the MechanicalParams field it sets (mechanics and softening sections)
MECHANICAL_FIELDS = {
    "mechanics.young_modulus": "E0", "mechanics.poisson_ratio": "nu", "mechanics.friction": "mu",
    "mechanics.rolling_friction": "mu_r", "mechanics.wall_friction": "mu_wall",
    "mechanics.wall_rolling_friction": "mu_r_wall", "mechanics.damping": "xi_con",
    "mechanics.tangential_damping": "xi_fric", "mechanics.rolling_damping": "xi_rol",
    "softening.onset_temperature": "theta_star", "softening.rate": "rate", "softening.min_modulus": "E_min",
}

TEMPERATURE = _within(1.0, 1e4, "K")
PACKING_KINDS = ("powder_bed", "simple_cubic", "spheres", "poured", "file")
PACKING_METHODS = ("relax", "dem")
"""How a ``powder_bed`` is made (``packing.method``): harmonic relaxation, or poured with the DEM of [mechanics]."""
MAX_POURED_PARTICLES = 20_000
"""Spheres of a ``poured`` packing: each costs a DEM settle (~1e4-1e5 steps)."""
MAX_LISTED_SPHERES = 10_000
"""Most spheres of a ``kind = "spheres"`` packing (they are listed in the scene file)."""
FRACTION = _within(0.0, 1.0)

# Limits of a run, checked before anything is built (``run.override_limits = true`` lifts the last three).
MAX_LATTICE_PARTICLES = 2_000_000
"""Largest ``simple_cubic`` lattice (memory of the network build, ~4 kB a particle)."""
MAX_STEPS = 10_000_000
"""Most time steps of a run (estimated from the scene: ``duration`` over the (estimated stable) step)."""
MAX_FRAMES = 10_000
"""Most output frames of a run (``steps / output_every + 1``): files in ``vtp/``, frames of the dump."""
MAX_OUTPUT_BYTES = 2e9
"""Most bytes of outputs of a run (about 230 B a particle and frame in VTP, 140 B in the LAMMPS dump)."""
MAX_MEMORY_BYTES = 8e9
"""Most memory of the network build (about 4 kB a particle)."""

_SCHEMA = {
    "material": {
        "density": Key(float, _within(1.0, 1e5, "kg/m^3"), True, "kg/m^3", doc="solid density"),
        "specific_heat": Key(float, _within(1.0, 1e5, "J/(kg K)"), True, "J/(kg K)", doc="specific heat capacity"),
        "conductivity": Key(float, _within(1e-6, 1e4, "W/(m K)"), True, "W/(m K)",
                            doc="solid conductivity kappa (with conductivity_table: the one number sintercond "
                                "effective and the run's estimate take)"),
        "conductivity_table": Key(list, ("a list of at least 2 [T, kappa] pairs, T strictly increasing in (0, "
                                         "1e5] K, kappa in [1e-06, 10000] W/(m K)", lambda v: True), False,
                                  "K, W/(m K)",
                                  doc="kappa(T): each particle conducts at its own temperature, piecewise linear "
                                      "between the pairs and clamped beyond them (sintercond.materials.Table); the "
                                      "run's conductances are then evaluated at every step"),
        "melting_point": Key(float, TEMPERATURE, False, "K",
                             doc="melting point (or solidus): the model has no melting, so a run whose hottest "
                                 "particle crosses it stops (or warns, material.on_melting), naming it"),
        "on_melting": Key(str, _choice("stop", "warn"), False, default="stop",
                          doc="what a run crossing material.melting_point does"),
    },
    "conduction": {
        "law": Key(str, _choice(*sorted(CONDUCTANCE_LAWS)), True, doc="pair conductance law"),
        "neck_model": Key(str, _choice(*sorted(NECK_MODELS)), False, default="the law's",
                          doc="neck (contact) radius the law takes"),
        "params": Key(dict, None, False, default="the law's", doc="the law's parameters, see [conduction.params]"),
    },
    "initial": {"temperature": Key(float, TEMPERATURE, True, "K", doc="initial temperature of every particle")},
    "boundary": {"floor_temperature": Key(float, TEMPERATURE, False, "K",
                                          doc="shorthand for a held wall at the bottom (axis 2, min)")},
    "beam": {
        "kind": Key(str, _choice("laser", "nozzle"), False, default="laser",
                    doc="laser: Lambert-Beer attenuation; nozzle: linear attenuation to max_depth"),
        "intensity": Key(float, _within(0.0, 1e12, "W/m^2"), False, "W/m^2",
                         doc="I0, power per unit spot area (give it or beam.power)"),
        "power": Key(float, _within(0.0, 1e6, "W"), False, "W",
                     doc="the beam's power, I0 pi spot_radius^2 (give it or beam.intensity)"),
        "attenuation": Key(float, _within(0.0, 1e9, "1/m"), False, "1/m", doc="mu of a laser (required for it)"),
        "max_depth": Key(float, _within(1e-9, 1.0, "m"), False, "m", doc="reach d_max of a nozzle (required for it)"),
        "spot_radius": Key(float, _within(1e-9, 1.0, "m"), True, "m",
                           doc="a particle is heated when its centre lies within spot_radius + r of the beam axis"),
        "absorptance": Key(float, FRACTION, True, doc="absorbed fraction a"),
        "speed": Key(float, _within(0.0, 1e3, "m/s"), True, "m/s", doc="speed along the path"),
        "path": Key(list, ("a non-empty list of [x, y] points (m)", lambda v: True), True, "m",
                    doc="[[x, y], ...] waypoints in absolute coordinates of the packing "
                        "(the container's corner or the lattice's first sphere side at 0), "
                        "each within the packing's lateral extent widened by spot_radius"),
        "segments_on": Key(list, ("a list of booleans, one per segment of beam.path", lambda v: True), False,
                           doc="whether the beam heats along each segment of the path (false: a jump between "
                               "hatch lines); default: every segment"),
        "after_path": Key(str, _choice("off", "stay"), False, default="off",
                          doc="off: the beam stops heating once its path is done; stay: it heats on at the last "
                              "waypoint (a path of one point is a stationary spot, on throughout)"),
    },
    "convection": {
        "environment_temperature": Key(float, TEMPERATURE, True, "K", doc="T_E of the gas"),
        "environment_conductivity": Key(float, _within(1e-6, 1e3, "W/(m K)"), True, "W/(m K)",
                                        doc="k_E of the gas"),
        "nusselt": Key(float, _within(0.0, 1e4, low_open=True), False, default=2.0,
                       doc="Nu of h = Nu k_E / (2 r); or give reynolds and prandtl"),
        "reynolds": Key(float, _within(0.0, 1e6), False, doc="Re of Whitaker's correlation (with prandtl)"),
        "prandtl": Key(float, _within(1e-3, 1e5), False, doc="Pr of Whitaker's correlation (with reynolds)"),
    },
    "radiation": {
        "environment_temperature": Key(float, TEMPERATURE, True, "K", doc="T_E of the surroundings"),
        "emissivity": Key(float, FRACTION, True, doc="epsilon"),
    },
    "physics": {
        "mechanics": Key(bool, None, False, default=False,
                         doc="true: the coupled thermo-mechanical step (Quintana-Ruiz & Campello 2020, Eqs. 43-46): "
                             "particles move under Hertz contacts, friction, rolling resistance, gravity and the "
                             "walls, "
                             "and heat flows through the contacts the motion opens and grows; needs [mechanics]. "
                             "false: the packing stays put (the fast thermal path)"),
        "gravity": Key(list, ("a list of 3 numbers in [-1000, 1000] m/s^2", lambda v: True), False, "m/s^2",
                       default=[0.0, 0.0, -9.81], doc="acceleration of gravity (with mechanics)"),
        "shear": Key(str, _choice("paper", "mindlin"), False, default="paper",
                     doc="effective shear modulus G*: the paper's Eq. 9 or Mindlin's 1/G* = sum (2 - nu)/G"),
        "slip_direction": Key(str, _choice("trial", "velocity"), False, default="trial",
                              doc="direction of a slipping friction force: along the trial force (LAMMPS) or the "
                                  "sliding velocity (MECHANICS.md erratum 3)"),
        "rolling_projection": Key(bool, None, False, default=False,
                                  doc="roll on the tangential part of the relative spin only (LAMMPS sds; erratum 5)"),
        "damping_clamp": Key(bool, None, False, default=False,
                             doc="no tensile normal force while a contact opens (LAMMPS limit_damping)"),
        "skin": Key(float, _within(0.0, 10.0, low_open=True), False, "largest radii", default=0.1,
                    doc="Verlet skin of the contact list; it is rebuilt once a particle moved half of it"),
        "impact_velocity": Key(float, _within(0.0, 1e3, "m/s", low_open=True), False, "m/s", default=0.05,
                               doc="largest approach speed of two particles (or of a particle and a wall, beyond the "
                                   "wall's own speed) the automatic time step is sized for (Eq. 47 and MECHANICS.md "
                                   "erratum 8); a faster contact stops the run"),
    },
    "mechanics": {
        "young_modulus": Key(float, _parameter("E0"), True, "Pa",
                             doc="E0, Young's modulus (below the softening onset)"),
        "poisson_ratio": Key(float, _parameter("nu"), True, doc="nu"),
        "friction": Key(float, _parameter("mu"), False, default=0.0,
                        doc="mu, Coulomb friction between particles (Eq. 8); > 0 turns Mindlin friction on"),
        "rolling_friction": Key(float, _parameter("mu_r"), False, default=0.0,
                                doc="mu_r, rolling resistance between particles (Eq. 16); > 0 turns it on"),
        "wall_friction": Key(float, _parameter("mu_wall"), False, default="friction",
                             doc="mu against every wall"),
        "wall_rolling_friction": Key(float, _parameter("mu_r_wall"), False, default="rolling_friction",
                                     doc="mu_r against every wall"),
        "damping": Key(float, _parameter("xi_con"), False, default=1.0,
                       doc="xi_con, normal damping ratio (Eq. 6; 1 critical for the linearised contact); or give "
                           "restitution"),
        "restitution": Key(float, _within(0.0, 1.0, low_open=True), False,
                           doc="coefficient of restitution e instead of damping: xi_con = sqrt(5/6) beta, "
                               "beta = -ln e / sqrt(pi^2 + ln^2 e) (Tsuji's form, as LAMMPS)"),
        "tangential_damping": Key(float, _parameter("xi_fric"), False, default=1.0, doc="xi_fric (Eq. 11)"),
        "rolling_damping": Key(float, _parameter("xi_rol"), False, default=0.0, doc="xi_rol (Eq. 18)"),
    },
    "softening": {
        "onset_temperature": Key(float, _parameter("theta_star"), True, "K",
                                 doc="theta*, where softening starts (Eq. 42)"),
        "rate": Key(float, _parameter("rate"), False, default=1.0,
                    doc="r of E = max(E_min, E0 exp(min(0, r (1 - theta/theta*)))) (MECHANICS.md erratum 6; "
                        "1: the printed Eq. 42)"),
        "min_modulus": Key(float, _parameter("E_min"), False, "Pa", default=0.0,
                           doc="E_min, the floor (at most mechanics.young_modulus)"),
    },
    "sintering": {
        "law": Key(str, _choice(*sorted(KINETIC_LAWS)), False, default="grain_boundary",
                   doc="kinetic law of the necks (sintercond.sintering): grain_boundary (Bouvard & McMeeking; "
                       "Nosewicz et al. 2013), power_law (d(a^n)/dt = K0 exp(-Q/RT) (r*/r_ref)^p) or viscous "
                       "(Frenkel)"),
        "every": Key(int, _within(1, 1e6), False, "steps", default=1,
                     doc="thermal steps between two neck updates; each grows the necks over those steps at the "
                         "mean of the pair temperatures at their start and end"),
        "params": Key(dict, None, False, default="the law's",
                      doc="the kinetic law's parameters, see [sintering.params]"),
        "k_star_axis": Key(int, _choice(0, 1, 2), False,
                           doc="history.csv gains k_star_W_mK: the effective conductivity along this axis from a "
                               "steady solve on the grown necks at each output (sintercond.steady, the face "
                               "layers of the packing held hot and cold), each particle at its conductivity "
                               "(material.conductivity_table at its temperature, or material.conductivity)"),
    },
    "preheating": {
        "end_temperature": Key(float, TEMPERATURE, True, "K", doc="the temperature the held particles reach"),
        "duration": Key(float, _within(0.0, 1e6, "s", low_open=True), True, "s", doc="the ramp's duration"),
        "steps": Key(int, _within(1, 1e6), False, default=25,
                     doc="equal steps of the ramp (25: Rizza & Galati 2024's Eq. 6), each held at the temperature "
                         "it ends at"),
        "hold": Key(str, _choice("walls", "all"), False, default="walls",
                    doc="walls: the particles of the held walls follow the ramp from the wall's temperature; all: "
                        "every particle is held and follows it from initial.temperature (an isothermal cell, as "
                        "Rizza & Galati's REVs)"),
    },
    "run": {
        "duration": Key(float, _within(0.0, 1e6, "s", low_open=True), True, "s",
                        doc="simulated time; the run ends exactly there"),
        "dt": Key(object, ('"auto" or a number in (0, 1e3] s', lambda v: v == "auto" or (
            not isinstance(v, (bool, str)) and isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 1e3)),
            False, "s", default="auto", doc='explicit step; "auto" = 0.9 x the stable step'),
        "output_every": Key(int, _within(1, 1e9), True, "steps", doc="steps between output frames"),
        "checkpoint_every": Key(int, _within(1, 1e9), True, "steps",
                                doc="steps between checkpoints, a multiple of output_every"),
        "formats": Key(list, ("a non-empty list of distinct names from ['lammps', 'vtp']", lambda v: True), False,
                       default=["vtp"],
                       doc='non-empty list of distinct "vtp" (ParaView) and "lammps" (OVITO)'),
        "contact_network": Key(bool, None, False, default=False,
                               doc="true: with vtp, each output also writes the contact network, vtp/network_*.vtp "
                                   "(network.pvd): a line per contact carrying its neck_radius (m), conductance "
                                   "(W/K) and heat_flow (W, from its lower to its higher index)"),
        "vtp_encoding": Key(str, _choice("binary", "ascii"), False, default="binary",
                            doc="binary: point data appended and zlib-compressed (VTK's own layout); ascii: text"),
        "override_limits": Key(bool, None, False, default=False,
                               doc="true lifts the limits on steps, frames and output bytes (MAX_STEPS, "
                                   "MAX_FRAMES, MAX_OUTPUT_BYTES)"),
    },
}
_PACKING = {
    "powder_bed": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "lateral_size": Key(float, _within(1e-7, 1.0, "m"), True, "m", doc="side of the square container"),
        "height": Key(float, _within(1e-7, 1.0, "m"), True, "m",
                      doc="bed height to fill, >= the largest diameter; the bed holds 0.62 of this volume"),
        "diameter_range": Key(list, ("a list [low, high] of numbers in [1e-08, 1] m", lambda v: True), True, "m",
                              doc="[low, high] diameters, uniform by volume, 1e-8 <= low <= high < lateral_size"),
        "seed": Key(int, _within(0, 2**63 - 1), False, default=0, doc="random seed"),
        "method": Key(str, _choice(*PACKING_METHODS), False, default="relax",
                      doc="how the bed is made: relax (spheres dropped and relaxed with harmonic repulsion, "
                          "sintercond.packing.powder_bed) or dem (poured and settled with the contact laws of "
                          "the [mechanics] section, which it then needs; sintercond.packing.pour; SI units)"),
        "sinter_swelling": Key(float, _within(0.0, 0.05), False, default=0.0,
                               doc="relative radius increase after settling that turns contacts into sintered "
                                   "necks (overlap h = 2 r s for equal spheres)"),
    },
    "simple_cubic": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "counts": Key(list, ("a list of 3 integers in [1, 10000]", lambda v: True), True,
                      doc="[nx, ny, nz] spheres per axis, integers >= 1; at most "
                          f"{MAX_LATTICE_PARTICLES} in all"),
        "spacing": Key(float, _within(1e-8, 1.0, "m"), True, "m", doc="centre distance of neighbours"),
        "radius": Key(float, _within(1e-8, 1.0, "m"), True, "m",
                      doc="sphere radius; the lattice conducts only for radius > spacing/2 (overlap "
                          "h = 2 radius - spacing > 0), up to the neck model's largest overlap "
                          "(0.75 spacing for the volume-conserving neck)"),
    },
    "poured": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "particles": Key(int, _within(2, MAX_POURED_PARTICLES), True, doc="number of spheres"),
        "radius_mean": Key(float, _within(1e-6, 0.1, "m"), True, "m", doc="mean of the normal radius distribution"),
        "radius_std": Key(float, _within(0.0, 0.1, "m"), False, "m", default=0.0,
                          doc="standard deviation of the radius distribution (0: equal spheres)"),
        "truncation": Key(float, _within(0.0, 10.0, low_open=True), False, "standard deviations", default=3.0,
                          doc="radii beyond mean +- truncation std are redrawn; every radius must stay > 0"),
        "lateral_size": Key(float, _within(1e-5, 10.0, "m"), True, "m",
                            doc="side of the open square box [0, L]^2 the spheres are poured into, > 2 max radius"),
        "seed": Key(int, _within(0, 2**63 - 1), False, default=0, doc="random seed (radii and the deposit)"),
        "start": Key(str, _choice("relaxed", "deposit"), False, default="relaxed",
                     doc="deposit: the DEM collapses the loose pile itself (a real pour); relaxed: the pile is "
                         "first collapsed without friction, then the DEM settles it (cheaper, denser)"),
    },
    "file": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "path": Key(str, ("a file name", lambda v: bool(v)), True,
                    doc="the packing's file, relative to the scene file's folder (or absolute); no particle cap"),
        "format": Key(str, _choice("auto", "table", "lammps_data", "lammps_dump"), False, default="auto",
                      doc="table: CSV or whitespace rows x y z r (an optional header naming x, y, z and r, radius, "
                          "d or diameter); lammps_data: atom_style sphere (id type diameter density x y z); "
                          "lammps_dump: a LAMMPS or LIGGGHTS dump's last frame (radius or diameter, x y z); "
                          "auto: from the name (*.data, *.dump, *.lammpstrj, else a table)"),
        "length_unit": Key(str, _choice("m", "mm", "um", "nm"), False, default="m",
                           doc="unit of the file's lengths"),
    },
    "spheres": {
        "kind": Key(str, _choice(*PACKING_KINDS), True, doc="the packing"),
        "centres": Key(list, (f"a list of at most {MAX_LISTED_SPHERES} [x, y, z] points (m)", lambda v: True), True,
                       "m", doc="sphere centres in absolute coordinates"),
        "radii": Key(object, ("a number in [1e-08, 1] m or a list of them, one per centre", lambda v: True), True,
                     "m", doc="one radius for all, or one per centre"),
    },
}
_WALL = {
    "axis": Key(int, _choice(0, 1, 2), True, doc="normal axis of the wall"),
    "side": Key(str, _choice("min", "max"), True, doc="which face of the packing"),
    "mode": Key(str, _choice("held", "conducting", "insulated"), True,
                doc="held: touching particles held at temperature; conducting: they exchange heat with a wall "
                    "at temperature through the conduction law (a sphere 1000 x the largest radius); "
                    "insulated: no flux (the default of any face)"),
    "temperature": Key(float, TEMPERATURE, False, "K", doc="wall temperature (required unless insulated)"),
    "penetration": Key(float, _within(0.0, 0.2), False, "mean radii", default=0.02,
                       doc="the wall plane lies at the packing's extreme along the axis moved this many mean "
                           "radii into the packing: the particles it cuts touch the wall (with mechanics, 0 places "
                           "it touching without pushing); 0.1 on a powder bed, whose face layer spreads over about "
                           "a tenth of a radius; the run reports how many particles each wall touches"),
    "velocity": Key(list, ("a list of 3 numbers in [-1000, 1000] m/s", lambda v: True), False, "m/s",
                    default=[0.0, 0.0, 0.0],
                    doc="with mechanics: the wall moves at this velocity (its plane along its normal component, "
                        "its surface rubbing along the rest)"),
}
# the laws' parameters in a scene: physical ranges (the API only requires them finite, > 0 or >= 0)
_LAW_PARAMS = {
    "slope": Key(float, _within(0.0, 100.0, low_open=True), False, doc="s of K_i = s kappa pi a (Rojek Eq. 43)"),
    "contact_resistance": Key(float, _within(0.0, 1e12, "K/W"), False, "K/W", default=0.0,
                              doc="R_c in series with the halves (Rojek Eq. 8)"),
    "thickness": Key(float, _within(0.0, 1e3, "m", low_open=True), False, "m", default=1.0,
                     doc="out-of-plane thickness of Feng's 2-D law"),
    **{c: Key(float, _within(-1e3, 1e3), False, doc="coefficient of the fitted smooth law")
       for c in ("c1", "c2", "c3", "c4")},
}
# the kinetic laws' parameters in a scene: physical ranges
_SINTERING_PARAMS = {
    "A": Key(float, _within(0.0, 1e6, "m^4 K/s", low_open=True), False, "m^4 K/s",
             doc="Omega delta_b D_0b gamma_s / k_B of the grain-boundary law (sintercond.sintering.grain_boundary_a)"),
    "activation_energy": Key(float, _within(0.0, 1e4, "kJ/mol"), False, "kJ/mol", doc="Q of exp(-Q / (R T))"),
    "dihedral_angle": Key(float, _within(0.0, 180.0, "degrees", low_open=True), False, "degrees",
                          doc="psi; the grain-boundary neck stops at the equilibrium neck r_min sin(psi/2)"),
    "K0": Key(float, _within(0.0, 1e300, "m^n/s", low_open=True), False, "m^n/s", doc="K0 of the power law"),
    "exponent": Key(float, _within(0.0, 20.0, low_open=True), False, doc="n of the power law (6 grain boundary, "
                                                                         "5 volume, 2 viscous)"),
    "size_exponent": Key(float, _within(-20.0, 20.0), False, doc="p of the power law's (r*/r_ref)^p"),
    "reference_radius": Key(float, _within(0.0, 1.0, "m", low_open=True), False, "m", doc="r_ref of the power law"),
    "max_neck_ratio": Key(float, _within(0.0, 1.0, low_open=True), False,
                          doc="the power law's and viscous flow's neck stops at this fraction of min(r_i, r_j)"),
    "surface_energy": Key(float, _within(0.0, 100.0, "N/m", low_open=True), False, "N/m",
                          doc="gamma_s of viscous flow"),
    "viscosity": Key(float, _within(0.0, 1e30, "Pa s", low_open=True), False, "Pa s",
                     doc="eta0 of viscous flow, eta = eta0 exp(Q / (R T))"),
}
_SECTIONS = ("packing", "material", "conduction", "initial", "boundary", "walls", "beam", "convection", "radiation",
             "physics", "mechanics", "softening", "sintering", "preheating", "run")
_REQUIRED_SECTIONS = ("packing", "material", "conduction", "initial", "run")


def _suggest(name, allowed):
    close = difflib.get_close_matches(name, allowed, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _describe(key: Key) -> str:
    kind = {float: "a number", int: "an integer", str: "a string", bool: "true or false", list: "a list",
            dict: "a table", object: "a value"}[key.kind]
    if key.rule is None:
        return kind
    return key.rule[0] if key.kind in (str, object, list) or key.rule[0].startswith("one of") else f"{kind} {key.rule[0]}"


def _value(name, value, key: Key):
    """``value`` checked against ``key``; raises :class:`SceneError` naming ``name`` and the range."""
    if key.kind is float:
        ok = not isinstance(value, bool) and isinstance(value, (int, float))
        value = float(value) if ok else value
        ok = ok and math.isfinite(value)
    elif key.kind is int:
        ok = not isinstance(value, bool) and isinstance(value, int)
    elif key.kind is object:
        ok = True
    else:
        ok = isinstance(value, key.kind)
    if not ok or (key.rule is not None and not key.rule[1](value)):
        raise SceneError(f"{name} must be {_describe(key)}; got {value!r}")
    return value


def _check_keys(name, table, schema):
    for key in table:
        if key not in schema:
            raise SceneError(f"unknown key {name}.{key}{_suggest(key, schema)}; allowed keys: {sorted(schema)}")


def _check_section(name, table, schema):
    if not isinstance(table, dict):
        raise SceneError(f"[{name}] must be a table of keys {sorted(schema)}; got {table!r}")
    _check_keys(name, table, schema)
    out = {key: _value(f"{name}.{key}", table[key], spec) for key, spec in schema.items() if key in table}
    for key, spec in schema.items():
        if key not in table and spec.required:
            raise SceneError(f"missing key {name}.{key} ({_describe(spec)})")
    return out


def validate_scene(raw: dict) -> dict:
    """Check a parsed scene and return it with numbers normalised and its defaults filled; raises :class:`SceneError`.

    Everything is checked here, before any packing or network is built:
    keys, types and ranges, combinations (beam path over the packing,
    lattice overlap within the neck model's domain, bed size), and the work
    of the run estimated from the scene (particles, steps, frames, output
    bytes, memory) against the limits above.
    """
    if not isinstance(raw, dict):
        raise SceneError("a scene must be a TOML table")
    for name in raw:
        if name not in _SECTIONS:
            raise SceneError(f"unknown section [{name}]{_suggest(name, _SECTIONS)}; allowed sections: "
                             f"{sorted(_SECTIONS)}")
    for name in _REQUIRED_SECTIONS:
        if name not in raw:
            raise SceneError(f"missing section [{name}] (required: {list(_REQUIRED_SECTIONS)})")
    scene = {name: _check_section(name, raw[name], schema) for name, schema in _SCHEMA.items() if name in raw}
    packing = raw["packing"]
    kind = packing.get("kind") if isinstance(packing, dict) else None
    if kind not in _PACKING:
        if isinstance(packing, dict):  # a misspelt key (kindx = ...) is named before the kind it hides
            _check_keys("packing", packing, {key: None for schema in _PACKING.values() for key in schema})
        raise SceneError(f"packing.kind must be one of {sorted(_PACKING)}; got {kind!r}")
    scene["packing"] = _check_section("packing", packing, _PACKING[kind])
    walls = raw.get("walls", [])
    if not isinstance(walls, list):
        raise SceneError(f"walls must be an array of tables ([[walls]]) with keys {sorted(_WALL)}; got {walls!r}")
    scene["walls"] = [_check_section(f"walls[{k}]", w, _WALL) for k, w in enumerate(walls)]
    for k, wall in enumerate(scene["walls"]):
        if wall["mode"] != "insulated" and "temperature" not in wall:
            raise SceneError(f"walls[{k}].temperature is required for a {wall['mode']} wall "
                             f"({_describe(_WALL['temperature'])})")
        if "velocity" in wall:
            wall["velocity"] = _numbers(f"walls[{k}].velocity", wall["velocity"], 3, _within(-1e3, 1e3, "m/s"))
    _check_mechanics(scene)
    _fill_defaults(scene)
    _check_details(scene)
    estimate_run(scene)
    return scene


# keys whose default holds only without another key (given instead), or only with mechanics
_ALTERNATIVES = {("mechanics", "damping"): "restitution", ("convection", "nusselt"): "reynolds"}
_MECHANICAL_ONLY = {("physics", key) for key in _SCHEMA["physics"] if key != "mechanics"}


def _default_of(section, key, spec: Key, table, on):
    """The value ``spec`` declares for a missing key (None: no default to fill): a literal the key's own rule
    accepts, or the value of the key its default names (``mechanics.wall_friction`` defaults to
    ``mechanics.friction``); a default that needs another key absent, or mechanics on, only then."""
    if spec.default is None or (section, key) in _ALTERNATIVES and _ALTERNATIVES[section, key] in table:
        return None
    if (section, key) == ("walls", "penetration"):  # computed from the packing: default_penetration
        return None
    if (section, key) in _MECHANICAL_ONLY and not on:
        return None
    if isinstance(spec.default, str) and spec.kind is float:
        return table.get(spec.default)  # a reference, itself filled first (the schema lists it before)
    try:
        return _value(f"{section}.{key}", copy.deepcopy(spec.default), spec)
    except SceneError:  # a description ("the law's"): computed where it is used
        return None


def _fill_defaults(scene):
    """Fill every missing key of the sections present with the default its :class:`Key` declares, once, so that
    the run reads ``scene[section][key]`` and no code restates a default. Run after the checks of what was
    given; the filled scene validates again as it is (``scene.json``, read back by ``--resume``)."""
    on = scene["physics"].get("mechanics", False)
    tables = [(name, scene[name], _SCHEMA[name]) for name in _SCHEMA if name in scene]
    tables.append(("packing", scene["packing"], _PACKING[scene["packing"]["kind"]]))
    tables += [("walls", wall, _WALL) for wall in scene["walls"]]
    for section, table, schema in tables:
        for key, spec in schema.items():
            if key not in table:
                value = _default_of(section, key, spec, table, on)
                if value is not None:
                    table[key] = value
    penetration = default_penetration(scene)  # with the packing's method filled
    for wall in scene["walls"]:
        wall.setdefault("penetration", penetration)


ROUGH_BED_PENETRATION = 0.1
"""``walls[k].penetration`` (mean radii) on a powder bed settled by relaxation without mechanics: the face layer of
such a bed spreads over about a tenth of a radius, so the schema's 0.02 touches only the particles that stick out."""


def default_penetration(scene) -> float:
    """``walls[k].penetration`` where the scene gives none (mean radii): :data:`ROUGH_BED_PENETRATION` on a relaxed
    powder bed without mechanics, else the schema's default."""
    p = scene["packing"]
    rough = p["kind"] == "powder_bed" and p["method"] != "dem" and not scene["physics"]["mechanics"]
    return ROUGH_BED_PENETRATION if rough else _WALL["penetration"].default


def _numbers(name, value, length, rule, integer=False):
    what = "integers" if integer else "numbers"
    if not isinstance(value, list) or len(value) != length:
        raise SceneError(f"{name} must be a list of {length} {what} {rule[0]}; got {value!r}")
    for v in value:
        bad_type = isinstance(v, bool) or not isinstance(v, int if integer else (int, float))
        if bad_type or not math.isfinite(v) or not rule[1](v):
            raise SceneError(f"{name} must be a list of {length} {what} {rule[0]}; got {value!r}")
    return [int(v) if integer else float(v) for v in value]


def _lateral_extent(packing):
    """``((x_lo, x_hi), (y_lo, y_hi))`` (m) of the packing, from the scene alone."""
    if packing["kind"] in ("powder_bed", "poured"):  # both fill the square [0, L]^2
        return (0.0, packing["lateral_size"]), (0.0, packing["lateral_size"])
    if packing["kind"] == "spheres":
        c, r = packing["centres"], packing["radii"]
        return tuple((min(p[k] - q for p, q in zip(c, r)), max(p[k] + q for p, q in zip(c, r))) for k in (0, 1))
    if packing["kind"] == "file":
        c, r = file_packing(packing)
        return tuple((float(np.min(c[:, k] - r)), float(np.max(c[:, k] + r))) for k in (0, 1))
    nx, ny, _ = packing["counts"]
    return ((0.0, (nx - 1) * packing["spacing"] + 2 * packing["radius"]),
            (0.0, (ny - 1) * packing["spacing"] + 2 * packing["radius"]))


def file_packing(packing):
    """``(centres, radii)`` (m) of a ``kind = "file"`` packing (:func:`sintercond.packing_files.read_packing`, read
    once per file version); a file that cannot be read raises :class:`SceneError` naming ``packing.path``."""
    from sintercond.packing_files import PackingFileError, read_packing

    try:
        return read_packing(packing["path"], packing.get("format", "auto"), packing.get("length_unit", "m"))
    except PackingFileError as err:
        raise SceneError(f"packing.path: {err}") from None


def restitution_damping_ratio(e):
    """Normal damping ratio ``xi_con`` (Eq. 6) of a restitution coefficient ``e`` in (0, 1].

    ``xi = sqrt(5/6) beta`` with ``beta = -ln e / sqrt(pi^2 + ln^2 e)``: the
    ``delta^(1/4)`` (Tsuji) damping LAMMPS' ``hertz/material`` derives from
    ``e`` (MECHANICS.md, "What users comparing with LAMMPS will see"); it
    makes the paper's ``d_con = 2 xi sqrt(2 E* m* sqrt(r*)) delta^(1/4)``
    equal LAMMPS' ``2 sqrt(5/6) beta sqrt(k_n m*)``, ``k_n = 2 E* sqrt(r* delta)``.
    ``e = 1``: 0 (elastic).
    """
    log_e = math.log(e)
    return math.sqrt(5.0 / 6.0) * -log_e / math.sqrt(math.pi**2 + log_e**2)


def _check_mechanics(scene):
    """The thermo-mechanical sections: [mechanics] and [softening] only with physics.mechanics, combinations."""
    physics = scene.setdefault("physics", {})
    on = physics.get("mechanics", False)
    packing = scene["packing"]
    pours = packing["kind"] == "poured" or packing.get("method") == "dem"
    if pours and "mechanics" not in scene:
        raise SceneError("a poured packing (packing.kind = \"poured\" or packing.method = \"dem\") needs a [mechanics] "
                         "section: the contact material it is poured with (at least mechanics.young_modulus and "
                         "mechanics.poisson_ratio)")
    for section in ("mechanics", "softening"):
        if section == "mechanics" and pours:
            continue
        if section in scene and not on:
            raise SceneError(f"[{section}] needs physics.mechanics = true (the packing moves); without it the run is "
                             "thermal only: drop the section or set physics.mechanics = true")
    for k, wall in enumerate(scene["walls"]):
        if "velocity" in wall and any(wall["velocity"]) and not on:
            raise SceneError(f"walls[{k}].velocity needs physics.mechanics = true (a wall moves only with mechanics)")
    if "gravity" in physics:
        physics["gravity"] = _numbers("physics.gravity", physics["gravity"], 3, _within(-1e3, 1e3, "m/s^2"))
    if not on:
        for key in physics:
            if key != "mechanics":
                raise SceneError(f"physics.{key} needs physics.mechanics = true (without it nothing moves and "
                                 f"physics.{key} would be ignored)")
        return
    if "mechanics" not in scene:
        raise SceneError("physics.mechanics = true needs a [mechanics] section (the contact material: at least "
                         f"mechanics.young_modulus ({_describe(_SCHEMA['mechanics']['young_modulus'])}) and "
                         f"mechanics.poisson_ratio ({_describe(_SCHEMA['mechanics']['poisson_ratio'])}))")
    m = scene["mechanics"]
    if "restitution" in m and "damping" in m:
        raise SceneError("give mechanics.damping or mechanics.restitution, not both (restitution sets the damping)")
    # the Python API's rules on the values the scene gives (ranges, as the keys', and E_min <= E0)
    given = {}
    for key, field in MECHANICAL_FIELDS.items():
        section, name = key.split(".")
        if name in scene.get(section, {}):
            given[field] = scene[section][name]
    try:
        validate_mechanical_params(given, names={field: key for key, field in MECHANICAL_FIELDS.items()})
    except ValueError as err:
        raise SceneError(str(err)) from None


def _check_packing(packing, conduction, sintering=False):
    from sintercond import neck
    from sintercond.packing import PackingError, check_bed

    if packing["kind"] == "file":
        packing["path"] = str(Path(packing["path"]).resolve())  # scene.json then finds it from anywhere
        file_packing(packing)  # read (once) and checked now: a bad file is named before anything is built
        return
    if packing["kind"] == "spheres":
        centres, radii = packing["centres"], packing["radii"]
        rule = ("a list of 3 numbers in [-1, 1] m", lambda v: -1.0 <= v <= 1.0)
        if not centres or len(centres) > MAX_LISTED_SPHERES:
            raise SceneError(f"packing.centres must be {_describe(_PACKING['spheres']['centres'])}; got "
                             f"{len(centres)} points")
        packing["centres"] = [_numbers(f"packing.centres[{k}]", c, 3, rule) for k, c in enumerate(centres)]
        radius_rule = _within(1e-8, 1.0, "m")
        if not isinstance(radii, list):
            radii = [radii] * len(centres)
        packing["radii"] = _numbers("packing.radii", radii, len(centres), radius_rule)
        return
    if packing["kind"] == "poured":
        from sintercond.packing import check_radius_distribution

        try:
            check_radius_distribution(packing["radius_mean"], packing["radius_std"], packing["truncation"])
        except PackingError as err:
            raise SceneError(f"packing: {err}") from None
        largest = packing["radius_mean"] + packing["truncation"] * packing["radius_std"]
        if not packing["lateral_size"] > 2 * largest:
            raise SceneError(f"packing.lateral_size must be > the largest diameter {2 * largest:g} m "
                             f"(2 (radius_mean + truncation radius_std)); got {packing['lateral_size']:g}")
        return
    if packing["kind"] == "powder_bed":
        packing["diameter_range"] = _numbers("packing.diameter_range", packing["diameter_range"], 2,
                                             _within(1e-8, 1.0, "m"))
        try:
            check_bed(packing["lateral_size"], packing["height"], packing["diameter_range"],
                      names={k: f"packing.{k}" for k in ("lateral_size", "height", "diameter_range")})
        except PackingError as err:
            raise SceneError(str(err)) from None
        return
    packing["counts"] = _numbers("packing.counts", packing["counts"], 3, _within(1, 10_000), integer=True)
    n = math.prod(packing["counts"])
    if n > MAX_LATTICE_PARTICLES:
        raise SceneError(f"packing.counts {packing['counts']} make {n} particles; the limit is "
                         f"{MAX_LATTICE_PARTICLES} (product of the counts)")
    radius, spacing = packing["radius"], packing["spacing"]
    if sintering and radius == spacing / 2:
        return  # point contacts: the necks grow from them
    if not radius > spacing / 2:
        raise SceneError(f"packing.radius must be > packing.spacing/2 = {spacing / 2:g} m for the lattice to conduct "
                         f"(touching spheres have no neck); got {radius:g}")
    model = conduction.get("neck_model", CONDUCTANCE_LAWS[conduction["law"]].neck_model)
    try:
        neck.validate_neck_inputs(radius, radius, 2 * radius - spacing, model=model,
                                  names=("packing.radius", "packing.radius", "the overlap 2 packing.radius - "
                                         "packing.spacing"))
    except ValueError as err:
        raise SceneError(f"{err} ({model} neck of conduction.law {conduction['law']!r}; packing.radius must be in "
                         f"(spacing/2, {_largest_lattice_radius(model, spacing):g}] m)") from None


def _largest_lattice_radius(model, spacing):
    # equal spheres: h_max = 2r/3 (volume-conserving), h < 2r (intersection), any h (Coble, Hertz)
    return {"volume_conserving": 0.75 * spacing}.get(model, spacing)


def _check_sintering(scene):
    """``[sintering]``: its law's parameters, and the physics the first stage grows necks on; ``[preheating]``."""
    if "preheating" in scene:
        ramp = scene["preheating"]
        if ramp["hold"] == "walls" and not any(w["mode"] == "held" for w in scene["walls"]):
            raise SceneError("[preheating] with preheating.hold = \"walls\" ramps the held walls: give a held "
                             "[[walls]] (or boundary.floor_temperature), or preheating.hold = \"all\"")
        if scene["physics"]["mechanics"]:
            raise SceneError("[preheating] needs physics.mechanics = false in this version")
    if "sintering" not in scene:
        return
    s, conduction = scene["sintering"], scene["conduction"]
    law = KINETIC_LAWS[s["law"]]
    params = s.get("params", {})
    for key, value in params.items():
        if key not in law.default_params:
            raise SceneError(f"unknown key sintering.params.{key}{_suggest(key, list(law.default_params))}; "
                             f"kinetic law {law.name!r} takes {sorted(law.default_params)}")
        params[key] = _value(f"sintering.params.{key}", value, _SINTERING_PARAMS[key])
    if scene["physics"]["mechanics"]:
        raise SceneError("[sintering] grows necks on a packing that does not move (the first stage): it needs "
                         "physics.mechanics = false")
    model = conduction.get("neck_model", CONDUCTANCE_LAWS[conduction["law"]].neck_model)
    if model != "volume_conserving":
        raise SceneError(f"[sintering] grows Rojek's volume-conserving necks: conduction.neck_model must be "
                         f"\"volume_conserving\" (conduction.law {conduction['law']!r} takes {model!r})")


def _check_conductivity_table(material):
    table = material.get("conductivity_table")
    if table is None:
        return
    rule = _SCHEMA["material"]["conductivity_table"].rule[0]
    if len(table) < 2:
        raise SceneError(f"material.conductivity_table must be {rule}; got {table!r}")
    rows = [_numbers(f"material.conductivity_table[{k}]", row, 2, ("a [T, kappa] pair of positive numbers",
                                                                     lambda v: 0 < v <= 1e5)) for k, row in
            enumerate(table)]
    temperatures, values = zip(*rows)
    if any(b <= a for a, b in zip(temperatures, temperatures[1:])) or not all(1e-6 <= v <= 1e4 for v in values):
        raise SceneError(f"material.conductivity_table must be {rule}; got {table!r}")
    material["conductivity_table"] = [list(r) for r in rows]


def _check_details(scene):
    _check_conductivity_table(scene["material"])
    conduction = scene["conduction"]
    law = CONDUCTANCE_LAWS[conduction["law"]]
    params = conduction.get("params", {})
    for key, value in params.items():
        if key not in law.default_params:
            raise SceneError(f"unknown key conduction.params.{key}{_suggest(key, list(law.default_params))}; "
                             f"law {law.name!r} takes {sorted(law.default_params)}")
        params[key] = _value(f"conduction.params.{key}", value, _LAW_PARAMS[key])
    _check_sintering(scene)
    _check_packing(scene["packing"], conduction, "sintering" in scene)
    if "beam" in scene:
        beam = scene["beam"]
        needed = "attenuation" if beam["kind"] == "laser" else "max_depth"
        if needed not in beam:
            raise SceneError(f"beam.{needed} is required for a {beam['kind']} beam "
                             f"({_describe(_SCHEMA['beam'][needed])})")
        if ("intensity" in beam) == ("power" in beam):
            raise SceneError("give beam.intensity (W/m^2) or beam.power (W), one of them")
        if "power" in beam:
            beam["intensity"] = beam.pop("power") / (math.pi * beam["spot_radius"] ** 2)
            low = _SCHEMA["beam"]["intensity"].rule[0]
            if not _SCHEMA["beam"]["intensity"].rule[1](beam["intensity"]):
                raise SceneError(f"beam.power over the spot (pi beam.spot_radius^2) gives an intensity of "
                                 f"{beam['intensity']:.4g} W/m^2; it must be {low}")
        path = beam["path"]
        if not path or any(not isinstance(p, list) for p in path):
            raise SceneError(f"beam.path must be a non-empty list of [x, y] points (m); got {path!r}")
        (x0, x1), (y0, y1) = _lateral_extent(scene["packing"])
        reach = beam["spot_radius"]
        rule = (f"within the packing's lateral extent [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m widened by "
                f"beam.spot_radius", lambda v: True)
        beam["path"] = [_numbers(f"beam.path[{k}]", p, 2, rule) for k, p in enumerate(path)]
        for k, (x, y) in enumerate(beam["path"]):
            if not (x0 - reach <= x <= x1 + reach and y0 - reach <= y <= y1 + reach):
                raise SceneError(f"beam.path[{k}] = {[x, y]} must be {rule[0]} (beam coordinates are absolute)")
        on = beam.get("segments_on")
        if on is not None and (not isinstance(on, list) or len(on) != len(path) - 1
                               or any(not isinstance(v, bool) for v in on)):
            raise SceneError(f"beam.segments_on must be a list of {len(path) - 1} booleans (true or false), one per "
                             f"segment of beam.path; got {on!r}")
    convection = scene.get("convection", {})
    if ("reynolds" in convection) != ("prandtl" in convection):
        raise SceneError("convection.reynolds and convection.prandtl go together (Whitaker's correlation)")
    if "reynolds" in convection and "nusselt" in convection:
        raise SceneError("give convection.nusselt or convection.reynolds and prandtl, not both")
    run = scene["run"]
    run["dt"] = run["dt"] if run["dt"] == "auto" else float(run["dt"])
    if run["checkpoint_every"] % run["output_every"]:
        raise SceneError(f"run.checkpoint_every ({run['checkpoint_every']}) must be a multiple of "
                         f"run.output_every ({run['output_every']})")
    formats = run["formats"]
    allowed = ("lammps", "vtp")
    if (not formats or any(not isinstance(f, str) or f not in allowed for f in formats)
            or len(set(formats)) != len(formats)):
        raise SceneError(f"run.formats must be a non-empty list of distinct names from {list(allowed)}; "
                         f"got {formats!r}")
    run["formats"] = list(formats)


class RunEstimate(NamedTuple):
    """What a scene will cost, estimated before anything is built (order of magnitude for steps)."""

    particles: int
    dt: float  # s: run.dt, or 0.9 x an estimate of the stable step
    steps: int
    frames: int
    output_bytes: float
    memory_bytes: float


def estimate_run(scene) -> RunEstimate:
    """Estimate particles, step, steps, frames, output bytes and memory of a validated scene; refuse beyond limits.

    The stable step is estimated as ``C / (z K + G)`` for the smallest
    particle: ``C = rho c (4/3) pi r^3``, ``z`` = 12 neighbours (6 in a
    simple-cubic lattice) plus one wall, ``K = kappa pi a`` with Coble's neck
    ``a = sqrt(r h)`` (an upper bound on the necks of every law's default
    model but Feng's 2-D law, which takes ``thickness`` instead), and ``G``
    the linearised convection ``2 pi Nu k_E r`` and radiation
    ``16 pi eps sigma T^3 r^2`` at the highest temperature the scene names.
    """
    from sintercond.heat_sources import STEFAN_BOLTZMANN
    from sintercond.packing import bed_particle_count

    packing, material, run = scene["packing"], scene["material"], scene["run"]
    if packing["kind"] == "spheres":
        n, r = len(packing["radii"]), min(packing["radii"])
        h, z = 2 * r * 1e-3, 13
    elif packing["kind"] == "file":
        radii = file_packing(packing)[1]
        n, r = len(radii), float(np.min(radii))
        h, z = 2 * r * 1e-3, 13
    elif packing["kind"] == "poured":
        n = packing["particles"]
        r = max(packing["radius_mean"] - packing["truncation"] * packing["radius_std"],
                1e-3 * packing["radius_mean"])
        h, z = 2 * r * 1e-3, 13
    elif packing["kind"] == "powder_bed":
        n = bed_particle_count(packing["lateral_size"], packing["height"], packing["diameter_range"])
        r = packing["diameter_range"][0] / 2
        h, z = 2 * r * max(packing["sinter_swelling"], 1e-3), 13
    else:
        n = math.prod(packing["counts"])
        r = packing["radius"]
        h, z = 2 * r - packing["spacing"], 7
    if "sintering" in scene:
        h = r  # the necks grow up to about the radius, a = sqrt(r h): the step is taken on them
    kappa = max([material["conductivity"]] + [k for _, k in material.get("conductivity_table", [])])
    law = scene["conduction"]["law"]
    k_pair = kappa * scene["conduction"].get("params", {}).get("thickness", 1.0) * math.pi if law == "feng" else (
        kappa * math.pi * math.sqrt(r * h))
    g = 0.0
    temperatures = [scene["initial"]["temperature"]] + [w["temperature"] for w in scene["walls"] if "temperature" in w]
    if "convection" in scene:
        c = scene["convection"]
        nusselt = c["nusselt"] if "nusselt" in c else (
            2.0 + (0.4 * c["reynolds"] ** 0.5 + 0.06 * c["reynolds"] ** (2 / 3)) * c["prandtl"] ** 0.4)
        g += 2 * math.pi * nusselt * c["environment_conductivity"] * r
        temperatures.append(c["environment_temperature"])
    if "radiation" in scene:
        temperatures.append(scene["radiation"]["environment_temperature"])
        g += 16 * math.pi * scene["radiation"]["emissivity"] * STEFAN_BOLTZMANN * max(temperatures) ** 3 * r**2
    capacity = material["density"] * material["specific_heat"] * 4 / 3 * math.pi * r**3
    dt = 0.9 * capacity / (z * k_pair + g)
    if scene["physics"]["mechanics"]:
        wall_speed = max((advance_speed(w) for w in scene["walls"]), default=0.0)
        dt = min(dt, 0.9 * _mechanical_step_estimate(scene, r, wall_speed))
        if wall_speed > 0:
            dt = min(dt, 0.9 * WALL_STEP_FRACTION * r / wall_speed)
    if "beam" in scene and beam_step(scene["beam"]) is not None:
        dt = min(dt, 0.9 * beam_step(scene["beam"]))
    dt = dt if run["dt"] == "auto" else run["dt"]
    steps = max(1, math.ceil(run["duration"] / dt))
    frames = steps // run["output_every"] + 1
    per_frame = n * (("vtp" in run["formats"]) * 230 + ("lammps" in run["formats"]) * 140)
    estimate = RunEstimate(n, dt, steps, frames, frames * per_frame, 4e3 * n)
    if estimate.memory_bytes > MAX_MEMORY_BYTES:
        raise SceneError(f"the packing needs about {estimate.memory_bytes / 1e9:.3g} GB ({n} particles); the limit "
                         f"is {MAX_MEMORY_BYTES / 1e9:g} GB: make [packing] smaller")
    if not run["override_limits"]:
        for what, value, limit, advice in (
                ("time steps", steps, MAX_STEPS, "shorten run.duration or raise run.dt"),
                ("output frames", frames, MAX_FRAMES, "raise run.output_every or shorten run.duration"),
                ("bytes of output", estimate.output_bytes, MAX_OUTPUT_BYTES,
                 "raise run.output_every, drop a run.formats entry or shorten run.duration")):
            if value > limit:
                raise SceneError(f"run.duration {run['duration']:g} s with a step of about {dt:.3g} s means about "
                                 f"{value:.3g} {what}; the limit is {limit:g}: {advice}, or set "
                                 f"run.override_limits = true")
    return estimate


WALL_STEP_FRACTION = 0.1
"""A moving wall advances at most this fraction of the smallest radius per automatic step (no tunnelling)."""

BEAM_STEP_FRACTION = 0.2
"""A beam's spot advances at most this fraction of its radius per automatic step (the spot is resolved)."""


def advance_speed(wall) -> float:
    """The speed (m/s) at which a scene wall (``[[walls]]`` table) advances into the packing; 0 if it recedes."""
    inward = 1.0 if wall["side"] == "min" else -1.0
    return max(inward * float(wall["velocity"][wall["axis"]]), 0.0)


def beam_step(beam) -> float | None:
    """The step (s) in which the beam's spot moves :data:`BEAM_STEP_FRACTION` of its radius; None for a spot that
    does not move (no speed, or a path of one point or of coincident points)."""
    path = beam["path"]
    if not beam["speed"] > 0 or all(p == path[0] for p in path):
        return None
    return BEAM_STEP_FRACTION * beam["spot_radius"] / beam["speed"]


def _mechanical_step_estimate(scene, r, wall_speed=0.0):
    """:func:`sintercond.forces.contact_time_step` of two of the smallest spheres meeting at
    ``physics.impact_velocity`` plus ``wall_speed`` (s): Eq. 47 and the symplectic-Euler bounds (erratum 8).

    The estimate :func:`estimate_run` counts steps with; the run's own step
    (:func:`sintercond.mechanics.mechanical_time_step`) takes every listed pair
    and wall (a wall contact is stiffer: about 0.8 of this).
    """
    m, physics = scene["mechanics"], scene["physics"]
    e, nu = m["young_modulus"], m["poisson_ratio"]
    mass = scene["material"]["density"] * 4 / 3 * math.pi * r**3
    friction = m["friction"] > 0 or m["wall_friction"] > 0
    rolling = m["rolling_friction"] > 0 or m["wall_rolling_friction"] > 0
    xi_con = restitution_damping_ratio(m["restitution"]) if "restitution" in m else m["damping"]
    return float(_contact_step(physics["shear"])(
        r, mass, e, nu, physics["impact_velocity"] + wall_speed, xi_con,
        m["tangential_damping"] if friction else 0.0, m["rolling_damping"] if rolling else 0.0))


@functools.cache
def _contact_step(shear):
    """Jitted time step of two equal spheres ``(r, m, E, nu, v, xi_con, xi_fric, xi_rol)`` (one compile, not ~50
    dispatched ops)."""
    import jax

    from sintercond import forces

    def step(r, mass, e, nu, v, xi_con, xi_fric, xi_rol):
        g_star = forces.effective_shear_modulus(e, nu, e, nu, shear)
        return forces.contact_time_step(r / 2, mass / 2, forces.effective_modulus(e, nu, e, nu), g_star, v,
                                       xi_con=xi_con, xi_fric=xi_fric, xi_rol=xi_rol)

    return jax.jit(step)


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
          "A random bed settled under gravity (`sintercond.packing.powder_bed`), at most 20000 particles.")
    table("[packing] kind = \"simple_cubic\"", _PACKING["simple_cubic"],
          "Sphere centres at `radius + spacing * (i, j, k)`.")
    table("[packing] kind = \"poured\"", _PACKING["poured"],
          "Spheres of normally distributed radii poured into an open square box and settled with the DEM "
          "(`sintercond.packing.pour`: Hertz, Mindlin, rolling resistance, gravity, the box walls) with the contact "
          "material of `[mechanics]` and `material.density`; settled means kinetic energy and force balance below "
          "the thresholds the summary reports. Example 5.3's bed (`quintana2020_5_3`).")
    table("[packing] kind = \"file\"", _PACKING["file"],
          "A packing read from a file (a CT scan, a LIGGGHTS or LAMMPS pour, another code): "
          "`sintercond.packing_files`. The particles are used as they are; `sintercond effective` measures k* "
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
          "(`sintercond.mechanics.mechanical_time_step`: Eq. 47 and the tangential and rotational bounds of "
          "MECHANICS.md erratum 8 at the unsoftened modulus and the approach speed `impact_velocity` plus the "
          "fastest wall's normal speed), the step in which a moving wall advances a tenth of the smallest radius, "
          "and the step in which a beam's spot advances a fifth of its radius; a larger `run.dt` is refused, "
          "naming the limit and its key. While it runs, a contact approaching faster than the step was sized for, "
          "or kinetic energy growing beyond what gravity and the initial overlaps can supply, stops the run "
          "naming `physics.impact_velocity`.")
    table("[mechanics]", _SCHEMA["mechanics"],
          "The contact material (Quintana-Ruiz & Campello 2020, Eqs. 2-20), with `physics.mechanics = true`. "
          "Walls are rigid (`E* = E/(1 - nu^2)`).")
    table("[softening]", _SCHEMA["softening"],
          "Thermal softening of Young's modulus (Eq. 42, MECHANICS.md erratum 6), with `physics.mechanics = true`.")
    table("[sintering]", _SCHEMA["sintering"],
          "Necks that grow with each contact's temperature history (`sintercond.neck_growth`; issue 26's first "
          "stage): the packing does not move, each contact's volume-conserving neck (Rojek et al. 2022, Eqs. 23-27) "
          "grows by the kinetic law, and the conductance law is applied to the grown neck at every step. Touching "
          "spheres (a lattice with `radius = spacing/2`) start from point contacts. `history.csv` gains the mean "
          "and largest neck ratio a/min(r_i, r_j) and the mean linear shrinkage (H(a) - h_0)/(r_i + r_j); the "
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


def _builtin_dir():
    return importlib.resources.files("sintercond.data").joinpath("scenes")


def builtin_scenes() -> dict:
    """The example scenes shipped with the package: ``{name: one-line description}`` (their first comment line)."""
    scenes = {}
    for entry in sorted(_builtin_dir().iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".toml"):
            first = entry.read_text(encoding="utf-8").splitlines()[0]
            scenes[entry.name.removesuffix(".toml")] = first.lstrip("# ").strip()
    return scenes


def load_scene(path=None, duration=None) -> dict:
    """Read and validate a scene file or a built-in scene by name; ``None`` loads the built-in default scene.

    ``path`` is a TOML file, or the name of a built-in example scene
    (:func:`builtin_scenes`, e.g. ``"quintana2020_5_1"``) when no such file
    exists. ``duration`` (s) replaces ``run.duration`` before validation
    (a shorter run of the same scene).
    """
    if path is None:
        data = importlib.resources.files("sintercond.data").joinpath("default_scene.toml").read_bytes()
        source = "default scene"
    elif not Path(path).is_file() and str(path) in builtin_scenes():
        data = _builtin_dir().joinpath(f"{path}.toml").read_bytes()
        source = f"built-in scene {str(path)!r}"
    else:
        path = Path(path)
        if not path.is_file():
            raise SceneError(f"scene file {str(path)!r} does not exist (built-in scenes: "
                             f"{', '.join(builtin_scenes())}; `sintercond scenes` lists them)")
        data, source = path.read_bytes(), str(path)
    if b"\x00" in data:
        raise SceneError(f"{source} is a binary file, not a TOML scene (UTF-8 text)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise SceneError(f"{source} is not UTF-8 text (byte {err.start}: {data[err.start:err.start + 1]!r}; "
                         "Latin-1?): save the scene as UTF-8") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{source} is not valid TOML: {err}") from None
    if duration is not None:
        if isinstance(raw.get("run"), dict):
            raw["run"]["duration"] = duration
    packing = raw.get("packing")
    if (isinstance(packing, dict) and packing.get("kind") == "file" and isinstance(packing.get("path"), str)
            and isinstance(path, Path) and not Path(packing["path"]).is_absolute()):
        packing["path"] = str((path.parent / packing["path"]).resolve())  # relative to the scene file
    return validate_scene(raw)


if __name__ == "__main__":
    print(scene_reference())
