"""Example 5.3 of Quintana-Ruiz & Campello (2020) on a small bed: pour, settle, heat, k* within the HS bounds.

References: the truncated normal's moments (closed form), the Hashin-Shtrikman
upper bound with a void phase ``2 k phi / (3 - phi)`` (Maxwell's form), heat
conservation of the network (heat through the walls = heat stored), and the
direction of the softening effect (larger contacts conduct more).
"""

import math

import numpy as np
import pytest
from scipy import stats

from sintercond import examples


@pytest.fixture(scope="module")
def ex():
    return examples.example_5_3(n=60, lateral_size=0.025, iterations=1, check_every=250)


def test_radii_follow_the_truncated_normal():
    radii = examples.example_5_3_radii(200_000, seed=0)
    d = examples.EXAMPLE_5_3
    law = stats.truncnorm(-3.0, 3.0, loc=d["radius_mean"], scale=d["radius_std"])
    assert np.all(np.abs(radii - 3e-3) <= 3 * 0.667e-3)
    assert radii.mean() == pytest.approx(law.mean(), rel=1e-3)
    assert radii.std() == pytest.approx(law.std(), rel=5e-3)  # 0.9866 sigma: the tails cut at 3 sigma


@pytest.mark.slow
def test_both_beds_settled_into_a_random_packing(ex):
    for bed in (ex.packing, ex.softened_packing):
        assert bed.settle.kinetic_ratio < bed.settle.kinetic_tol and bed.settle.force_ratio < bed.settle.force_tol
        assert 0.5 < bed.packing_fraction < 0.7 and bed.isolated == 0


@pytest.mark.slow
def test_k_star_lies_within_the_hashin_shtrikman_bounds(ex):
    for est, bed, bounds in ((ex.unsoftened, ex.packing, ex.bounds),
                             (ex.softened, ex.softened_packing, ex.softened_bounds)):
        phi = bed.packing_fraction
        upper = 2 * 100.0 * phi / (3 - phi)  # void matrix: HS upper bound = Maxwell's dense-solid estimate
        assert bounds == pytest.approx((0.0, upper), rel=1e-12)
        for k in (est.k_steady, est.k_wall, est.k_paper):
            assert 0 < k < upper
        assert est.steady_change < 1e-2  # 350 s reach the steady state: what enters leaves
        assert est.k_wall == pytest.approx(est.k_steady, rel=0.3)  # same flux, wall resistance and L differ


@pytest.mark.slow
def test_heat_through_the_walls_is_the_heat_stored(ex):
    for est in (ex.unsoftened, ex.softened):
        assert est.heat_hot > 0 > est.heat_cold
        assert est.heat_hot + est.heat_cold == pytest.approx(est.stored, rel=1e-9)


@pytest.mark.slow
def test_softening_raises_k_star(ex):
    assert ex.softened.k_steady > ex.unsoftened.k_steady
    assert ex.softened.k_wall > ex.unsoftened.k_wall
    assert ex.iterations == (ex.softened.k_steady,)
    # softer contacts: the bed sinks and its contacts grow
    assert ex.softened_packing.max_overlap > ex.packing.max_overlap
    assert math.isfinite(ex.seconds["softened"])
