"""The contacts: which particles touch and how a step sees them. ``neighbors`` (cell lists, skinned neighbour lists,
jax-md wrapped once) and ``pair_list`` (the half pair list with per-pair history) are the ``space`` layer;
``network`` (the padded ``[n, m]`` contact table, the conduction update's fast path, and its mat-vec) is the
``lifts`` layer above them (docs/architecture.md). The main names are re-exported here
(``sintercond.contacts.contact_table``); importing the folder imports none of its modules until one is used.
"""

from sintercond._deprecation import lazy_names

__getattr__ = lazy_names(__name__, {
    **dict.fromkeys(["NeighborList", "neighbor_list"], "neighbors"),
    **dict.fromkeys(["HalfPairs", "half_pairs"], "pair_list"),
    **dict.fromkeys(["ContactTable", "contact_table", "contact_pairs"], "network"),
})
