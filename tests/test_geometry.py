"""Packing geometry: exact clipping (closed forms, sum rules), contacts, necks, lattice cells."""

import numpy as np
import pytest

from sintercond.laws import geometry as g
from sintercond.laws.neck import neck_residual

R = 40.0  # um: Rizza & Galati's 80 um spheres


def test_circle_rectangle_area_closed_forms():
    assert g.circle_rectangle_area(0, 0, 1, -2, 2, -2, 2) == pytest.approx(np.pi, rel=1e-15)
    assert g.circle_rectangle_area(0, 0, 1, 0, 2, 0, 2) == pytest.approx(np.pi / 4, rel=1e-15)  # quadrant
    h = 0.3  # a segment: the disc with y >= 1 - h
    segment = np.arccos(1 - h) - (1 - h) * np.sqrt(2 * h - h * h)
    assert g.circle_rectangle_area(0, 0, 1, -2, 2, 1 - h, 2) == pytest.approx(segment, rel=1e-13)
    assert g.circle_rectangle_area(0, 0, 1, 1.5, 2, -2, 2) == 0.0
    assert g.circle_rectangle_area(0.2, -0.1, 0.05, -1, 1, -1, 1) == pytest.approx(np.pi * 0.05**2, rel=1e-14)


def test_clipping_is_additive():
    rng = np.random.default_rng(0)
    for _ in range(5):
        c, r = rng.uniform(-0.5, 0.5, 3), rng.uniform(0.3, 1.2)
        lo, hi = rng.uniform(-1.0, -0.2, 3), rng.uniform(0.2, 1.0, 3)
        mid = rng.uniform(lo, hi)
        total = g.sphere_box_volume(c, r, lo, hi)
        parts = sum(g.sphere_box_volume(c, r, np.where(s, mid, lo), np.where(s, hi, mid))
                    for s in np.ndindex(2, 2, 2))
        assert parts == pytest.approx(total, rel=1e-13)
        # faces: a rectangle split in four
        area = g.circle_rectangle_area(c[0], c[1], r, lo[0], hi[0], lo[1], hi[1])
        quarters = sum(g.circle_rectangle_area(c[0], c[1], r, *xs, *ys)
                       for xs in ((lo[0], mid[0]), (mid[0], hi[0])) for ys in ((lo[1], mid[1]), (mid[1], hi[1])))
        assert quarters == pytest.approx(area, rel=1e-13, abs=1e-15)


def test_sphere_box_volume_closed_forms():
    assert g.sphere_box_volume([0, 0, 0], 1.0, [-2] * 3, [2] * 3) == pytest.approx(4 / 3 * np.pi, rel=1e-14)
    cap = np.pi * 0.7**2 * (3 - 0.7) / 3
    assert g.sphere_box_volume([0, 0, 0], 1.0, [-2] * 3, [0.3, 2, 2]) == pytest.approx(4 / 3 * np.pi - cap, rel=1e-14)
    assert g.sphere_box_volume([0, 0, 0], 1.0, [0] * 3, [2] * 3) == pytest.approx(np.pi / 6, rel=1e-14)  # octant
    assert g.sphere_box_volume([5, 0, 0], 1.0, [-2] * 3, [2] * 3) == 0.0


def test_simple_cubic_cell_holds_one_sphere():
    m = g.rev_measures(*g.simple_cubic_cell(2 * R))
    assert m.U_0 == 512_000 and m.S_0 == 38_400  # Rizza & Galati, Sect. 3.1
    assert m.U_0s == pytest.approx(4 / 3 * np.pi * R**3, rel=1e-13)  # eight octants
    assert m.S_ss == pytest.approx(6 * np.pi * R**2, rel=1e-13)  # four quarter discs per face
    assert m.phi == 3 and list(m.coordination) == [3] * 8 and len(m.pairs) == 12
    assert m.n == pytest.approx(np.pi / 6, rel=1e-13)


def test_bcc_and_fcc_cells():
    centres, radii, box = g.bcc_cell(2 * R)
    assert 2 * radii[-1] == pytest.approx(58.6, abs=0.05)  # Rizza & Galati's 58.6 um centre sphere
    m = g.rev_measures(centres, radii, box)
    assert m.U_0s == pytest.approx(4 / 3 * np.pi * (R**3 + radii[-1] ** 3), rel=1e-13)
    assert m.S_ss == pytest.approx(6 * np.pi * R**2, rel=1e-13)  # the centre sphere stays off the faces
    assert m.phi == 8 and sorted(m.coordination) == [4] * 8 + [8]
    m = g.rev_measures(*g.fcc_cell(2 * R))
    assert m.n == pytest.approx(np.pi / (3 * np.sqrt(2)), rel=1e-13)  # FCC packing fraction
    assert m.phi == 8  # face-centre spheres see 4 corners + 4 face centres inside the cell


def test_neck_volume_is_cylinder_minus_caps_and_clipped_exactly():
    x = 8.62
    v = g.neck_volume(x, R, R)
    h_c = R - np.sqrt(R * R - x * x)
    expected = np.pi * x * x * 2 * h_c - 2 * np.pi * h_c**2 * (3 * R - h_c) / 3
    assert v == pytest.approx(expected, rel=1e-12)
    assert v == pytest.approx(np.pi / 3 * float(neck_residual(x, R, R, 0.0)), rel=1e-14)
    # SC: twelve edge necks, a quarter of each inside the cell
    m = g.rev_measures(*g.simple_cubic_cell(2 * R), necks=x)
    assert m.U_0s - m.sphere_volume == pytest.approx(3 * v, rel=1e-10)
    # ... and two half sections of each on the faces: 2 x 12 x int_0^x gap(s) ds
    s = np.linspace(0, x, 400_001)
    half_section = np.trapezoid(2 * (R - np.sqrt(R * R - s * s)), s)
    assert m.S_ss - m.sphere_face_area == pytest.approx(24 * half_section, rel=1e-8)
    assert np.allclose(m.gamma, (80 - 2 * x) / 80) and np.allclose(m.neck_radii, x)


def test_bcc_necks_per_pair_type():
    x_edge, x_diag = 8.62, 8.09  # Table 3 at 9.5 s: couple 1 (80-80) and couple 2 (80-58.6)
    centres, radii, box = g.bcc_cell(2 * R)
    m = g.rev_measures(centres, radii, box, necks=lambda a, b: x_edge if a == b else x_diag)
    v_edge = g.neck_volume(x_edge, R, R)
    v_diag = g.neck_volume(x_diag, R, radii[-1])
    assert m.U_0s - m.sphere_volume == pytest.approx(3 * v_edge + 8 * v_diag, rel=1e-6)
    # gamma uses the larger diameter, 80 um, for both couples (Eq. 4)
    assert sorted(np.round(m.gamma, 6)) == sorted(np.round([(80 - 2 * x_edge) / 80] * 12 + [(80 - 2 * x_diag) / 80] * 8, 6))


def test_bad_input():
    with pytest.raises(ValueError, match="centres must be"):
        g.rev_measures(np.zeros((3, 2)), np.ones(3), (np.zeros(3), np.ones(3)))
    with pytest.raises(ValueError, match="radii must be finite and > 0"):
        g.rev_measures(np.zeros((1, 3)), -np.ones(1), (np.zeros(3), np.ones(3)))
    with pytest.raises(ValueError, match="neck radii"):
        g.rev_measures(*g.simple_cubic_cell(2 * R), necks=50.0)
