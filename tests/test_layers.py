"""The import direction of the package (docs/architecture.md): no cycle, and no module importing a layer above it.

Every import is counted, at module level or inside a function: a function-level import of a higher layer is the
same dependency, only deferred. Old names kept for one release are resolved by string (``thermal.__getattr__``) and
are checked separately below.
"""

import ast
import importlib
import pathlib
import warnings

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]

# lowest first; a module may import its own layer and those below it
LAYERS = {
    "private": ["_numerics", "_validation", "_symmetric", "_cache", "_deprecation"],
    "state": ["state"],
    "laws": ["laws", "laws.neck", "laws.conductance", "laws.forces", "laws.materials", "laws.heat_sources", "laws.walls",
             "laws.sintering", "laws.effective", "laws.dryden_zok", "laws.tortuosity", "laws.geometry"],
    "space": ["contacts", "contacts.neighbors", "contacts.pair_list"],
    "lifts": ["contacts.network", "contacts.sphere_coupling", "sim.mechanics", "sim.thermal", "sim.neck_growth"],
    "drive": ["sim", "sim.physics", "sim.state", "sim.contacts", "sim.terms", "sim.terms.sources", "sim.terms.walls",
              "sim.terms.conduction", "sim.terms.mechanics", "sim.terms.sintering", "sim.terms.coupling", "sim.step",
              "sim.stability", "sim.validation", "sim.rollout", "simulate", "sim.steady", "rollout", "sim.guards",
              "sim.adaptive"],
    "use": ["scene", "scene.schema", "scene.validate", "scene.estimate", "scene.reference", "scene.typed", "scene.build",
            "scene.integrator",
            "output", "output.observe", "beds", "beds.settle", "beds.rolling", "beds.packing", "beds.packing_files",
            "run", "output.io", "output.plots", "cli", "sweep", "examples"],
}
RANK = {f"sintercond.{m}": rank for rank, modules in enumerate(LAYERS.values()) for m in modules}


def _modules():
    """Every module of the package by dotted name; a subpackage's ``__init__`` is the subpackage itself."""
    modules = {}
    for p in (ROOT / "sintercond").rglob("*.py"):
        parts = p.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__main__" or parts == ("sintercond", "__init__") or parts[1] == "data":  # data: files only
            continue
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return modules


def _is_module(dotted):
    path = ROOT.joinpath(*dotted.split("."))
    return path.with_suffix(".py").exists() or (path / "__init__.py").exists()


