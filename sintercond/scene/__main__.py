"""``python -m sintercond.scene > docs/scenes.md``: the generated scene reference."""

from sintercond.scene.reference import scene_reference

print(scene_reference())
