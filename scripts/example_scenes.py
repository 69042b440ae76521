"""Write the example scene files of ``scenes/`` (and, on request, their reference renders).

    python scripts/example_scenes.py                        # rewrite scenes/*.json, scenes/meshes/*.obj
    python scripts/example_scenes.py --update-references    # also tests/data/scene_refs.npz

The scene files are committed; ``tests/test_scenes.py`` renders each one small and
compares with ``tests/data/scene_refs.npz`` to catch format and render drift. Run
``--update-references`` only after a deliberate change of the renderer or format.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from relight.generator.sampling import GeneratorConfig, sample_scene  # noqa: E402
from relight.scene.spec import (CameraSpec, LightSpec, ObjectSpec, RenderSpec, RoomSpec,  # noqa: E402
                                SceneSpec)

SCENES = os.path.join(REPO, "scenes")
REFERENCES = os.path.join(REPO, "tests", "data", "scene_refs.npz")
REFERENCE_RES, REFERENCE_SPP = 24, 16


def plain(grey: float) -> dict:
    return {"kind": "checker", "seed": 0, "cells": 2, "angle": 0.0, "colors": [[grey] * 3, [grey] * 3]}


def sphere_right() -> SceneSpec:
    """The conventions' check: a grey sphere lit from the camera's right (pan_rel 90)."""
    sphere = ObjectSpec(family="superquadric", params={"e1": 1.0, "e2": 1.0, "axes": [1.0, 1.0, 1.0]},
                        position_m=(0.0, 0.0), yaw_deg=0.0, size_m=1.5, reflectance=(0.6, 0.6, 0.6),
                        roughness=0.0)
    room = RoomSpec(n_walls=4, inradius_m=110.0, height_m=80.0, rotation_deg=0.0,
                    wall_textures=tuple(plain(0.5) for _ in range(4)), floor_texture=plain(0.5),
                    texture_res=16)
    return SceneSpec(id="sphere_right", camera=CameraSpec(tilt_deg=30.0, fov_deg=30.0),
                     light=LightSpec(r_m=30.0, pan_deg=90.0, tilt_deg=30.0, rgb=(1.0, 1.0, 1.0)),
                     room=room, objects=(sphere,),
                     render=RenderSpec(res=128, spp=16, max_depth=4, seed=1, sampler="multijitter"))


def ziggurat_obj(levels: int = 4) -> str:
    """A stepped tower of square slabs (z up), a small user mesh in OBJ text."""
    vertices, faces = [], []
    for k in range(levels):
        half, z0, z1 = 1.0 - 0.2 * k, 0.5 * k, 0.5 * (k + 1)
        base = len(vertices)
        for z in (z0, z1):
            vertices += [(-half, -half, z), (half, -half, z), (half, half, z), (-half, half, z)]
        b = [base + i + 1 for i in range(8)]  # OBJ indices are 1-based
        faces += [(b[0], b[2], b[1]), (b[0], b[3], b[2]), (b[4], b[5], b[6]), (b[4], b[6], b[7])]
        for i in range(4):
            j = (i + 1) % 4
            faces += [(b[i], b[j], b[4 + j]), (b[i], b[4 + j], b[4 + i])]
    lines = ["# stepped tower, z up, written by scripts/example_scenes.py"]
    lines += [f"v {x:.4f} {y:.4f} {z:.4f}" for x, y, z in vertices]
    lines += [f"f {a} {b} {c}" for a, b, c in faces]
    return "\n".join(lines) + "\n"


def user_mesh(mesh_rel: str) -> SceneSpec:
    """A default SID2 scene whose first object is the user mesh (path relative to scenes/)."""
    spec = sample_scene(GeneratorConfig(), 3, 0)
    first = dataclasses.replace(spec.objects[0], family="mesh", params={}, mesh_path=mesh_rel)
    return dataclasses.replace(spec, id="user_mesh", objects=(first,) + spec.objects[1:])


def example_scenes() -> dict[str, SceneSpec]:
    return {
        "sphere_right": sphere_right(),
        "sid2_default": dataclasses.replace(sample_scene(GeneratorConfig(), 0, 0), id="sid2_default"),
        "user_mesh": user_mesh("meshes/ziggurat.obj"),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--update-references", action="store_true",
                    help=f"also render each scene at {REFERENCE_RES} px into {os.path.relpath(REFERENCES, REPO)}")
    args = ap.parse_args()
    os.makedirs(os.path.join(SCENES, "meshes"), exist_ok=True)
    with open(os.path.join(SCENES, "meshes", "ziggurat.obj"), "w") as f:
        f.write(ziggurat_obj())
    for name, spec in example_scenes().items():
        spec.save(os.path.join(SCENES, f"{name}.json"))
        print(f"scenes/{name}.json")
    if args.update_references:
        from relight import backend
        from relight.scene.build import render_spec
        from relight.scene.spec import load_scene
        backend.init()
        refs = {}
        for name in example_scenes():
            spec = load_scene(os.path.join(SCENES, f"{name}.json"))
            small = dataclasses.replace(spec, render=dataclasses.replace(spec.render, res=REFERENCE_RES,
                                                                         spp=REFERENCE_SPP))
            refs[name] = render_spec(small).astype(np.float32)
        np.savez_compressed(REFERENCES, **refs)
        print(os.path.relpath(REFERENCES, REPO))
    return 0


if __name__ == "__main__":
    sys.exit(main())
