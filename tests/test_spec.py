"""Scene files: JSON round trip, versioning, validation."""
import json

import pytest

from relight.generator.sampling import GeneratorConfig, sample_scene
from relight.scene.spec import SceneFileError, SceneSpec, load_scene


def test_json_round_trip(tmp_path):
    spec = sample_scene(GeneratorConfig(), 3, 17)
    path = tmp_path / "s.json"
    spec.save(path)
    assert load_scene(path) == spec
    assert json.loads(path.read_text())["format"] == "relight.scene/v1"


def test_unknown_version_and_malformed(tmp_path):
    d = sample_scene(GeneratorConfig(), 3, 17).to_dict()
    d["format"] = "relight.scene/v9"
    with pytest.raises(SceneFileError, match="unknown scene format"):
        SceneSpec.from_dict(d)
    with pytest.raises(SceneFileError, match="not valid JSON"):
        SceneSpec.from_json("{not json")
    bad = sample_scene(GeneratorConfig(), 3, 17).to_dict()
    del bad["light"]
    with pytest.raises(SceneFileError):
        SceneSpec.from_dict(bad)
    bad = sample_scene(GeneratorConfig(), 3, 17).to_dict()
    bad["light"]["rgb"] = [0, 0, 0]
    with pytest.raises(SceneFileError):
        SceneSpec.from_dict(bad)
    bad = sample_scene(GeneratorConfig(), 3, 17).to_dict()
    bad["camera"]["tilt_deg"] = float("nan")
    with pytest.raises(SceneFileError):
        SceneSpec.from_dict(bad)
    with pytest.raises(SceneFileError, match="cannot read"):
        load_scene(tmp_path / "missing.json")


def test_with_light_changes_only_the_light():
    spec = sample_scene(GeneratorConfig(), 3, 17)
    moved = spec.with_light(pan_rel_deg=90.0, tilt_deg=45.0, rgb=(2, 1, 1))
    assert moved.pan_rel_deg == pytest.approx(90.0) and moved.light.tilt_deg == 45.0
    assert moved.light.rgb == pytest.approx((2 / 6 ** 0.5, 1 / 6 ** 0.5, 1 / 6 ** 0.5))
    assert moved.light.r_m == spec.light.r_m and moved.objects == spec.objects and moved.camera == spec.camera
    assert spec.with_light() == spec
