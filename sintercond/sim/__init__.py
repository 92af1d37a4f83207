"""The simulator: what is simulated (:mod:`~sintercond.sim.physics`), its state and differentiable parameters
(:mod:`~sintercond.sim.state`), the contacts the terms see (:mod:`~sintercond.sim.contacts`), one module per physics
term (:mod:`sintercond.sim.terms`), the step that composes them (:mod:`~sintercond.sim.step`), the checks before
anything compiles (:mod:`~sintercond.sim.validation`, :mod:`~sintercond.sim.stability`) and the rollout with its
host loop (:mod:`~sintercond.sim.rollout`).

:mod:`sintercond.simulate` is the public face of all of it: import from there.
"""

from sintercond._deprecation import lazy_names

__getattr__ = lazy_names(__name__, {})  # sintercond.sim.thermal, ...: the modules, imported on first use
