"""Random powder beds: reproducible, settled, non-overlapping beyond the settling tolerance, plausibly dense."""

import os
import subprocess
import sys

import numpy as np
import pytest

from sintercond import geometry, packing


@pytest.fixture(scope="module")
def bed():
    return packing.powder_bed(320.0, 400.0, diameter_range=(45.0, 150.0), seed=3)


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
    again = packing.powder_bed(320.0, 400.0, diameter_range=(45.0, 150.0), seed=3)
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


def _settled_figures(bed, lateral_size):
    """Independent recount: contacts from all pairs, mean surface height from a finer grid."""
    c, r = bed.centres, bed.radii
    i, j = np.triu_indices(len(r), 1)
    touching = np.linalg.norm(c[i] - c[j], axis=1) < r[i] + r[j]
    degree = np.bincount(i[touching], minlength=len(r)) + np.bincount(j[touching], minlength=len(r))
    supported = (c[:, 2] - r < 0) | np.any(c[:, :2] - r[:, None] < 0, axis=1) | np.any(c[:, :2] + r[:, None] > lateral_size,
                                                                                       axis=1)
    g = (np.arange(100) + 0.5) * lateral_size / 100
    gx, gy = (a.ravel() for a in np.meshgrid(g, g))
    rho2 = (gx[:, None] - c[:, 0]) ** 2 + (gy[:, None] - c[:, 1]) ** 2
    surface = np.max(np.where(rho2 < r**2, c[:, 2] + np.sqrt(np.maximum(r**2 - rho2, 0)), 0.0), axis=1).mean()
    return int(np.sum((degree == 0) & ~supported)), float(surface), 2 * touching.sum() / len(r)


# (lateral size, height, diameter range) in m; the first two are the beds of issue 10 that did not settle
BEDS = [
    (300e-6, 150e-6, (20e-6, 60e-6)),
    (400e-6, 400e-6, (45e-6, 105e-6)),
    (500e-6, 300e-6, (45e-6, 150e-6)),  # the default scene's
    (500e-6, 150e-6, (50e-6, 50e-6)),  # monodisperse, a wide and shallow container
    (150e-6, 80e-6, (10e-6, 30e-6)),  # fine powder
]


@pytest.mark.parametrize("lateral_size,height,diameters", BEDS)
def test_beds_settle_to_the_asked_height(lateral_size, height, diameters):
    bed = packing.powder_bed(lateral_size, height, diameters, seed=1)
    isolated, surface, coordination = _settled_figures(bed, lateral_size)
    assert isolated == 0 and bed.isolated == 0  # every sphere rests on a sphere, the floor or a wall
    assert bed.height == pytest.approx(surface, rel=0.02)
    assert 0.85 < bed.height / height < 1.25  # before the fix: up to 7x
    assert 0.55 < bed.packing_fraction < 0.70
    assert bed.coordination == pytest.approx(coordination) and bed.coordination > 3.5
    assert 0 < bed.max_overlap < 5e-3 and bed.residual_force < 2e-3
    summary = bed.summary()
    assert summary["particles"] == len(bed.radii) and summary["isolated_particles"] == 0


def test_refused_beds_say_why():
    with pytest.raises(packing.PackingError, match=r"height must be >= the largest diameter"):
        packing.powder_bed(300e-6, 10e-6, (20e-6, 60e-6))  # thinner than one particle
    with pytest.raises(packing.PackingError, match=r"needs \d+ particles; the limit is 20000"):
        packing.powder_bed(10e-3, 10e-3, (20e-6, 60e-6))
    with pytest.raises(packing.PackingError, match=r"lateral_size must be a finite number > 0"):
        packing.powder_bed(float("nan"), 1e-4, (20e-6, 60e-6))
    rng = np.random.default_rng(0)
    radii = packing.sample_diameters(50, 20.0, 60.0, rng) / 2
    with pytest.raises(packing.PackingError, match=r"did not settle within 100 steps"):
        packing.relax_under_gravity(packing.deposit_spheres(radii, 200.0, rng), radii, 200.0, max_steps=100)


def test_the_packing_does_not_depend_on_the_jax_precision():
    code = ("import numpy as np, jax, sintercond; from sintercond import packing; "
            "assert jax.numpy.ones(1).dtype == ('float64' if jax.config.jax_enable_x64 else 'float32'); "
            "b = packing.powder_bed(300e-6, 120e-6, (40e-6, 80e-6), seed=2); "
            "np.save(__import__('sys').argv[1], np.concatenate([b.centres.ravel(), b.radii]))")
    results = []
    for flag, name in (("1", "x64.npy"), ("0", "x32.npy")):
        env = {**os.environ, "SINTERCOND_ENABLE_X64": flag}
        subprocess.run([sys.executable, "-c", code, name], check=True, env=env, cwd=os.getcwd())
        results.append(np.load(name))
        os.remove(name)
    # before the fix the float32 run settled a different bed (T_max 761 vs 1125 K on the default scene)
    np.testing.assert_array_equal(results[0], results[1])
