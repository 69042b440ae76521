"""``relight compare``: re-render under the predicted light, errors, report, bad input.

Uses one tiny generated dataset (48 px, 16 spp, 5 images) for the whole module.
"""
import json
import math
import os
import shutil

import numpy as np
import pytest

from relight import metrics
from relight.cli import main
from relight.predictions import PredictionsError, write_predictions
from relight.verify.compare import compare_predictions

N_IMAGES = 5
RES, SPP = 48, 16
NOISE_FLOOR_FACTOR = 1.0      # GT-as-prediction: RMSE(a, b) <= this * noise-floor RMSE (it is 0)
VISIBLE_FACTOR = 2.0          # lowered light: RMSE(a, b) >= this * noise-floor RMSE, each image
ANGLE_TOL_DEG = 1e-9
PAN_SHIFT_DEG = 60.0          # the known move of the light along its circle of constant tilt
TILT_DROP_DEG = 30.0          # the known move of the light toward the horizon


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from relight.generator.run import generate
    from relight.generator.sampling import GeneratorConfig
    path = tmp_path_factory.mktemp("verify_ds") / "ds"
    generate(path, count=N_IMAGES, seed=11, cfg=GeneratorConfig(res=RES, spp=SPP), progress=False)
    return str(path)


@pytest.fixture(scope="module")
def records(dataset):
    from relight.dataset import read_manifest
    return read_manifest(dataset)


def _gt_entries(records):
    from conftest import truth_entries
    return truth_entries(records)


def test_ground_truth_prediction_is_exact(dataset, records, tmp_path):
    path = tmp_path / "gt.json"
    write_predictions(path, _gt_entries(records), dataset=dataset)
    c = compare_predictions(path, progress=False)
    assert len(c.items) == N_IMAGES and not c.bad
    for it in c.items:
        for name, err in it.light_errors_deg.items():
            assert err == pytest.approx(0.0, abs=ANGLE_TOL_DEG), name
        # same scene, same light, same seed: the re-render is the original, bit for bit
        np.testing.assert_array_equal(it.rerender, it.original)
        assert it.image_errors["rmse"] <= NOISE_FLOOR_FACTOR * it.noise_floor["rmse"]
        assert it.noise_floor["rmse"] > 0.0        # another seed does differ: a real floor
        assert it.image_errors["ssim"] == pytest.approx(1.0)


def test_y_vector_prediction_matches(dataset, records, tmp_path):
    path = tmp_path / "y.json"
    write_predictions(path, [{"id": r["id"], "y": r["y"]} for r in records[:2]])
    c = compare_predictions(path, data_dir=dataset, progress=False)
    for it in c.items:
        assert it.light_errors_deg["direction"] == pytest.approx(0.0, abs=1e-6)
        np.testing.assert_allclose(it.rerender, it.original, atol=1e-5)


def test_moved_light_gives_that_error(dataset, records, tmp_path):
    entries = [{**e, "pan_deg": (e["pan_deg"] + PAN_SHIFT_DEG) % 360.0} for e in _gt_entries(records)]
    path = tmp_path / "moved.json"
    write_predictions(path, entries, dataset=dataset)
    c = compare_predictions(path, progress=False)
    for it, rec in zip(c.items, records):
        t = math.radians(rec["light"]["tilt_deg"])
        # two directions at equal tilt t, pans dp apart: cos(angle) = cos^2 t cos dp + sin^2 t
        expected = math.degrees(math.acos(math.cos(t) ** 2 * math.cos(math.radians(PAN_SHIFT_DEG))
                                          + math.sin(t) ** 2))
        assert it.light_errors_deg["direction"] == pytest.approx(expected, abs=1e-6)
        via_metrics = metrics.direction_error_deg(rec["pan_rel_deg"] + PAN_SHIFT_DEG, rec["light"]["tilt_deg"],
                                                  rec["pan_rel_deg"], rec["light"]["tilt_deg"])
        assert it.light_errors_deg["direction"] == pytest.approx(float(via_metrics), abs=ANGLE_TOL_DEG)
        assert it.light_errors_deg["pan"] == pytest.approx(PAN_SHIFT_DEG, abs=1e-6)
        assert it.light_errors_deg["colour"] == pytest.approx(0.0, abs=ANGLE_TOL_DEG)


