"""The integrator of a scene's run: ``run.integrator`` (``"auto"``, the default, ``"explicit"``, ``"implicit"``)
resolved.

``"auto"`` is implicit (adaptive TR-BDF2, :mod:`sintercond.sim.adaptive`) where the run has no inertial mechanics, no
coupled necks and no scanning beam (:func:`sintercond.sim.physics.resolve_integrator`) and the explicit run would
take at least :data:`AUTO_IMPLICIT_STEPS` steps (:func:`auto_by_steps`, once the step is known); explicit
otherwise. The run's log says which and why.
"""

from __future__ import annotations

from sintercond.scene.schema import SceneError
from sintercond.sim.physics import resolve_integrator


AUTO_IMPLICIT_STEPS = 100_000
"""``run.integrator = "auto"`` steps adaptively only a run that would take at least this many explicit steps: below,
compiling the adaptive step costs more than the steps it saves (benchmarks/RESULTS.md, integrator_choice:
``sintering_hot_floor``'s 43,047 explicit steps run faster than its adaptive steps; the preheating bed's 236,471 take
as long; the 9,762-particle bed's 301,223 longer)."""


def scene_integrator(scene) -> tuple[str, str]:
    """``(integrator, why)`` of a validated scene (``scene["run"]["integrator"]``, ``"auto"`` resolved by the kind
    of physics; :func:`auto_by_steps` then looks at the step count); a dict or the typed scene
    (:func:`sintercond.scene.typed.typed_scene`)."""
    if isinstance(scene, dict):
        asked = scene["run"].get("integrator", "auto")
        mechanics = bool((scene.get("physics") or {}).get("mechanics", False))
        if mechanics and (scene.get("mechanics") or {}).get("quasi_static"):
            mechanics = "quasi_static"
        coupling = (scene.get("conduction") or {}).get("coupling") or "none"
        beam = scene.get("beam")
        scanning = beam is not None and beam.get("speed", 0.0) > 0
    else:
        asked, mechanics = scene.run.integrator, scene.physics.mechanics
        if mechanics and scene.mechanics.quasi_static:
            mechanics = "quasi_static"
        coupling, beam = scene.conduction.coupling or "none", scene.beam
        scanning = beam is not None and beam.speed > 0
    if asked == "auto":
        integrator, why = resolve_integrator(mechanics, coupling=coupling, beam="scanning" if scanning else None)
        return integrator, f"run.integrator = \"auto\": {why}"
    if asked == "implicit" and mechanics == "quasi_static":
        raise SceneError('run.integrator = "implicit" steps the slow physics of static contacts; with '
                         'mechanics.quasi_static = true the necks\' balance moves the particles and the pair list '
                         'rebuilds: use "explicit" or "auto"')
    if asked == "implicit" and mechanics:
        raise SceneError('run.integrator = "implicit" steps the slow physics of a static packing; this scene has '
                         'physics.mechanics = true (inertial, bounded by the contact stiffness): use "explicit" or '
                         '"auto"')
    return asked, f"run.integrator = \"{asked}\""


def auto_by_steps(scene, integrator: str, why: str, explicit_steps: int) -> tuple[str, str]:
    """``(integrator, why)``: :func:`scene_integrator`'s, made explicit where ``run.integrator = "auto"`` chose the
    implicit one for a run of fewer than :data:`AUTO_IMPLICIT_STEPS` explicit steps ``explicit_steps``."""
    asked = scene["run"].get("integrator", "auto") if isinstance(scene, dict) else scene.run.integrator
    if asked != "auto" or integrator != "implicit" or explicit_steps >= AUTO_IMPLICIT_STEPS:
        return integrator, why
    return "explicit", (f"run.integrator = \"auto\": the explicit run takes {explicit_steps:,} steps, fewer than "
                        f"{AUTO_IMPLICIT_STEPS:,}: the adaptive step would cost more to compile than it saves")
