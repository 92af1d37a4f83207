"""Sequential deposition with rolling (sintercond.beds.rolling) against closed forms, statics and Visscher & Bolsterli.

The single-sphere cases drop spheres at chosen positions (a stand-in for the generator) and compare where they come
to rest with the geometry worked out by hand; the beds are checked sphere by sphere: each at rest under gravity on
the supports it found (the weight inside the cone of the contact normals, by non-negative least squares), no
overlap beyond the one asked, and the bulk fraction of equal spheres against Visscher & Bolsterli's (1972) ~0.58.
"""

import math

import numpy as np
import pytest
from scipy.optimize import nnls

from sintercond.beds import packing, rolling
from sintercond.contacts.neighbors import brute_force_pairs


class Drops:
    """A generator that drops the spheres at the given lateral positions (and rolls off a top along +x)."""

    def __init__(self, points):
        self.points = [np.asarray(p, float) for p in points]

    def uniform(self, low, high, size=None):
        if size == 2:
            return self.points.pop(0)
        return 0.0


def test_a_sphere_dropped_on_a_sphere_rolls_off_its_equator_to_the_floor():
    """Off a sphere's top it rolls down the great circle, leaves at the equator (2 r out) and falls to the floor."""
    centres, report = rolling.roll_deposit(np.ones(2), 10.0, Drops([(5.0, 5.0), (5.3, 5.0)]))
    assert centres[0] == pytest.approx([5.0, 5.0, 1.0], abs=1e-12)
    assert centres[1] == pytest.approx([7.0, 5.0, 1.0], abs=1e-12)
    assert report.on_floor == 2 and report.unresolved == 0


def test_a_small_sphere_leaves_a_large_one_at_its_equator_and_falls_straight_down():
    """B (radius 1) dropped near the top of A (radius 3, on the floor) rolls down A's great circle and leaves it at
    the equator of their contact sphere, 4 from A's axis at A's height; it then falls vertically to the floor (it
    would land 2 sqrt(3) out had it kept rolling on A under the equator)."""
    centres, _ = rolling.roll_deposit(np.array([3.0, 1.0]), 20.0, Drops([(10.0, 10.0), (10.5, 10.0)]))
    assert centres[1] == pytest.approx([14.0, 10.0, 1.0], abs=1e-12)


def test_a_sphere_comes_to_rest_in_the_pocket_of_three():
    """Three unit spheres on the floor at the corners of a triangle of side s: the fourth, dropped off centre, rests
    above the centroid at z = 1 + sqrt(4 - s^2 / 3) (it touches all three)."""
    s = 2.2
    corners = np.array([[4.0, 4.0], [4.0 + s, 4.0], [4.0 + s / 2, 4.0 + s * math.sqrt(3) / 2]])
    centroid = corners.mean(axis=0)
    drop = corners[0] + 0.3 * (centroid - corners[0])
    centres, report = rolling.roll_deposit(np.ones(4), 10.0, Drops([*corners, drop]))
    assert centres[3] == pytest.approx([*centroid, 1.0 + math.sqrt(4.0 - s * s / 3.0)], abs=1e-9)
    assert np.linalg.norm(centres[:3] - centres[3], axis=1) == pytest.approx(2.0, abs=1e-9)
    assert report.on_three == 1 and report.on_floor == 3


def test_a_sphere_rolling_into_a_side_wall_slides_down_it():
    """A unit sphere rolling off A = (1.5, 5, 1) toward the wall x = 0 meets the wall, rolls on A along the wall
    (centre on x = 1) and lands on the floor where it leaves A, at A's height: y = 5 + sqrt(4 - 0.5^2)."""
    centres, _ = rolling.roll_deposit(np.ones(2), 10.0, Drops([(1.5, 5.0), (1.0, 5.2)]))
    assert centres[1] == pytest.approx([1.0, 5.0 + math.sqrt(4.0 - 0.25), 1.0], abs=1e-9)


def test_a_small_sphere_wedges_in_the_groove_of_two_large_ones():
    """Two touching spheres of radius 3 on the floor; a sphere of radius 1 dropped into the groove between them
    rests at its bottom on both: above their contact, at z = 3 + sqrt(16 - 9) (the two-support wedge)."""
    centres, report = rolling.roll_deposit(np.array([3.0, 3.0, 1.0]), 20.0,
                                           Drops([(7.0, 10.0), (13.0, 10.0), (9.5, 10.0)]))
    assert centres[2] == pytest.approx([10.0, 10.0, 3.0 + math.sqrt(7.0)], abs=1e-9)
    assert report.on_two == 1


def _supports(centres, radii, lateral, overlap, k):
    """Normals of what sphere ``k`` rests on: the spheres dropped before it that it touches, the floor, the walls."""
    d = np.linalg.norm(centres[:k] - centres[k], axis=1)
    touching = d <= (radii[:k] + radii[k]) * (1.0 - 0.5 * overlap)
    normals = list((centres[k] - centres[:k][touching]) / d[touching, None])
    reach = radii[k] * (1.0 - overlap) * (1.0 + 1e-9)
    if centres[k, 2] <= reach:
        normals.append(np.array([0.0, 0.0, 1.0]))
    for axis in (0, 1):
        if centres[k, axis] <= reach:
            normals.append(np.eye(3)[axis])
        if centres[k, axis] >= lateral - reach:
            normals.append(-np.eye(3)[axis])
    return np.array(normals)