def test_lowered_light_is_visible(dataset, records, tmp_path):
    # Lowering the light by TILT_DROP_DEG at the same pan moves it along a great circle
    # through the zenith: the direction error is exactly TILT_DROP_DEG.
    entries = [{**e, "tilt_deg": e["tilt_deg"] - TILT_DROP_DEG} for e in _gt_entries(records)]
    write_predictions(tmp_path / "low.json", entries, dataset=dataset)
    c = compare_predictions(tmp_path / "low.json", progress=False)
    for it in c.items:
        assert it.light_errors_deg["direction"] == pytest.approx(TILT_DROP_DEG, abs=1e-9)
        assert it.light_errors_deg["tilt"] == pytest.approx(TILT_DROP_DEG, abs=1e-9)
        assert it.light_errors_deg["pan"] == pytest.approx(0.0, abs=1e-9)
        # (b) and (c) visibly differ: the image error is well above the noise floor
        assert it.image_errors["rmse"] >= VISIBLE_FACTOR * it.noise_floor["rmse"], it.id
        assert it.image_errors["ssim"] < 1.0


def _run(argv, capsys):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_report_through_cli(dataset, records, tmp_path, capsys):
    entries = [{**e, "pan_deg": (e["pan_deg"] + 25.0) % 360.0} for e in _gt_entries(records)]
    write_predictions(tmp_path / "p.json", entries, dataset=dataset)
    out = tmp_path / "report"
    code, stdout, _ = _run(["compare", str(tmp_path / "p.json"), "--out", str(out), "--quiet",
                            "--max-columns", "4"], capsys)
    assert code == 0, stdout
    for name in ("figure3.png", "figure3.pdf", "metrics.csv", "summary.json", "tables.md",
                 "index.html", "settings.json"):
        assert (out / name).is_file(), name
    assert sorted(os.listdir(out / "panels")) == sorted(f"{r['id']}.png" for r in records)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n"] == N_IMAGES and summary["n_bad"] == 0
    assert len(summary["figure3_ids"]) == 4
    assert "strength" in " ".join(summary["notes"])
    lines = (out / "metrics.csv").read_text().strip().splitlines()
    assert len(lines) == N_IMAGES + 1 and "direction_error_deg" in lines[0] and "noise_rmse" in lines[0]
    assert "Table 1" in (out / "tables.md").read_text()
    assert json.loads((out / "settings.json").read_text())["command"] == "compare"
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".report")]  # no temp left
    # running again replaces the old report
    assert _run(["compare", str(tmp_path / "p.json"), "--out", str(out), "--quiet", "--limit", "2"],
                capsys)[0] == 0
    assert json.loads((out / "summary.json").read_text())["n"] == 2


def test_out_that_is_not_a_report_is_refused(dataset, records, tmp_path, capsys):
    write_predictions(tmp_path / "p.json", _gt_entries(records)[:1], dataset=dataset)
    (tmp_path / "precious").mkdir()
    (tmp_path / "precious" / "file.txt").write_text("keep")
    code, _, err = _run(["compare", str(tmp_path / "p.json"), "--out", str(tmp_path / "precious")], capsys)
    assert code == 2 and "not a relight compare report" in err
    assert (tmp_path / "precious" / "file.txt").read_text() == "keep"


# --- bad input: each gives exit 2, one stderr line naming the entry, and no report ------------

def _raw_predictions(dataset, body: str) -> str:
    return '{"format": "relight.predictions/v1", "dataset": %s, "predictions": [%s]}' % (
        json.dumps(dataset), body)


def _good(rec) -> str:
    return json.dumps({"id": rec["id"], "pan_deg": rec["pan_rel_deg"], "tilt_deg": rec["light"]["tilt_deg"],
                       "rgb": rec["light"]["rgb"]})


BAD_BODIES = {
    "malformed_json": ('{"id": "000000", "pan_deg": 10, ', "malformed JSON"),
    "unknown_id": ('{"id": "999999", "pan_deg": 10, "tilt_deg": 40, "rgb": [1, 1, 1]}', "999999"),
    "duplicate_id": ('{GOOD0}, {GOOD0}', "duplicate"),
    "escaping_id": ('{"id": "../x", "pan_deg": 10, "tilt_deg": 40, "rgb": [1, 1, 1]}', "../x"),
    "nan": ('{"id": "000000", "pan_deg": NaN, "tilt_deg": 40, "rgb": [1, 1, 1]}', "000000"),
    "missing_number": ('{"id": "000000", "tilt_deg": 40, "rgb": [1, 1, 1]}', "000000"),
    "zero_rgb": ('{"id": "000000", "pan_deg": 10, "tilt_deg": 40, "rgb": [0, 0, 0]}', "000000"),
    "negative_rgb": ('{"id": "000000", "pan_deg": 10, "tilt_deg": 40, "rgb": [1, -0.5, 1]}', "000000"),
}


