"""The public face: ``relight`` re-exports a small API loaded on first use, and every
module's ``__all__`` is true (each name exists, each public definition is listed)."""
from __future__ import annotations

import ast
import importlib
import os
import pkgutil
import subprocess
import sys

import pytest

import relight

MODULES = sorted(m.name for m in pkgutil.walk_packages(relight.__path__, "relight.")
                 if m.name != "relight.__main__")


def _source(module: str) -> str:
    spec = importlib.util.find_spec(module)
    return open(spec.origin, encoding="utf-8").read()


@pytest.mark.parametrize("name", MODULES)
def test_every_all_name_exists(name):
    mod = importlib.import_module(name)
    assert isinstance(getattr(mod, "__all__", None), list), f"{name} has no __all__"
    missing = [n for n in mod.__all__
               if not hasattr(mod, n) and importlib.util.find_spec(f"{name}.{n}") is None]
    assert not missing, f"{name}.__all__ names what does not exist: {missing}"
    assert len(set(mod.__all__)) == len(mod.__all__), f"{name}.__all__ lists a name twice"


@pytest.mark.parametrize("name", MODULES)
def test_every_public_function_and_class_is_in_all(name):
    tree = ast.parse(_source(name))
    defined = [n.name for n in tree.body
               if isinstance(n, (ast.FunctionDef, ast.ClassDef)) and not n.name.startswith("_")]
    unlisted = sorted(set(defined) - set(importlib.import_module(name).__all__))
    assert not unlisted, f"{name}: public but not in __all__: {unlisted}"


def test_top_level_api_resolves_to_its_owners():
    for n in relight.__all__:
        assert hasattr(relight, n), n
    assert relight.generate is importlib.import_module("relight.generator.run").generate
    assert relight.load_model is importlib.import_module("relight.net.predict").load_model
    assert relight.frames is importlib.import_module("relight.frames")
    with pytest.raises(AttributeError):
        relight.no_such_name   # noqa: B018


def test_import_relight_loads_neither_mitsuba_nor_torch():
    code = ("import sys, relight; print(sorted(m for m in ('torch', 'mitsuba', 'drjit') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": os.path.dirname(os.path.dirname(relight.__file__))})
    assert out.stdout.strip() == "[]", out.stdout
