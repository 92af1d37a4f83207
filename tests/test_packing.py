"""Random powder beds: reproducible, non-overlapping beyond the settling tolerance, plausibly dense."""

import numpy as np
import pytest

from sintercond import geometry, packing


@pytest.fixture(scope="module")
def bed():
    return packing.powder_bed(320.0, 260.0, diameter_range=(45.0, 150.0), seed=3)


def test_diameters_follow_the_volume_uniform_distribution():
    d = packing.sample_diameters(200_000, 45.0, 150.0, np.random.default_rng(0))
    assert d.min() >= 45.0 and d.max() <= 150.0
    volume = d**3
    # by volume, diameters are uniform: the volume-weighted mean diameter is the midpoint
    assert np.sum(volume * d) / np.sum(volume) == pytest.approx(97.5, rel=5e-3)


def test_bed_is_settled_and_reproducible(bed):
    lo, hi = bed.container
    assert np.all(bed.centres - bed.radii[:, None] >= lo - 1e-2 * bed.radii[:, None])
    assert np.all(bed.centres[:, :2] + bed.radii[:, None] <= hi[:2] + 1e-2 * bed.radii[:, None])
    assert 0 < bed.max_overlap < 5e-3  # contacts are small overlaps, nothing interpenetrates
    again = packing.powder_bed(320.0, 260.0, diameter_range=(45.0, 150.0), seed=3)
    np.testing.assert_allclose(again.centres, bed.centres, rtol=1e-10)


def test_rev_from_the_bed_interior(bed):
    centres, radii, box = packing.rev_box(bed, 150.0)
    m = geometry.rev_measures(centres, radii, box)
    # a settled polydisperse bed: relative density near random close packing of such powders
    assert 0.5 < m.n < 0.75
    assert 0.4 < m.sss_over_s0 < 0.85
    assert m.phi >= 3 and len(m.pairs) >= len(radii) // 2
    lo, hi = box
    nearest = np.clip(centres, lo, hi)
    assert np.all(np.linalg.norm(centres - nearest, axis=1) < radii)  # every sphere reaches into the cube
    with pytest.raises(ValueError, match="does not fit"):
        packing.rev_box(bed, 400.0)


def test_bad_diameter_range():
    with pytest.raises(ValueError, match="diameter_range"):
        packing.powder_bed(100.0, 100.0, diameter_range=(45.0, 150.0))
