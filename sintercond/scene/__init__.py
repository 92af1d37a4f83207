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
schema (:mod:`sintercond.scene.schema`, :func:`scene_reference`); ``sintercond/data/default_scene.toml``
is a complete example (the scene ``sintercond run`` uses without arguments).

Every key is checked (unknown keys, wrong types, out-of-range values,
inconsistent combinations raise :class:`SceneError` naming the key and the
allowed range), and the work of the run is estimated from the scene alone
(:func:`estimate_run`: particles, steps, output frames and bytes, memory) and
refused beyond the documented limits, all before a packing is built.

The package: :mod:`~sintercond.scene.schema` (the keys), :mod:`~sintercond.scene.validate` (checks and defaults,
:func:`load_scene`), :mod:`~sintercond.scene.estimate` (the run's cost from the scene),
:mod:`~sintercond.scene.reference` (``docs/scenes.md``), :mod:`~sintercond.scene.typed` (the validated scene as
frozen dataclasses made from the schema, what the build reads) and :mod:`~sintercond.scene.build` (a validated scene
to the model a run steps: simulator, parameters, initial state; imported on first use, it pulls in the simulator).
"""

from sintercond.scene.schema import (  # noqa: F401
    FRACTION,
    Key,
    MAX_FRAMES,
    MAX_LATTICE_PARTICLES,
    MAX_LISTED_SPHERES,
    MAX_MEMORY_BYTES,
    MAX_OUTPUT_BYTES,
    MAX_POURED_PARTICLES,
    MAX_STEPS,
    MECHANICAL_FIELDS,
    PACKING_KINDS,
    PACKING_METHODS,
    SceneError,
    TEMPERATURE,
    _LAW_PARAMS,
    _PACKING,
    _SCHEMA,
    _WALL,
    file_packing,
    file_temperatures,
    restitution_damping_ratio,
)
from sintercond.scene.validate import (  # noqa: F401
    ROUGH_BED_PENETRATION,
    builtin_scenes,
    default_penetration,
    load_scene,
    validate_scene,
)
from sintercond.scene.estimate import (  # noqa: F401
    BEAM_STEP_FRACTION,
    RunEstimate,
    WALL_STEP_FRACTION,
    advance_speed,
    beam_step,
    estimate_run,
)
from sintercond.scene.reference import (  # noqa: F401
    scene_reference,
)

__all__ = [
    'BEAM_STEP_FRACTION', 'FRACTION', 'Key', 'MAX_FRAMES', 'MAX_LATTICE_PARTICLES', 'MAX_LISTED_SPHERES',
    'MAX_MEMORY_BYTES', 'MAX_OUTPUT_BYTES', 'MAX_POURED_PARTICLES', 'MAX_STEPS', 'MECHANICAL_FIELDS', 'PACKING_KINDS',
    'PACKING_METHODS', 'ROUGH_BED_PENETRATION', 'RunEstimate', 'SceneError', 'TEMPERATURE', 'WALL_STEP_FRACTION',
    'advance_speed', 'beam_step', 'builtin_scenes', 'default_penetration', 'estimate_run', 'file_packing', 'file_temperatures',
    'load_scene', 'restitution_damping_ratio', 'scene_reference', 'validate_scene',
]
