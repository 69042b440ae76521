"""Multi-coloured objects (``--object-parts``): the paper's one colour per mesh part.

The mesh split (``shapes.part_labels``), the scene-file field, the generator setting and
the render path (a per-face albedo attribute in the one loaded scene)."""
import json

import numpy as np
import pytest

from relight.scene import shapes as S
from relight.generator.sampling import GeneratorConfig, sample_scene
from relight.scene.spec import ObjectSpec, SceneFileError, SceneSpec


def _mesh(family="superquadric", seed=0):
    return S.make_mesh(family, S.sample_shape_params(family, np.random.default_rng(seed)))


@pytest.mark.parametrize("family", S.FAMILIES)
@pytest.mark.parametrize("n", [2, 5, 16, S.MAX_PARTS])
def test_part_labels_cover_every_part_and_are_deterministic(family, n):
    mesh = _mesh(family, 3)
    labels = S.part_labels(mesh, n)
    assert labels.shape == (len(mesh.faces),)
    assert set(np.unique(labels)) == set(range(n))           # every part used, no other label
    assert np.array_equal(labels, S.part_labels(_mesh(family, 3), n))


def test_part_labels_are_compact_patches():
    # Voronoi cells are compact: the faces' spread about their own part's centre is a
    # small share of their spread about the mesh centre (a random labelling keeps ~100%);
    # two parts split the mesh into pieces of comparable size
    mesh = _mesh("superquadric", 1)
    c = mesh.vertices[mesh.faces.astype(np.int64)].mean(1).astype(np.float64)
    labels = S.part_labels(mesh, 8)
    centres = np.stack([c[labels == j].mean(0) for j in range(8)])
    within = ((c - centres[labels]) ** 2).sum()
    total = ((c - c.mean(0)) ** 2).sum()
    assert within < 0.3 * total, within / total
    shuffled = np.random.default_rng(0).permutation(labels)
    centres_s = np.stack([c[shuffled == j].mean(0) for j in range(8)])
    assert ((c - centres_s[shuffled]) ** 2).sum() > 0.9 * total
    halves = np.bincount(S.part_labels(mesh, 2))
    assert halves.min() > 0.2 * halves.sum()


def test_part_labels_one_part_and_bad_counts():
    mesh = _mesh()
    assert not S.part_labels(mesh, 1).any()
    for bad in (0, S.MAX_PARTS + 1):
        with pytest.raises(ValueError):
            S.part_labels(mesh, bad)


def _obj(**kw):
    base = dict(family="primitive", params=S.sample_shape_params("primitive", np.random.default_rng(0)),
                position_m=(0.0, 0.0), yaw_deg=0.0, size_m=1.5, reflectance=(0.5, 0.5, 0.5), roughness=0.0)
    return ObjectSpec(**{**base, **kw})


def test_scene_file_field_round_trip_and_validation(tmp_path):
    plain = sample_scene(GeneratorConfig(object_parts=(1, 1)), 3, 17)
    assert "part_reflectances" not in plain.to_json()     # one-colour files unchanged
    parted = sample_scene(GeneratorConfig(object_parts=(3, 3)), 3, 17)
    assert all(len(o.part_reflectances) == 3 and o.reflectance == o.part_reflectances[0]
               for o in parted.objects)
    assert SceneSpec.from_json(parted.to_json()) == parted
    d = json.loads(parted.to_json())
    assert all(len(o["part_reflectances"]) == 3 for o in d["objects"])
    for bad in ([[0.5, 0.5, 0.5]], [[0.5, 0.5]] * 2, [[0.5, 0.5, 1.5]] * 2, [[0.5] * 3] * (S.MAX_PARTS + 1),
                [[0.5, float("nan"), 0.5]] * 2, "red"):
        with pytest.raises(SceneFileError):
            _obj(part_reflectances=bad)


def test_generator_parts_change_only_the_objects():
    cfg1, cfg4 = GeneratorConfig(res=32, spp=4, object_parts=(1, 1)), GeneratorConfig(res=32, spp=4, object_parts=(2, 6))
    counts = []
    for i in range(20):
        a, b = sample_scene(cfg1, 5, i), sample_scene(cfg4, 5, i)
        assert (a.camera, a.light, a.room) == (b.camera, b.light, b.room)
        # object count, sizes and places are drawn before the colours; later objects'
        # shapes follow the extra colour draws, so only the first one's shape is shared
        assert [(o.size_m, o.position_m) for o in a.objects] == [(o.size_m, o.position_m) for o in b.objects]
        assert (a.objects[0].family, a.objects[0].params) == (b.objects[0].family, b.objects[0].params)
        assert all(not o.part_reflectances for o in a.objects)
        counts += [len(o.part_reflectances) for o in b.objects]
    assert set(counts) == {2, 3, 4, 5, 6}


def test_generator_config_refuses_bad_part_ranges():
    from relight.errors import ConfigError
    for bad in ((0, 1), (3, 2), (1, S.MAX_PARTS + 1)):
        with pytest.raises(ConfigError, match="object_parts"):
            GeneratorConfig(object_parts=bad)


def test_parts_render_their_own_colours(mi):
    # a box with red and blue parts under white light: the object shows pure red and
    # pure blue pixels; with every part the same grey it renders as the one-colour
    # object (same samples, same per-face albedo)
    import dataclasses

    from conftest import sphere_scene
    from relight.scene.build import render_spec
    base = sphere_scene(pan_rel_deg=0.0, tilt_deg=60.0, res=32, spp=8)
    sphere = base.objects[0]
    grey = render_spec(base)
    same = render_spec(dataclasses.replace(base, objects=(dataclasses.replace(
        sphere, part_reflectances=(sphere.reflectance,) * 4),)))
    assert np.allclose(grey, same, atol=1e-6)
    two = render_spec(dataclasses.replace(base, objects=(dataclasses.replace(
        sphere, reflectance=(0.8, 0.0, 0.0), part_reflectances=((0.8, 0.0, 0.0), (0.0, 0.0, 0.8))),)))
    red = (two[..., 0] > 0.05) & (two[..., 2] < 0.2 * two[..., 0])
    blue = (two[..., 2] > 0.05) & (two[..., 0] < 0.2 * two[..., 2])
    assert red.sum() >= 5 and blue.sum() >= 5, (red.sum(), blue.sum())
    # the floor is grey, so it cannot be either: both colours come from the sphere's parts
    assert np.abs(grey[..., 0] - grey[..., 2]).max() < 1e-3

