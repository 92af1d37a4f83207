"""The contact network as VTP lines (issue 27): one line per contact with its neck radius, conductance and heat flow.

References: the heat each particle receives through its lines equals the heat power the particle frame reports
(two code paths: the network's pair flows and the simulator's Laplacian or pair exchange), the conductance of a
simple cubic lattice's contact from the law on its overlap, and VTK's own reader (lines and times).
"""

import copy

import numpy as np
import pytest

from sintercond.output import io
from sintercond import run as runner
from sintercond.laws.conductance import pair_conductance
from sintercond.scene import validate_scene
from _helpers import reader

vtk = reader("vtk")

LATTICE = {
    "packing": {"kind": "simple_cubic", "counts": [3, 2, 2], "spacing": 1e-4, "radius": 0.52e-4},
    "material": {"density": 4430.0, "specific_heat": 560.0, "conductivity": 12.6},
    "conduction": {"law": "rojek"},
    "initial": {"temperature": 300.0},
    "walls": [{"axis": 0, "side": "min", "mode": "held", "temperature": 400.0}],
    "run": {"duration": 2e-3, "output_every": 5, "checkpoint_every": 10, "contact_network": True},
}


def _inflow(pairs, flow, n):
    """Heat into each particle through its contacts, flow ``K (T_i - T_j)`` leaving ``i`` for ``j``."""
    into = np.zeros(n)
    np.add.at(into, pairs[:, 1], flow)
    np.add.at(into, pairs[:, 0], -flow)
    return into


@pytest.mark.parametrize("sintering", [False, True])
def test_the_networks_lines_carry_the_heat_the_particles_receive(tmp_path, sintering):
    scene = copy.deepcopy(LATTICE)
    if sintering:  # lifted conductances, necks that grow
        scene["sintering"] = {"params": {"A": 1e-16, "activation_energy": 100.0}}
    runner.run_scene(validate_scene(scene), tmp_path, progress=False, pictures=False)
    particles, network = (sorted((tmp_path / "vtp").glob(f"{kind}_*.vtp")) for kind in ("step", "network"))
    assert [f.stem.split("_")[1] for f in particles] == [f.stem.split("_")[1] for f in network]
    frame, lines = io.read_vtp(particles[-1]), io.read_vtp(network[-1])
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(network[-1]))
    reader.Update()
    data = reader.GetOutput()
    n = len(frame["radius"])
    assert data.GetNumberOfLines() == 2 * 2 * 2 + 3 * 2 + 3 * 2 and data.GetNumberOfPoints() == n  # the bonds
    cells = data.GetLines().GetConnectivityArray()
    pairs = np.array([cells.GetValue(k) for k in range(cells.GetNumberOfValues())]).reshape(-1, 2)
    flow = np.array([data.GetCellData().GetArray("heat_flow").GetValue(k) for k in range(len(pairs))])
    held = frame["held"].astype(bool)
    np.testing.assert_allclose(_inflow(pairs, flow, n)[~held], frame["heat_power"][~held],
                               rtol=1e-12, atol=1e-12 * np.abs(frame["heat_power"]).max())
    if not sintering:  # every bond of the lattice: the law on its overlap 2 r - spacing
        expected = pair_conductance("rojek", 0.52e-4, 0.52e-4, 0.04e-4, 12.6, 12.6)
        np.testing.assert_allclose(lines["conductance"], float(expected), rtol=1e-12)
    else:  # each line's conductance is the law at the neck it carries, on the volume-conserving approach
        from sintercond.laws.conductance import conductance_from_neck
        from sintercond.laws.sintering import neck_overlap

        a = lines["neck_radius"]
        assert np.all(a > 0)
        expected = conductance_from_neck("rojek", a, 0.52e-4, 0.52e-4, neck_overlap(a, 0.52e-4, 0.52e-4), 12.6, 12.6)
        np.testing.assert_allclose(lines["conductance"], np.asarray(expected), rtol=1e-12)
    time = float(data.GetFieldData().GetArray("TimeValue").GetValue(0))
    assert f'timestep="{time!r}" group="" part="0" file="vtp/{network[-1].name}"' in (tmp_path / "network.pvd").read_text()


def test_no_network_unless_asked(tmp_path):
    scene = copy.deepcopy(LATTICE)
    scene["run"].update(contact_network=False)
    runner.run_scene(validate_scene(scene), tmp_path, progress=False, pictures=False)
    assert not list((tmp_path / "vtp").glob("network_*.vtp")) and not (tmp_path / "network.pvd").exists()


def test_a_moving_packings_lines_carry_the_contact_forces(tmp_path):
    """Issue 27's force on the network lines. Three unit-size spheres pressed in a row (overlap delta, at rest, no
    springs yet): each line's normal force at the start is Hertz's 4/3 E* sqrt(R*) delta^(3/2) (Eq. 2, E* and R*
    of two equal spheres); at every frame the forces of a particle's lines add up to the contact force its
    particle frame reports (m dv/dt less gravity, the simulator's own step: no walls here)."""
    r, delta, E, nu = 1e-3, 2e-5, 1e6, 0.3
    scene = {
        "packing": {"kind": "spheres", "centres": [[k * (2 * r - delta), 0.0, 0.0] for k in range(3)], "radii": r},
        "material": {"density": 3000.0, "specific_heat": 100.0, "conductivity": 60.0},
        "conduction": {"law": "conductivity", "neck_model": "hertz"}, "initial": {"temperature": 300.0},
        "physics": {"mechanics": True, "impact_velocity": 0.1},
        "mechanics": {"young_modulus": E, "poisson_ratio": nu, "friction": 0.4, "rolling_friction": 0.1},
        "run": {"duration": 2e-4, "output_every": 3, "checkpoint_every": 6, "contact_network": True},
    }
    runner.run_scene(validate_scene(scene), tmp_path, progress=False, pictures=False)
    frames, networks = (sorted((tmp_path / "vtp").glob(f"{kind}_*.vtp")) for kind in ("step", "network"))
    assert len(frames) == len(networks) >= 3
    first = io.read_vtp(networks[0])
    hertz = 4.0 / 3.0 * (E / (2 * (1 - nu**2))) * np.sqrt(r / 2) * delta**1.5
    np.testing.assert_allclose(first["normal_force"], hertz, rtol=1e-12)
    np.testing.assert_allclose(first["force"][:, 0], -hertz, rtol=1e-12)  # on i (the left one) from j: to -x
    for frame_file, network_file in zip(frames, networks):
        frame, lines = io.read_vtp(frame_file), io.read_vtp(network_file)
        reader = vtk.vtkXMLPolyDataReader()
        reader.SetFileName(str(network_file))
        reader.Update()
        cells = reader.GetOutput().GetLines().GetConnectivityArray()
        pairs = np.array([cells.GetValue(k) for k in range(cells.GetNumberOfValues())]).reshape(-1, 2)
        total = np.zeros((3, 3))
        np.add.at(total, pairs[:, 0], lines["force"])
        np.add.at(total, pairs[:, 1], -lines["force"])
        np.testing.assert_allclose(total, frame["force"], rtol=1e-9, atol=1e-9 * hertz)
