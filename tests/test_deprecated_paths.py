"""The old module paths of the modules moved into the folders of their layers (issue 39, docs/architecture.md) keep
working for one release: ``import sintercond.network``, ``from sintercond.network import x``, ``from sintercond import
network`` and ``sintercond.network`` each warn with the new path and give the new module itself (so patching either
path patches both); the new paths, and the names ``sintercond`` re-exports, do not warn.

Checkpoints hold arrays by their path in the state (``np.savez``, loaded without pickle), not module paths, so those
written before the move load unchanged.
"""

import importlib
import subprocess
import sys
import warnings

import pytest

import sintercond

OLD = sorted(sintercond._MOVED)


def _forget(monkeypatch, old):
    """Drop what a first use of the old path leaves behind (the alias in ``sys.modules``, the attribute the import
    sets on the package), so that the next use goes through the alias again."""
    monkeypatch.delitem(sys.modules, f"sintercond.{old}", raising=False)
    if old in vars(sintercond):  # not hasattr: that is a use of the old path
        monkeypatch.delattr(sintercond, old)


def _run(statement, namespace):
    exec(compile(statement, __file__, "exec"), namespace)  # the warning points at this file: the user's import


@pytest.mark.parametrize("old", OLD)
def test_every_old_path_warns_with_the_new_path_and_is_the_new_module(old, monkeypatch):
    new_path = f"sintercond.{sintercond._MOVED[old]}.{old}"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = importlib.import_module(new_path)
    name = next(n for n in vars(new) if not n.startswith("_") and n != "annotations")
    match = f"sintercond.{old} moved to {new_path}"
    forms = {"import": (f"import sintercond.{old}", lambda ns: ns["sintercond"].__dict__.get(old)
                        or sys.modules[f"sintercond.{old}"]),
             "import as": (f"import sintercond.{old} as m", lambda ns: ns["m"]),
             "from old import name": (f"from sintercond.{old} import {name} as x", lambda ns: ns["x"]),
             "from package import old": (f"from sintercond import {old} as m", lambda ns: ns["m"]),
             "attribute": (f"m = sintercond.{old}", lambda ns: ns["m"])}
    for form, (statement, result) in forms.items():
        _forget(monkeypatch, old)
        namespace = {"sintercond": sintercond}
        with pytest.warns(DeprecationWarning, match=match) as record:
            _run(statement, namespace)
        assert record[0].filename == __file__, (form, record[0].filename)
        got = result(namespace)
        assert (got is getattr(new, name)) if form == "from old import name" else (got is new), form
        if form.startswith("import"):
            assert sys.modules[f"sintercond.{old}"] is new
    assert new.__name__ == new_path and new.__spec__.name == new_path  # the alias leaves the module's own spec


def test_patching_the_old_path_patches_the_new_module(monkeypatch):
    from sintercond.contacts import network

    _forget(monkeypatch, "network")
    with pytest.warns(DeprecationWarning, match="sintercond.network moved to sintercond.contacts.network"):
        monkeypatch.setattr("sintercond.network.contact_table", "patched")
    assert network.contact_table == "patched"


@pytest.mark.parametrize("old", OLD)
def test_the_new_paths_do_not_warn(old):
    folder = sintercond._MOVED[old]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        module = importlib.import_module(f"sintercond.{folder}.{old}")
        assert getattr(importlib.import_module(f"sintercond.{folder}"), old) is module
        assert getattr(getattr(sintercond, folder), old) is module


def test_the_names_sintercond_exports_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in sintercond.__all__:
            assert getattr(sintercond, name) is not None
        assert sintercond.neck_radius is importlib.import_module("sintercond.laws.neck").neck_radius
        assert sintercond.beds.powder_bed is importlib.import_module("sintercond.beds.packing").powder_bed
        assert sintercond.contacts.ContactTable is importlib.import_module("sintercond.contacts.network").ContactTable
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        sintercond.laws.no_such_name  # noqa: B018


def test_the_package_and_its_folders_import_without_jax_md_or_matplotlib_or_a_warning():
    code = ("import sys, warnings; warnings.simplefilter('error');"
            "import sintercond, sintercond.laws, sintercond.contacts, sintercond.beds, sintercond.output, sintercond.sim;"
            "sintercond.laws.neck_radius; sintercond.output.write_vtp;"
            "loaded = [m for m in sys.modules if m.split('.')[0] in ('jax_md', 'matplotlib')]; assert not loaded, loaded")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
