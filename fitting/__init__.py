"""Calibration of sintercond's model parameters against reference data (optax).

The fitting core, reference data and the fits themselves arrive with the
fitting issue; this package is installed now so that its import path is
stable.
"""

import sintercond  # noqa: F401,E402  (float64 on, as for every sintercond model fitted here)
