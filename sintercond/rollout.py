"""The host loop :func:`advance` and its helpers; they live in :mod:`sintercond.sim.rollout`, beside
:func:`~sintercond.sim.rollout.rollout`, the traced program each chunk runs."""

from sintercond.sim.rollout import (MAX_REALLOCATIONS, ListOverflow, Report, advance, compiled_chunk,  # noqa: F401
                                    finite_temperatures)
