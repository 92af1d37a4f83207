"""The beds: packings of spheres to simulate. ``packing`` (sampled sizes, lattices, a bed's figures and the beds
built on them: ``powder_bed``, ``pour``, ``from_scene``), ``rolling`` (sequential deposition with rolling),
``settle`` (settling under gravity, harmonic or DEM) and ``packing_files`` (reading and writing packings of other
codes). This folder is in the ``use`` layer (docs/architecture.md): it drives the simulator, never the other way.
The main names are re-exported here (``sintercond.beds.powder_bed``); importing the folder imports none of its
modules until one is used.
"""

from sintercond._deprecation import lazy_names

__getattr__ = lazy_names(__name__, {
    **dict.fromkeys(["Packing", "powder_bed", "pour", "from_scene", "rev_box"], "packing"),
    **dict.fromkeys(["RollReport", "roll_deposit"], "rolling"),
    **dict.fromkeys(["PackingError", "relax_under_gravity", "dem_settle", "DemMaterial", "SettleReport"], "settle"),
    **dict.fromkeys(["read_packing", "read_temperatures"], "packing_files"),
})
