"""The heat-sources term: beam (nozzle or laser), convection, radiation, a prescribed pulse and a user source.

The laws are :func:`sintercond.sim.thermal.source_power` (Quintana-Ruiz & Campello 2020, Eqs. 29-31 for the beam,
37-39 convection, 41 radiation); this term says which are on (``Physics.sources``) and checks that each has its
parameters (``Params.beam``, ``.convection``, ``.radiation``, ``.pulse``).
"""

from __future__ import annotations

from sintercond.sim import thermal
from sintercond.sim.physics import Physics
from sintercond.sim.state import BeamParams, ConvectionParams, Params, PulseParams, RadiationParams, SimState

PARAMS = {"beam": BeamParams, "convection": ConvectionParams, "radiation": RadiationParams, "pulse": PulseParams}
"""Each source's part of :class:`~sintercond.sim.state.Params`."""


def validate(physics: Physics, params: Params) -> None:
    """Raise ``ValueError`` naming the field when a source that is on has no parameters."""
    for name, kind in PARAMS.items():
        if getattr(physics.sources, name) not in (None, False) and getattr(params, name) is None:
            raise ValueError(f"Physics.sources.{name} is on but Params.{name} is None; give a simulate.{kind.__name__}")


def power(physics: Physics, state: SimState, params: Params):
    """Heat power ``[n]`` (W) of every source that is on, at the state's time and positions (0: none is on)."""
    return thermal.source_power(physics.sources, state, params)


def power_parts(physics: Physics, state: SimState, params: Params):
    """:func:`power` as ``(terms, pulse)``, the pulse apart (:func:`sintercond.sim.thermal.source_power_parts`)."""
    return thermal.source_power_parts(physics.sources, state, params)