@pytest.fixture(scope="module")
def polydisperse():
    rng = np.random.default_rng(7)
    radii = packing.sample_diameters(1500, 20.0, 100.0, rng) / 2  # diameter ratio 5
    lateral, overlap = 500.0, 1e-4
    centres, report = rolling.roll_deposit(radii, lateral, rng, overlap)
    return centres, radii, lateral, overlap, report


def test_every_sphere_is_at_rest_on_the_supports_it_found(polydisperse):
    """Statics sphere by sphere: the weight lies in the cone of its supports' normals (NNLS residual ~0)."""
    centres, radii, lateral, overlap, report = polydisperse
    assert report.unresolved == 0 and report.on_floor + report.on_three + report.on_two == len(radii)
    worst = 0.0
    for k in range(len(radii)):
        normals = _supports(centres, radii, lateral, overlap, k)
        assert len(normals), f"sphere {k} touches nothing"
        _, residual = nnls(normals.T, np.array([0.0, 0.0, 1.0]))
        worst = max(worst, residual)
    assert worst < 1e-8


def test_no_two_spheres_overlap_beyond_the_asked_overlap(polydisperse):
    centres, radii, lateral, overlap, _ = polydisperse
    i, j = brute_force_pairs(centres, radii, tolerance=1e-6)
    relative = (radii[i] + radii[j] - np.linalg.norm(centres[i] - centres[j], axis=1)) / (radii[i] + radii[j])
    assert relative.max() == pytest.approx(overlap, rel=1e-6)  # the supports, at exactly the asked overlap
    assert np.all(centres[:, 2] >= radii * (1 - overlap) * (1 - 1e-12))
    assert np.all((centres[:, :2] >= (radii * (1 - overlap))[:, None] * (1 - 1e-12))
                  & (centres[:, :2] <= lateral - (radii * (1 - overlap))[:, None] * (1 - 1e-12) + 1e-9))


@pytest.mark.slow
def test_equal_spheres_pack_at_visscher_and_bolsterli_fraction():
    """Visscher & Bolsterli (1972) found ~0.58 for equal spheres dropped and rolled to rest; the interior of a
    rolled pile (4 radii from the floor, walls and surface) holds 0.585 here."""
    from sintercond.laws.geometry import sphere_box_volume

    lateral = 24.0
    centres, _ = rolling.roll_deposit(np.ones(4000), lateral, np.random.default_rng(3))
    lo = np.array([4.0, 4.0, 4.0])
    hi = np.array([lateral - 4.0, lateral - 4.0, np.percentile(centres[:, 2], 90) - 4.0])
    inside = np.all((centres > lo - 1.0) & (centres < hi + 1.0), axis=1)
    fraction = sum(float(sphere_box_volume(c, 1.0, lo, hi)) for c in centres[inside]) / np.prod(hi - lo)
    assert 0.57 < fraction < 0.60


def test_the_pile_stops_at_the_asked_surface_height():
    """``fill_height``: spheres are dropped until the mean surface height (the bed's ``height``) reaches it."""
    rng = np.random.default_rng(2)
    radii = packing.sample_diameters(3000, 20.0, 60.0, rng) / 2
    centres, _ = rolling.roll_deposit(radii, 400.0, rng, 1e-4, fill_height=150.0)
    bed = packing._bed(centres, radii[:len(centres)], 400.0)
    assert len(centres) < len(radii)
    assert 150.0 <= bed.height < 150.0 + 0.02 * 150.0  # reached, by at most the last sphere's share


def test_a_rolled_powder_bed_has_the_figures_of_a_stable_frictional_packing():
    """``powder_bed``'s default: the height as asked, no isolated sphere, fraction and coordination of a rolled
    pile (between random loose and random close packing), each sphere's rest reported."""
    bed = packing.powder_bed(400e-6, 300e-6, (20e-6, 60e-6), seed=4)
    assert bed.roll is not None and bed.roll.unresolved == 0
    assert bed.isolated == 0 and 1.0 <= bed.height / 300e-6 < 1.02
    assert 0.55 < bed.packing_fraction < 0.64
    assert 5.0 < bed.coordination < 6.0
    assert math.isnan(bed.residual_force)
    again = packing.powder_bed(400e-6, 300e-6, (20e-6, 60e-6), seed=4)
    assert np.array_equal(again.centres, bed.centres)


@pytest.mark.parametrize("args, field", [
    ((np.array([1.0, -1.0]), 10.0), "radii"),
    ((np.array([1.0, np.nan]), 10.0), "radii"),
    ((np.array([3.0]), 5.0), "lateral_size"),
    ((np.array([1.0]), 10.0, 0.02), "overlap"),
    ((np.array([1.0]), 10.0, -1e-3), "overlap"),
])
def test_bad_input_is_named(args, field):
    with pytest.raises(ValueError, match=field):
        rolling.roll_deposit(args[0], args[1], np.random.default_rng(0), *args[2:])
