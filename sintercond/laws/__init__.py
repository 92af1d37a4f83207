"""The laws: what happens at one contact, one particle or one wall, as pure functions of arrays (neck radii, pair
conductances, contact forces, material properties, heat sources, walls, neck-growth kinetics) and the
effective-conductivity models of a packing (Dryden-Zok, Hashin-Shtrikman, Maxwell, Rizza-Galati's tortuosity).
This folder is the ``laws`` layer (docs/architecture.md): its modules import only the private modules, ``state``
and each other, never contacts, the simulator or a bed. The main names are re-exported here
(``sintercond.laws.neck_radius``); importing the folder imports none of its modules until one is used.
"""

from sintercond._deprecation import lazy_names

__getattr__ = lazy_names(__name__, {
    **dict.fromkeys(["NECK_MODELS", "NeckStatus", "neck_radius", "max_overlap"], "neck"),
    **dict.fromkeys(["CONDUCTANCE_LAWS", "ConductanceLaw", "pair_conductance"], "conductance"),
    **dict.fromkeys(["dryden_zok_conductivity", "hashin_shtrikman_bounds", "maxwell_conductivity"], "effective"),
    "PlaneWall": "walls",
    "grow_neck": "sintering",
})
