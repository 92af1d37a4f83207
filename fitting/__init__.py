"""Calibration of sintercond's model parameters against reference data (optax).

``fitting.core`` (least squares with constrained parameters and Gauss-Newton
intervals), ``fitting.reference`` (the shipped data), and the fits: ``slope``
and ``neck_law`` (neck conductance laws against FE), ``phi`` (Rizza & Galati's
tortuosity exponent), ``inverse`` (conductivities through the simulator),
``softening`` (the thermal softening law through the coupled DEM) and
``sintering`` (neck-growth kinetics against Rizza & Galati's necks, and the
conductivity that follows); ``posterior`` (the Bayesian posterior by NUTS from
the least-squares optimum: ``fitting.sample_posterior``).
"""

import sintercond  # noqa: F401,E402  (float64 on, as for every sintercond model fitted here)


_POSTERIOR = ("sample_posterior", "sample_posterior_replicates", "PosteriorResult", "PosteriorWarning", "Normal",
              "LogNormal", "Uniform", "HalfNormal", "Jeffreys")


def __getattr__(name):
    """``fitting.sample_posterior`` and its priors, from :mod:`fitting.posterior` on first use (blackjax loads then)."""
    if name in _POSTERIOR:
        from fitting import posterior

        return getattr(posterior, name)
    raise AttributeError(f"module 'fitting' has no attribute {name!r}")
