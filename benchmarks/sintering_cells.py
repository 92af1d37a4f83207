"""Rizza & Galati (2024)'s BCC cell sintering in the simulator along the preheating ramp, against their Tables 3 and 6.

Usage: python benchmarks/sintering_cells.py

The BCC unit cell (8 corner spheres of 80 um touching along the edges, a 58.6 um centre sphere touching the
corners; sintercond.laws.geometry.bcc_cell) is held on the stepped ramp (Eq. 6 with its erratum) in the simulator, its
necks grown from point contacts by the grain-boundary law fitted to the 80-58.6 um couple (docs/laws.md), the
solid at their Table 1's lambda_0(T). At Table 3's and Table 6's times the simulator's two necks (corner-corner,
corner-centre) give k* along x of the infinite lattice (fitting.sintering.lattice_conductivity: a periodic block,
Rojek's law or the FE-fitted neck law on each neck; the necks coupled through their spheres, and the isolated pipe
network beside it), set beside their FE conductivity (Table 6). Prints the
table (the SC cell's comparison is the rizza2024_sc_cell scene's, docs/examples.md).
"""

import jax
import numpy as np

from fitting import sintering as fs
from fitting.reference import rizza_galati_table
from sintercond import simulate
from sintercond.laws import geometry, materials
from sintercond.sim import neck_growth
from sintercond.state import particle_state

KINETICS = {"A": 1.2e-20, "activation_energy": 37.0, "dihedral_angle": 150.0}
UM = 1e-6


def main():
    t1 = rizza_galati_table(1)
    kappa = materials.tabulated(t1["temperature_K"], t1["lambda0_W_per_mK"])
    centres, radii, box = geometry.bcc_cell(80.0 * UM)
    physics = simulate.Physics.create(law="rojek", conductance="lifted", held=True, held_ramp=True,
                                      conductivity_table=True, sintering=neck_growth.Sintering())
    particles = particle_state(centres, radii, np.full(len(radii), 845.0), 4430.0, fixed=True)
    contacts = simulate.lifted_contacts(physics, centres, radii)
    state = simulate.init_state(particles, contacts, 1e-3, sintering=neck_growth.neck_state(contacts,
                                                                                          particles.temperature))
    params = simulate.Params(conductivity=kappa, specific_heat=[560.0], sintering=KINETICS,
                             held_ramp=simulate.HeldRampParams(1273.0, 9.5, 25.0))
    sim = simulate.simulator(physics)
    centre = len(radii) - 1
    assert np.isclose(np.linalg.norm(centres[0] - centres[1]), 80 * UM)  # corners 0 and 1 share an edge
    nbrs = np.asarray(contacts.neighbors)
    slot_cc, slot_cm = int(np.argmax(nbrs[0] == 1)), int(np.argmax(nbrs[0] == centre))
    observe = lambda s: (s.contacts.table_neck[0, slot_cc], s.contacts.table_neck[0, slot_cm], s.particles.temperature[0])  # noqa: E731
    _, (x1, x2, temperature) = jax.jit(lambda s, p: simulate.rollout(sim, s, p, 9500, simulate.SaveAt(500, observe))
                                       )(state, params)
    times = 0.5 * np.arange(1, 20)
    t3, t6 = rizza_galati_table(3), rizza_galati_table(6)
    print("| t (s) | T (K) | corner-corner a (um) | Table 3 couple 1 (um) | corner-centre a (um) | Table 3 couple 2 "
          "(um) | k* coupled, Rojek's law | k* coupled, FE-fitted law | k* isolated, Rojek's law | "
          "k* isolated, FE-fitted law | Table 6 FE (W/(m K)) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    fe = dict(zip(t6["time_s"], t6["lambda_fe"]))
    for t, a1, a2 in zip(times, np.asarray(x1), np.asarray(x2)):
        row = np.flatnonzero(np.isclose(t3["time_s"], t))
        if not len(row):
            continue
        k = int(row[0])
        level = float(np.asarray(temperature)[int(round(t / 0.5)) - 1])
        k_star = [float(fs.lattice_conductivity(centres, radii, box, lambda ri, rj, a1=a1, a2=a2:
                                                a1 if np.isclose(ri, rj) else a2, float(kappa(level)), law,
                                                coupling=coupling))
                  for coupling in ("sphere", "none") for law in ("rojek", "fitted")]
        print(f"| {t:g} | {level:.0f} | {a1 / UM:.2f} | {t3['x_couple1_um'][k]:.2f} | {a2 / UM:.2f} | "
              f"{t3['x_couple2_um'][k]:.2f} | " + " | ".join(f"{v:.3f}" for v in k_star) + f" | {fe.get(t, '')} |")


if __name__ == "__main__":
    main()
