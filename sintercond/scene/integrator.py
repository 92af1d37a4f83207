"""The integrator of a scene's run: ``run.integrator`` (``"auto"``, ``"explicit"``, ``"implicit"``) resolved.

``"auto"`` is implicit (adaptive TR-BDF2, :mod:`sintercond.sim.adaptive`) wherever the run has no inertial
mechanics and explicit where it has (:func:`sintercond.sim.physics.resolve_integrator`); the run's log says which
and why.
"""

from __future__ import annotations

from sintercond.scene.schema import SceneError
from sintercond.sim.physics import resolve_integrator


def scene_integrator(scene) -> tuple[str, str]:
    """``(integrator, why)`` of a validated scene (``scene["run"]["integrator"]``, ``"auto"`` resolved); a dict or
    the typed scene (:func:`sintercond.scene.typed.typed_scene`)."""
    asked = scene["run"].get("integrator", "explicit") if isinstance(scene, dict) else scene.run.integrator
    mechanics = bool((scene.get("physics") or {}).get("mechanics", False) if isinstance(scene, dict)
                     else scene.physics.mechanics)
    if asked == "auto":
        integrator, why = resolve_integrator(mechanics)
        return integrator, f"run.integrator = \"auto\": {why}"
    if asked == "implicit" and mechanics:
        raise SceneError('run.integrator = "implicit" steps the slow physics of a static packing; this scene has '
                         'physics.mechanics = true (inertial, bounded by the contact stiffness): use "explicit" or '
                         '"auto"')
    return asked, f"run.integrator = \"{asked}\""