@pytest.mark.parametrize("case", sorted(BAD_BODIES))
def test_bad_predictions(case, dataset, records, tmp_path, capsys):
    body, expected = BAD_BODIES[case]
    body = body.replace("{GOOD0}", _good(records[0]))
    if case != "malformed_json":
        body = _good(records[1]) + ", " + body      # a good entry first: no partial report
    path = tmp_path / "p.json"
    path.write_text(_raw_predictions(dataset, body) if case != "malformed_json"
                    else _raw_predictions(dataset, body)[:-3])
    out = tmp_path / "report"
    code, _, err = _run(["compare", str(path), "--out", str(out), "--quiet"], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and expected in err, err
    assert not out.exists()
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".report")]


@pytest.fixture
def broken_dataset(dataset, tmp_path):
    copy = tmp_path / "ds"
    shutil.copytree(dataset, copy)
    return copy


@pytest.mark.parametrize("case", ["missing_scene", "unknown_version"])
def test_bad_scene_file(case, broken_dataset, records, tmp_path, capsys):
    victim = records[2]
    scene = broken_dataset / victim["scene"]
    if case == "missing_scene":
        scene.unlink()
    else:
        d = json.loads(scene.read_text())
        d["format"] = "relight.scene/v99"
        scene.write_text(json.dumps(d))
    write_predictions(tmp_path / "p.json", _gt_entries(records), dataset=str(broken_dataset))
    out = tmp_path / "report"
    # no --quiet: a progress bar must not add lines to stderr when it is not a terminal
    code, _, err = _run(["compare", str(tmp_path / "p.json"), "--out", str(out)], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and repr(victim["id"]) in err, err
    assert ("v99" in err) if case == "unknown_version" else ("cannot read scene file" in err)
    assert not out.exists()


def test_skip_bad_continues_and_lists(broken_dataset, records, tmp_path, capsys):
    (broken_dataset / records[2]["scene"]).unlink()
    body = ", ".join([_good(records[0]), _good(records[2]),
                      '{"id": "000001", "pan_deg": NaN, "tilt_deg": 40, "rgb": [1, 1, 1]}',
                      '{"id": "424242", "pan_deg": 1, "tilt_deg": 40, "rgb": [1, 1, 1]}',
                      _good(records[3])])
    path = tmp_path / "p.json"
    path.write_text(_raw_predictions(str(broken_dataset), body))
    out = tmp_path / "report"
    code, stdout, _ = _run(["compare", str(path), "--out", str(out), "--quiet", "--skip-bad"], capsys)
    assert code == 0 and "3 bad entries" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n"] == 2 and summary["n_bad"] == 3
    reasons = " ".join(b["entry"] + " " + b["reason"] for b in summary["bad"])
    for needle in (records[2]["id"], "000001", "424242"):
        assert needle in reasons
    assert "424242" in (out / "index.html").read_text() and "424242" in (out / "tables.md").read_text()


def test_no_dataset_is_an_error(records, tmp_path, capsys):
    write_predictions(tmp_path / "p.json", _gt_entries(records)[:1])
    code, _, err = _run(["compare", str(tmp_path / "p.json"), "--out", str(tmp_path / "r")], capsys)
    assert code == 2 and "--data" in err


def test_colour_only_predictions_keep_true_direction(tmp_path):
    # A colour-constancy baseline's file has no direction: compare keeps the true one,
    # so the direction error is exactly 0 and only the colour error remains.
    from relight.predictions import read_predictions, write_predictions
    path = tmp_path / "colour.json"
    write_predictions(path, [{"id": "a", "rgb": [1.0, 0.9, 0.8]}], colour_only=True)
    pred = read_predictions(path).predictions[0]
    assert pred.colour_only
    pan, tilt, rgb = pred.resolve(30.0, direction_if_missing=(123.0, 45.0))
    assert (pan, tilt) == (123.0, 45.0) and abs(np.linalg.norm(rgb) - 1) < 1e-12
    with pytest.raises(PredictionsError):
        pred.resolve(30.0)
    path.write_text('{"format": "relight.predictions/v1", "colour_only": true, '
                    '"predictions": [{"id": "a", "pan_deg": 1, "tilt_deg": 40}]}')
    with pytest.raises(PredictionsError, match="missing rgb"):
        read_predictions(path)
