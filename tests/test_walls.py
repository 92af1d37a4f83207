"""Plane walls as neighbours of infinite radius: neck limits, law halves, the one wall type."""

import jax
import numpy as np
import pytest

from sintercond import NECK_MODELS
from sintercond.laws import walls
from sintercond.laws.conductance import pair_conductance

MODELS = ("coble", "hertz", "intersection", "volume_conserving")


@pytest.mark.parametrize("model", MODELS)
def test_wall_neck_is_the_mirror_image_of_two_equal_spheres(model):
    """A sphere cutting a plane by h is half of two equal spheres overlapping by 2h, for every neck model
    (Coble r* = r, Hertz r* = r/2 for the pair; the lens circle; Rojek Eqs. 19-20 for the volume-conserving
    neck, a closed form independent of the plane formula)."""
    r = 1.3e-4
    h = np.linspace(1e-9, 0.33, 60) * r
    np.testing.assert_allclose(walls.wall_neck_radius(model, r, h), NECK_MODELS[model](r, r, 2 * h), rtol=1e-13)


@pytest.mark.parametrize("model", MODELS)
def test_wall_neck_is_the_limit_of_a_growing_sphere(model):
    """r_j -> inf: a sphere of 1e8 radii is within 1e-7 of the plane (a sphere of 1e3 radii was off by 5e-4)."""
    r, h = 1.0, np.array([1e-4, 0.01, 0.1, 0.3])
    plane = np.asarray(walls.wall_neck_radius(model, r, h))
    np.testing.assert_allclose(NECK_MODELS[model](r, 1e8, h), plane, rtol=2e-7)


def test_wall_neck_domain_and_gradients():
    assert np.isnan(walls.wall_neck_radius("volume_conserving", 1.0, 0.34))  # beyond r/3: no such neck
    assert float(walls.wall_neck_radius("volume_conserving", 1.0, 1 / 3)) == pytest.approx(1.0, rel=1e-7)
    assert float(walls.wall_neck_radius("volume_conserving", 1.0, 0.0)) == 0.0
    g = jax.grad(lambda h: walls.wall_neck_radius("volume_conserving", 1.0, h))
    assert float(g(0.0)) == 0.0 and np.isfinite(float(g(0.2)))
    h, eps = 0.2, 1e-7
    fd = (float(walls.wall_neck_radius("volume_conserving", 1.0, h + eps))
          - float(walls.wall_neck_radius("volume_conserving", 1.0, h - eps))) / (2 * eps)
    assert float(g(h)) == pytest.approx(fd, rel=1e-6)


@pytest.mark.parametrize("law", ["rojek", "argento_bouvard", "batchelor_obrien", "fitted"])
def test_wall_half_is_the_half_space_limit_of_the_law(law):
    """The wall's half of each law is its limit for r_j -> inf: a pair with a 1e8-radius sphere agrees."""
    r, h, kappa = 1.0, np.array([1e-3, 0.02, 0.2]), 20.0
    plane = np.asarray(walls.wall_conductance(law, r, h, kappa))
    np.testing.assert_allclose(pair_conductance(law, r, 1e8, h, kappa), plane, rtol=1e-6)


def test_conductivity_law_at_a_wall_uses_the_centre_to_wall_distance():
    """Quintana-Ruiz Eq. 32 at a wall, as MECHANICS.md reads Example 5.1: k pi a^2 / (r - h) with the lens
    (plane-cut) circle a^2 = h (2r - h); Eq. 35 with d -> inf would give nothing."""
    r, h, kappa = 1e-3, 1e-5, 60.0
    expected = kappa * np.pi * h * (2 * r - h) / (r - h)
    assert float(walls.wall_conductance("conductivity", r, h, kappa)) == pytest.approx(expected, rel=1e-13)


def test_plane_wall_type():
    w = walls.PlaneWall(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), mode="conducting", temperature=700.0)
    pen = np.asarray(w.penetration(np.array([[0.0, 0.0, 0.9e-3], [0.0, 0.0, 2e-3]]), np.array([1e-3, 1e-3])))
    np.testing.assert_allclose(pen, [1e-4, -1e-3], rtol=1e-12)
    with pytest.raises(ValueError, match="PlaneWall.mode"):
        walls.PlaneWall((0, 0, 0), (0, 0, 1), mode="hot")
    with pytest.raises(ValueError, match="PlaneWall.normal must be a unit"):
        walls.PlaneWall((0, 0, 0), (0, 0, 2))
    with pytest.raises(ValueError, match="PlaneWall.temperature must be > 0 K"):
        walls.PlaneWall((0, 0, 0), (0, 0, 1), mode="held")