def _imports(path):
    """The sintercond and fitting modules ``path`` imports, anywhere in it: ``from sintercond.sim import thermal``
    imports ``sintercond.sim.thermal`` (the folder ``sim`` runs no code), ``from sintercond.sim.thermal import x``
    imports ``sintercond.sim.thermal``."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in ("sintercond", "fitting"):
            if node.module in ("sintercond", "fitting"):
                found |= {f"{node.module}.{a.name}" for a in node.names}
            else:
                found |= {f"{node.module}.{a.name}" if _is_module(f"{node.module}.{a.name}") else node.module
                          for a in node.names}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] in ("sintercond", "fitting")}
    return found


def test_every_module_has_a_layer():
    assert set(_modules()) == set(RANK), set(_modules()) ^ set(RANK)


def test_no_module_imports_a_layer_above_its_own():
    names = list(LAYERS)
    upward = []
    for module, path in _modules().items():
        for dep in _imports(path):
            if dep.startswith("fitting"):
                upward.append(f"{module} -> {dep} (fitting sits above the package)")
            elif dep in RANK and RANK[dep] > RANK[module]:
                upward.append(f"{module} ({names[RANK[module]]}) -> {dep} ({names[RANK[dep]]})")
    assert not upward, upward


def test_no_import_cycle():
    graph = {m: _imports(p) & set(_modules()) - {m} for m, p in _modules().items()}
    graph |= {f"fitting.{p.stem}": _imports(p) for p in (ROOT / "fitting").glob("*.py") if p.stem != "__init__"}
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for d in sorted(graph.get(m, ())):
            if state.get(d) == "open":
                cycles.append(stack[stack.index(d):] + [d])
            elif d in graph and d not in state:
                visit(d)
        stack.pop()
        state[m] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert not cycles, [" -> ".join(c) for c in cycles]


def test_import_sintercond_as_sc_gives_every_submodule():
    import sintercond as sc

    for module in _modules():
        name = module.split(".")[1]
        if not name.startswith("_"):  # a subpackage's modules through it: sc.scene.build
            top = importlib.import_module(f"sintercond.{name}")
            assert getattr(sc, name) is top, name
            for part in module.split(".")[2:]:
                top = getattr(top, part) if hasattr(top, part) else importlib.import_module(f"{top.__name__}.{part}")
            assert top is importlib.import_module(module), module
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        sc.nonexistent  # noqa: B018


@pytest.mark.parametrize("old, new", [("simulate", "sintercond.simulate:simulate_table"),
                                      ("steady_state", "sintercond.sim.steady:steady_state"),
                                      ("steady_state_conductivity", "sintercond.sim.steady:steady_state_conductivity"),
                                      ("steady_state_network_conductivity",
                                       "sintercond.sim.steady:steady_state_network_conductivity"),
                                      ("stable_time_step", "sintercond.sim.thermal:table_time_step"),
                                      ("check_time_step", "sintercond.sim.thermal:check_table_time_step")])
def test_moved_thermal_names_still_resolve_with_a_deprecation_warning(old, new):
    from sintercond.sim import thermal

    module, name = new.split(":")
    with pytest.warns(DeprecationWarning, match=f"thermal.{old} moved to {module}.{name}"):
        assert getattr(thermal, old) is getattr(importlib.import_module(module), name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(AttributeError):
            thermal.no_such_function  # noqa: B018


@pytest.mark.parametrize("module, old, new", [("laws.forces", "stable_time_step", "contact_time_step"),
                                              ("sim.mechanics", "stable_time_step", "mechanical_time_step"),
                                              ("sim.mechanics", "check_time_step", "check_mechanical_time_step"),
                                              ("simulate", "stable_time_step", "thermal_time_step")])
def test_renamed_time_steps_still_resolve_with_a_deprecation_warning(module, old, new):
    """Four functions were called stable_time_step (one contact's, the packing's mechanical, a simulator's and a
    table's thermal step): each has its own name now, the old one kept for one release."""
    mod = importlib.import_module(f"sintercond.{module}")
    with pytest.warns(DeprecationWarning, match=f"sintercond.{module}.{old} moved to sintercond.{module}.{new}"):
        assert getattr(mod, old) is getattr(mod, new)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(AttributeError, match="has no attribute 'no_such_function'"):
            mod.no_such_function  # noqa: B018


@pytest.mark.parametrize("old, new", [("build_packing", "sintercond.scene.build"),
                                      ("scene_physics", "sintercond.scene.build"),
                                      ("WallContactWarning", "sintercond.scene.build"),
                                      ("SINTERING_COLUMNS", "sintercond.output.observe"),
                                      ("HISTORY_COLUMNS", "sintercond.output.observe")])
def test_the_model_build_and_history_moved_out_of_run_resolve_with_a_deprecation_warning(old, new):
    """The model build moved to ``sintercond.scene.build`` and the history rows to ``sintercond.output.observe``; what
    ``run`` itself uses (``build_model``, ``history_columns``, ``read_history``) it imports, without a warning."""
    from sintercond import run

    with pytest.warns(DeprecationWarning, match=f"sintercond.run.{old} moved to {new}.{old}"):
        assert getattr(run, old) is getattr(importlib.import_module(new), old)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert run.build_model is importlib.import_module("sintercond.scene.build").build_model
        assert run.read_history is importlib.import_module("sintercond.output.observe").read_history


@pytest.mark.parametrize("old", ["relax_under_gravity", "dem_settle", "DemMaterial", "SettleReport", "DemSettled",
                                 "box_walls", "dem_physics", "GRAVITY", "KINETIC_TOL", "FORCE_TOL"])
def test_the_settling_moved_out_of_packing_resolves_with_a_deprecation_warning(old):
    """The settling (relaxation and DEM) moved to ``sintercond.beds.settle``; ``packing`` keeps the geometry and the beds
    built on it, and its own error (``PackingError``, the same class as ``settle``'s), without a warning."""
    from sintercond.beds import packing, settle

    with pytest.warns(DeprecationWarning, match=f"sintercond.beds.packing.{old} moved to sintercond.beds.settle.{old}"):
        assert getattr(packing, old) is getattr(settle, old)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert packing.PackingError is settle.PackingError
        assert packing.powder_bed is not None and packing.pour is not None and packing.from_scene is not None
        with pytest.raises(AttributeError, match="has no attribute 'no_such_function'"):
            packing.no_such_function  # noqa: B018
