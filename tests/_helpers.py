"""Compositions of library functions that only the tests use (they were public functions of the package that no
caller of it needed; issue 24)."""

import dataclasses
import importlib
import os

import jax.numpy as jnp
import numpy as np
import pytest

from sintercond.contacts import network
from sintercond.output import io
from sintercond.sim import mechanics, thermal
from sintercond.contacts.pair_list import pair_exchange, pair_sum


def find_contacts(centres, radii, tolerance=1e-9, periodic_box=None):
    """Contacts of every particle as a padded ``[n, m]`` index table (padding the row's own index), ascending:
    :func:`sintercond.contacts.network.contact_pairs` laid out by :func:`sintercond.contacts.network.ell_table`."""
    pairs = network.contact_pairs(centres, radii, tolerance, periodic_box)
    (table,) = network.ell_table(pairs.n_particles, pairs.i, pairs.j)
    return table


def explicit_euler_step(temperature, table, capacity, dt, fixed_mask=None, fixed_temperature=None):
    """One explicit Euler step on a table, ``T + dt / C sum_j K_ij (T_j - T_i)``; held particles stay."""
    return thermal.explicit_update(temperature, network.heat_inflow(temperature, table), capacity, dt, fixed_mask,
                                   fixed_temperature)


def contact_loads(spec, params, geometry, positions, radii, mass, modulus, nu, state, t, dt):
    """Forces and torques on every particle from its pair and wall contacts and gravity at ``t``
    (:class:`sintercond.sim.mechanics.Loads`): the pair laws on the whole list at once, then the walls and gravity."""
    n = radii.shape[0]
    f, t_i, t_j, spring, rolling = mechanics.pair_loads(spec, params, geometry, radii, mass, modulus, nu,
                                                        state.velocity, state.spin, state.spring, state.rolling, dt,
                                                        positions.dtype)
    state = dataclasses.replace(state, spring=spring, rolling=rolling)
    return mechanics.body_loads(spec, params, positions, radii, mass, modulus, nu, state, t, dt,
                                pair_exchange(f, geometry.pairs, n), pair_sum(t_i, t_j, geometry.pairs, n))


def forced_rebuild(state):
    """A dynamic state with its lists marked stale: the next update rebuilds both (as after a reallocation),
    carrying the pair history to the rebuilt list."""
    nbrs = state.contacts.neighbor_list
    nbrs = dataclasses.replace(nbrs, reference_position=jnp.full_like(nbrs.reference_position, jnp.inf))
    return dataclasses.replace(state, contacts=dataclasses.replace(state.contacts, neighbor_list=nbrs))


def reader(module, extra="readers"):
    """``pytest.importorskip(module)``, except under ``CI=true`` (where the extras are installed, .ci/run): there a
    missing reader fails the test loudly instead of skipping the writers' checks that need it."""
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        try:
            return importlib.import_module(module)
        except ImportError as error:
            pytest.fail(f"CI=true but {module} is missing ({error}): install the '{extra}' extra", pytrace=False)
    return pytest.importorskip(module, reason=f"install the '{extra}' extra: pip install -e '.[{extra}]'")


def network_pairs(path):
    """The ``(i, j)`` pairs of the lines of a contact-network VTP, read by VTK's own reader where it is installed
    (independent of the package), else from the file's ``connectivity`` array by :func:`sintercond.output.io.read_vtp`."""
    try:
        import vtk
    except ImportError:
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            raise
        cells = np.asarray(io.read_vtp(path)["connectivity"], int)
        return {tuple(int(v) for v in cells[k:k + 2]) for k in range(0, len(cells), 2)}
    vtk_reader = vtk.vtkXMLPolyDataReader()
    vtk_reader.SetFileName(str(path))
    vtk_reader.Update()
    cells = vtk_reader.GetOutput().GetLines().GetConnectivityArray()
    return {tuple(int(cells.GetValue(k + m)) for m in (0, 1)) for k in range(0, cells.GetNumberOfValues(), 2)}


def check_network_of_a_moving_packing(out):
    """The last contact-network frame of a run with mechanics in ``out`` lists exactly the pairs that touch in the
    particle frame of the same step (brute force on its positions), each with a neck and a conductance.
    Called by tests/test_scene_mechanics.py's resume test, which runs such a scene (and resumes its network
    frames bitwise); here so that the resume test does not skip with the readers extra missing."""
    last = sorted((out / "vtp").glob("network_*.vtp"))[-1]
    frame, lines = io.read_vtp(out / "vtp" / last.name.replace("network", "step")), io.read_vtp(last)
    x, r = frame["position"], frame["radius"]
    n = len(r)
    touching = {(i, j) for i in range(n) for j in range(i + 1, n) if r[i] + r[j] > np.linalg.norm(x[i] - x[j])}
    assert network_pairs(last) == touching and touching
    assert np.all(lines["conductance"] > 0) and np.all(lines["neck_radius"] > 0)
