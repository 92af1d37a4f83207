"""Calibration of sintercond's model parameters against reference data (optax).

``fitting.core`` (least squares with constrained parameters and Gauss-Newton
intervals), ``fitting.reference`` (the shipped data), and the fits: ``slope``
and ``neck_law`` (neck conductance laws against FE), ``phi`` (Rizza & Galati's
tortuosity exponent), ``inverse`` (conductivities through the simulator),
``softening`` (the thermal softening law through the coupled DEM) and
``sintering`` (neck-growth kinetics against Rizza & Galati's necks, and the
conductivity that follows).
"""

import sintercond  # noqa: F401,E402  (float64 on, as for every sintercond model fitted here)
