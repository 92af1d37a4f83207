"""The kinetics posterior through grow_neck (fitting.sintering.kinetics_posterior): prior sensitivity on Rizza &
Galati's 80-80 necks.

Two independent routes to the posterior under an informative prior on Q: NUTS run under that prior, and the
draws under a wide prior reweighted by the ratio of the priors (importance sampling; BDA3 Sec. 10.4). They must
agree; the well-identified rate at T_ref must barely move while the poorly identified Q moves to the precision-
weighted combination of its likelihood and the prior (the product of two normals).
"""

import math
import warnings

import numpy as np
import pytest

pytest.importorskip("blackjax", reason="install the 'posterior' extra")
from fitting import sintering as fs  # noqa: E402
from fitting.core import Bounded  # noqa: E402
from fitting.posterior import Normal, Uniform  # noqa: E402

pytestmark = pytest.mark.slow  # two compilations of NUTS through grow_neck's gradient

SIGMA_UM = 0.27  # about the residual sd of the least-squares fit (um)
WIDE, TIGHT = Uniform(1.0, 1000.0), Normal(80.0, 10.0)
TRANSFORMS = {"activation_energy": Bounded(1.0, 1000.0)}  # the same for both: one least-squares program


@pytest.fixture(scope="module")
def posteriors():
    series = fs.neck_series("80-80")
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fs.IdentifiabilityWarning)
        for name, prior in (("wide", WIDE), ("tight", TIGHT)):
            out[name] = fs.kinetics_posterior(series, priors={"activation_energy": prior}, transforms=TRANSFORMS,
                                              sigma=SIGMA_UM, num_samples=400, num_warmup=100, seed=1)
    return out


def test_prior_sensitivity_of_the_kinetics_posterior(posteriors):
    wide, tight = posteriors["wide"].posterior, posteriors["tight"].posterior
    q_wide, q_tight = wide.samples["activation_energy"], tight.samples["activation_energy"]
    # importance reweighting of the wide-prior draws to the tight prior
    w = np.exp(np.asarray(TIGHT.log_density(q_wide)) - np.asarray(WIDE.log_density(q_wide)))
    w /= w.sum()
    ess_w = 1 / np.sum(w**2)
    mean_w = np.sum(w * q_wide)
    sd_tight = q_tight.std()
    assert ess_w > 200
    assert abs(q_tight.mean() - mean_w) < 4 * sd_tight * math.sqrt(1 / ess_w + 1 / tight.ess["activation_energy"])
    # the product of the (nearly normal) likelihood and the normal prior
    m, s = q_wide.mean(), q_wide.std()
    expected = (m / s**2 + TIGHT.mean / TIGHT.sd**2) / (1 / s**2 + 1 / TIGHT.sd**2)
    assert abs(q_tight.mean() - expected) < 0.25 * sd_tight, (q_tight.mean(), expected)
    assert abs(sd_tight - (1 / s**2 + 1 / TIGHT.sd**2) ** -0.5) < 0.15 * sd_tight
    # Q moved towards the prior; the rate at T_ref, which the necks pin, moved by less than its sd
    assert q_tight.mean() > m + 0.3 * s
    lr_wide, lr_tight = wide.samples["log_rate_ref"], tight.samples["log_rate_ref"]
    assert abs(lr_tight.mean() - lr_wide.mean()) < lr_wide.std()
    # ln A per draw is the module's relation, and it inherits Q's shift
    kp = posteriors["tight"]
    expected_ln_a = lr_tight + math.log(kp.reference_temperature) + 1e3 * q_tight / (8.314462618 * kp.reference_temperature)
    np.testing.assert_allclose(kp.log_prefactor, expected_ln_a, rtol=1e-12)
    assert not wide.warnings and not tight.warnings
