"""``relight invert`` and ``relight baseline`` end to end on a tiny generated dataset."""
from __future__ import annotations

import json

import numpy as np
import pytest

from relight.cli import main
from relight.metrics import light_errors

from conftest import NO_TIME_BUDGET

# 32 px targets at 16 spp, fitted at 32 px: one pixel spans ~0.7 m of floor at the
# scene centre, and the cast-shadow edge of a ~1 m object moves ~0.5 m per degree of
# light tilt at 30 m, so a 2 deg error moves shadows by about a pixel: clearly
# visible to the loss. Measured errors at these settings are well below 1 deg.
DIRECTION_TOL_DEG = 2.0
COLOUR_TOL_DEG = 1.0
N_IMAGES = 2


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, mi):
    from relight.generator.run import generate
    from relight.generator.sampling import GeneratorConfig
    out = tmp_path_factory.mktemp("inv_data")
    generate(out, count=N_IMAGES, seed=5, cfg=GeneratorConfig(res=32, spp=16), progress=False)
    return out


def _errors(data_dir, pred_path):
    from relight.dataset import read_manifest
    recs = {r["id"]: r for r in read_manifest(data_dir)}
    preds = json.loads(pred_path.read_text())["predictions"]
    out = []
    for p in preds:
        r = recs[p["id"]]
        out.append(light_errors(p["pan_deg"], p["tilt_deg"], p["rgb"], r["pan_rel_deg"],
                                r["light"]["tilt_deg"], r["light"]["rgb"]))
    return out


def test_invert_recovers_known_light(dataset, tmp_path):
    out = tmp_path / "inv.json"
    assert main(["invert", "--data", str(dataset), "--split", "all", "--out", str(out), "--quiet",
                 *NO_TIME_BUDGET]) == 0
    errs = _errors(dataset, out)
    assert len(errs) == N_IMAGES
    for e in errs:
        assert e["direction"] < DIRECTION_TOL_DEG, e
        assert e["colour"] < COLOUR_TOL_DEG, e
    doc = json.loads(out.read_text())
    assert doc["method"] == "inverse" and doc["settings"]["init"] == "grid"
    assert all(p["renders"] > 0 and p["iterations"] > 0 for p in doc["predictions"])
    trace = (tmp_path / "inv.trace.csv").read_text().splitlines()
    assert trace[0].startswith("id,iteration,stage") and len(trace) > N_IMAGES * 3
    from relight.predictions import read_predictions
    assert len(read_predictions(out).predictions) == N_IMAGES  # a valid predictions file


def test_invert_single_image_from_prediction_file(dataset, tmp_path):
    from relight.dataset import read_manifest
    from relight.predictions import write_predictions
    rec = read_manifest(dataset)[0]
    # start 5 deg off in pan and tilt (the role of a network prediction)
    start = tmp_path / "start.json"
    write_predictions(start, [{"id": rec["id"], "pan_deg": rec["pan_rel_deg"] + 5.0,
                               "tilt_deg": min(rec["light"]["tilt_deg"], 85.0) - 5.0, "rgb": [1, 1, 1]}])
    out = tmp_path / "one.json"
    assert main(["invert", "--scene", str(dataset / rec["scene"]), "--image", str(dataset / rec["exr"]),
                 "--init", str(start), "--out", str(out), "--quiet", "--max-iters", "20", *NO_TIME_BUDGET]) == 0
    (e,) = _errors(dataset, out)
    assert e["direction"] < DIRECTION_TOL_DEG and e["colour"] < COLOUR_TOL_DEG


def test_invert_bad_inputs(dataset, tmp_path, capsys):
    assert main(["invert", "--scene", str(tmp_path / "missing.json"), "--image", "x.exr",
                 "--out", str(tmp_path / "o.json")]) == 2
    assert main(["invert", "--data", str(dataset), "--split", "all", "--limit", "1",
                 "--init", str(tmp_path / "nope.json"), "--out", str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("relight: error:") for line in err)
    assert not (tmp_path / "o.json").exists()


@pytest.mark.parametrize("name", ["gray-world", "white-patch", "shades-of-gray", "gray-edge"])
def test_baseline_command(dataset, tmp_path, name, capsys):
    import re

    from relight.dataset import read_manifest
    from relight.inverse.colour_baselines import read_colour_predictions
    from relight.metrics import colour_error_deg
    out = tmp_path / f"{name}.json"
    assert main(["baseline", name, "--data", str(dataset), "--split", "all", "--out", str(out)]) == 0
    got = read_colour_predictions(out)
    assert len(got) == N_IMAGES
    assert all(np.isclose(np.linalg.norm(v), 1.0) and (v >= 0).all() for v in got.values())
    assert json.loads(out.read_text())["method"] == name
    # the printed colour error is the file's estimates against the manifest's lights
    truth = {r["id"]: r["light"]["rgb"] for r in read_manifest(dataset)}
    err = [float(colour_error_deg(v, truth[k])) for k, v in got.items()]
    m = re.search(r"mean (\d+\.\d\d), median (\d+\.\d\d) degrees", capsys.readouterr().out)
    assert m and float(m.group(1)) == pytest.approx(np.mean(err), abs=0.006)
    assert float(m.group(2)) == pytest.approx(np.median(err), abs=0.006)
