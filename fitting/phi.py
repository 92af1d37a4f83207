"""Fit of the coordination exponent phi of Rizza & Galati (2024)'s tortuosity model to their FE values.

Model (Rizza & Galati 2024, Eqs. 1, 4, 5): for each couple ``c`` of the BCC
cell, ``lambda_c = n lambda_0 / tau_c^2`` with ``tau_c^2 = (S_ss/S_0) gamma_c
n^(1 - phi)``, and the cell's value is the mean over the two couples (their
Table 6 "analytic" columns). The geometric inputs ``n`` and ``S_ss/S_0``
come from sintercond's own BCC cell (80 um corners, 58.56 um centre) with the
neck radii of their Table 3 at each time, ``gamma_c = (D - 2 x_c)/D`` with
``D = 80 um``; ``lambda_0`` is their Table 1 at the same time. The targets
are the FE conductivities of Table 6 (4.13, 5.52, 6.50 W/(m K) at 2.5, 5.5,
9.5 s). Residuals are relative. ``phi`` is continuous; an optional factor
``lambda0_scale`` multiplies ``lambda_0`` for the joint fit.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from fitting.core import Bounded, FitResult, Positive, least_squares
from fitting.reference import rizza_galati_table
from sintercond.laws import geometry
from sintercond.laws import tortuosity as tt

CORNER_DIAMETER_UM = 80.0


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class BCCInputs:
    """Per time of Table 6: geometry from our BCC cell and the paper's lambda_0 and FE value.

    Attributes (arrays over the times):
      time_s, n, sss_over_s0, lambda0 (W/(m K)), lambda_fe (W/(m K));
      gamma: ``[times, 2]`` the two couples' constriction.
    """

    time_s: np.ndarray
    n: np.ndarray
    sss_over_s0: np.ndarray
    gamma: np.ndarray
    lambda0: np.ndarray
    lambda_fe: np.ndarray


def bcc_inputs() -> BCCInputs:
    """Geometry of sintercond's BCC cell at the times of Table 6, with Table 3's necks."""
    t1, t3, t6 = rizza_galati_table(1), rizza_galati_table(3), rizza_galati_table(6)
    rows = [int(np.flatnonzero(np.isclose(t3["time_s"], t))[0]) for t in t6["time_s"]]
    n, sss, gamma = [], [], []
    centres, radii, box = geometry.bcc_cell(CORNER_DIAMETER_UM)
    for row in rows:
        x1, x2 = t3["x_couple1_um"][row], t3["x_couple2_um"][row]
        # couple 1: corner-corner (equal radii), couple 2: corner-centre
        m = geometry.rev_measures(centres, radii, box, necks=lambda a, b, x1=x1, x2=x2: x1 if a == b else x2)
        n.append(m.n)
        sss.append(m.sss_over_s0)
        gamma.append(np.asarray(tt.gamma_factor(np.array([x1, x2]), CORNER_DIAMETER_UM)))
    lambda0 = np.array([t1["lambda0_W_per_mK"][np.flatnonzero(np.isclose(t1["time_s"], t))[0]] for t in t6["time_s"]])
    return BCCInputs(t6["time_s"], np.array(n), np.array(sss), np.array(gamma), lambda0, t6["lambda_fe"])


def bcc_conductivity(params, inputs: BCCInputs):
    """Mean of the two couples' ``lambda_pow`` (W/(m K)) for ``params["phi"]`` (and ``lambda0_scale``)."""
    phi = params["phi"]
    scale = params.get("lambda0_scale", 1.0)
    tau2 = tt.tortuosity_squared(inputs.sss_over_s0[:, None], inputs.gamma, inputs.n[:, None], phi)
    lam = tt.powder_conductivity(inputs.n[:, None], tau2, scale * inputs.lambda0[:, None])
    return lam.mean(axis=1)


def fit_phi(inputs: BCCInputs | None = None, joint=False, **options) -> FitResult:
    """Fit ``phi`` (bounded to (1, 12)), or ``phi`` and ``lambda0_scale`` jointly, to Table 6's FE values."""
    inputs = bcc_inputs() if inputs is None else inputs
    params0 = {"phi": 6.0}
    transforms = {"phi": Bounded(1.0, 12.0)}
    if joint:
        params0["lambda0_scale"] = 1.0
        transforms["lambda0_scale"] = Positive()
    options = {"learning_rate": 0.05, "max_steps": 4000, **options}
    return least_squares(bcc_conductivity, inputs, inputs.lambda_fe, params0, transforms, relative=True, **options)


def correlation(fit: FitResult) -> np.ndarray:
    """Correlation matrix of the fitted parameters (from the Gauss-Newton covariance)."""
    s = np.sqrt(np.diag(fit.covariance))
    return fit.covariance / np.outer(s, s)
