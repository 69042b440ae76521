"""The example scene files of scenes/: they load, render, and have not drifted."""
from __future__ import annotations

import dataclasses
import glob
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from relight.generator.sampling import GeneratorConfig
from relight.scene.spec import load_scene

from conftest import render_drift

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = sorted(glob.glob(os.path.join(REPO, "scenes", "*.json")))
CONFIGS = sorted(glob.glob(os.path.join(REPO, "scenes", "configs", "*.json")))
REFERENCES = os.path.join(REPO, "tests", "data", "scene_refs.npz")
REFERENCE_RES, REFERENCE_SPP = 24, 16   # as scripts/example_scenes.py writes them


def test_examples_are_there():
    names = {os.path.basename(p) for p in SCENES}
    assert {"sphere_right.json", "sid2_default.json", "user_mesh.json"} <= names


@pytest.mark.parametrize("path", SCENES, ids=os.path.basename)
def test_scene_renders_as_its_reference(mi, path):
    from relight.scene.build import render_spec
    spec = load_scene(path)
    small = dataclasses.replace(spec, render=dataclasses.replace(spec.render, res=REFERENCE_RES,
                                                                 spp=REFERENCE_SPP))
    name = os.path.splitext(os.path.basename(path))[0]
    with np.load(REFERENCES) as refs:
        assert name in refs, f"no reference for {name}: run scripts/example_scenes.py --update-references"
        drift = render_drift(render_spec(small), refs[name])   # another machine's rounding allowed
        assert drift is None, f"{name}: {drift}"


def test_user_mesh_path_is_relative_to_the_scene_file():
    with open(os.path.join(REPO, "scenes", "user_mesh.json")) as f:
        stored = json.load(f)["objects"][0]["mesh_path"]
    assert not os.path.isabs(stored)
    spec = load_scene(os.path.join(REPO, "scenes", "user_mesh.json"))
    assert os.path.isfile(spec.objects[0].mesh_path)


def test_sphere_right_is_lit_on_the_image_right(mi):
    """The conventions' check: pan_rel 90 lights the sphere's right half (image right)."""
    from relight.scene.build import render_spec
    spec = load_scene(os.path.join(REPO, "scenes", "sphere_right.json"))
    small = dataclasses.replace(spec, render=dataclasses.replace(spec.render, res=48, spp=16))
    img = render_spec(small).mean(-1)
    mid = img[18:30]             # rows through the sphere
    assert mid[:, 24:30].mean() > 1.5 * mid[:, 18:24].mean()


@pytest.mark.parametrize("path", CONFIGS, ids=os.path.basename)
def test_generator_configs_load(path):
    assert GeneratorConfig.from_file(path).render_spp >= 1


def test_render_cli_on_an_example(tmp_path):
    out = tmp_path / "x.png"
    r = subprocess.run([sys.executable, "-m", "relight.cli", "render", os.path.join(REPO, "scenes", "user_mesh.json"),
                        "--out", str(out), "--spp", "2"], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 0
