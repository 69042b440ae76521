"""The import rules of README "Layout", checked on the package's own imports.

Every ``import relight...`` / ``from relight... import ...`` in ``relight/`` (at module
level or inside a function: both load the module) is an arrow from one *room* (a
top-level module such as ``relight/frames.py``, or a subpackage such as
``relight/scene/``) to another. The rooms stand on the layers of :data:`LAYERS`; a
room imports only rooms on lower layers, so no import runs back up and no two rooms
of one layer know each other. Nothing is imported to read the arrows: the files are
parsed.
"""
from __future__ import annotations

import ast
import os

import pytest

ROOT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "relight")

# bottom to top; README "Layout" draws the same picture
LAYERS = (
    {"errors", "frames", "colour", "timing", "children"}, # foundations: no relight import but these
    {"fileio", "backend", "metrics"},
    {"imageio", "engine", "predictions", "render"},       # files, the Dask engine, the one render call
    {"scene", "probe"},                                   # scene files -> images; probe spheres -> light
    {"dataset"},                                          # the dataset format (readers)
    {"generator", "net", "verify"},                       # the pipeline's stages
    {"inverse", "experiments"},                           # baselines over the network; the MID experiment
    {"commands"},                                         # one module per CLI group
    {"cli"},
    {"__main__"},
)
STAGES = ("net", "verify", "inverse", "probe")
FACE = "__init__"   # relight/__init__.py: the public API, above everything


def _modules() -> dict[str, str]:
    """Dotted module name -> file, for every module of the package."""
    found = {}
    for folder, dirs, files in os.walk(ROOT):
        dirs[:] = sorted(d for d in dirs if not d.startswith((".", "__pycache__")))
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                rel = os.path.relpath(path, os.path.dirname(ROOT))[:-3].split(os.sep)
                if rel[-1] == "__init__":
                    rel = rel[:-1]
                found[".".join(rel)] = path
    return found


MODULES = _modules()


def _imports(path: str) -> set[str]:
    """Modules of the package that a file imports (a ``from P import name`` whose name is
    a submodule counts as that submodule)."""
    tree = ast.parse(open(path, encoding="utf-8").read(), path)
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "relight"}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] == "relight":
            for a in node.names:
                sub = f"{node.module}.{a.name}"
                out.add(sub if sub in MODULES else node.module)
    return out


def _room(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else FACE


def _layer(room: str) -> int:
    if room == FACE:
        return len(LAYERS)
    for k, rooms in enumerate(LAYERS):
        if room in rooms:
            return k
    raise AssertionError(f"relight/{room}: on no layer of LAYERS (add it to README 'Layout' and here)")


ARROWS = {(mod, imp) for mod, path in MODULES.items() for imp in _imports(path) if imp != mod}


def test_every_import_names_a_module_of_the_package():
    missing = sorted({imp for _, imp in ARROWS if imp not in MODULES})
    assert not missing, f"imports of modules that do not exist: {missing}"


def test_every_room_stands_on_one_layer():
    rooms = [r for layer in LAYERS for r in layer]
    assert len(rooms) == len(set(rooms))
    for mod in MODULES:
        _layer(_room(mod))


def _against_layers(arrows) -> list[str]:
    return sorted(f"{a} -> {b}" for a, b in arrows
                  if _room(a) != _room(b) and _layer(_room(b)) >= _layer(_room(a)))


def test_no_import_runs_back_up_or_sideways():
    bad = _against_layers(ARROWS)
    assert not bad, "imports that run back up or across a layer:\n" + "\n".join(bad)


def test_scene_never_imports_probe():
    bad = sorted(f"{a} -> {b}" for a, b in ARROWS if _room(a) == "scene" and _room(b) == "probe")
    assert not bad, bad


@pytest.mark.parametrize("stage", STAGES)
def test_stages_never_import_the_generator_or_an_experiment(stage):
    bad = sorted(f"{a} -> {b}" for a, b in ARROWS
                 if _room(a) == stage and _room(b) in ("generator", "experiments"))
    assert not bad, bad


def test_no_circle_of_modules():
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for a, b in ARROWS:
        graph[a].add(b)
    state: dict[str, int] = {}      # 1: on the current path, 2: done

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                raise AssertionError("import circle: " + " -> ".join(path[path.index(n):] + [n]))
            if n not in state:
                visit(n, path + [n])
        state[m] = 2
    for m in sorted(graph):
        if m not in state:
            visit(m, [m])


def test_the_rules_catch_an_import_that_runs_back_up_or_sideways():
    # the check is not vacuous: it reads the package's arrows, and would refuse these
    assert len(ARROWS) > 100 and ("relight.scene.build", "relight.render") in ARROWS
    assert _against_layers({("relight.render", "relight.scene.noise")}) == ["relight.render -> relight.scene.noise"]
    assert _against_layers({("relight.net.data", "relight.verify.compare")})   # two stages of one layer
    assert not _against_layers({("relight.scene.build", "relight.scene.spec")})   # inside one room
