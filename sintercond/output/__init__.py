"""The outputs of a run: ``observe`` (what a run reports of a state: the rows of ``history.csv``, the heat through
the walls, k* of growing necks, the contact network), ``io`` (VTP, LAMMPS dumps, atomic checkpoints) and ``plots``
(the PNG pictures of a run, the only module that imports matplotlib). This folder is in the ``use`` layer
(docs/architecture.md). The main names are re-exported here (``sintercond.output.write_vtp``); importing the folder
imports none of its modules (nor matplotlib) until one is used.
"""

from sintercond._deprecation import lazy_names

__getattr__ = lazy_names(__name__, {
    **dict.fromkeys(["write_vtp", "read_vtp", "write_pvd", "save_checkpoint", "load_checkpoint"], "io"),
    **dict.fromkeys(["read_history", "history_columns"], "observe"),
    "write_run_pictures": "plots",
})
