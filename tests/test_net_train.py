"""relight.net train / evaluate / predict end to end on a tiny rendered dataset,
and the CLI's handling of bad inputs (one line on stderr, exit 2)."""
import csv
import dataclasses
import json
import math
import os
import shutil

import numpy as np
import pytest
import torch

from relight.cli import main
from relight.errors import TrainingError
from relight.net.io import ModelFileError, load_model_file
from relight.net.loss import light_loss
from relight.net.model import LightNet, NetConfig
from relight.net.predict import load_model, predict_arrays, predict_files
from relight.net.train import TrainConfig, train
from relight.predictions import read_predictions
from conftest import tiny_dataset, untrained_model

RES = 32
OVERFIT_LOSS = 0.02          # a few images, many steps: the loss (~1 at start) gets near zero
OVERFIT_STEPS = 300
SAME_INPUT_ATOL = 1e-6       # same pixels through two paths give the same outputs


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return tiny_dataset(tmp_path_factory.mktemp("tiny"), count=8, seed=11, res=RES)


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    return untrained_model(tmp_path_factory.mktemp("m") / "net.safetensors", res=RES)


def test_tiny_overfit(tiny):
    from relight.net.data import LightDataset
    torch.manual_seed(0)
    torch.set_num_threads(1)
    ds = LightDataset(tiny, "all", res=RES)
    x = torch.stack([ds[i][0] for i in range(4)])
    y = torch.stack([ds[i][1] for i in range(4)])
    net = LightNet(NetConfig(res=RES, width=16))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    first = None
    for _ in range(OVERFIT_STEPS):
        loss = light_loss(net(x), y)
        first = first if first is not None else loss.item()
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert loss.item() < OVERFIT_LOSS < first


def test_resume_equals_uninterrupted(tiny, tmp_path):
    cfg2 = TrainConfig(data_dir=tiny, epochs=2, batch_size=4, res=RES, width=8, seed=5)
    cfg1 = TrainConfig(data_dir=tiny, epochs=1, batch_size=4, res=RES, width=8, seed=5)
    train(cfg2, tmp_path / "straight", progress=False)
    train(cfg1, tmp_path / "cut", progress=False)
    assert train(cfg1, tmp_path / "cut", progress=False)["epoch"] == 1  # the identical command resumes
    more_threads = dataclasses.replace(cfg1, threads=2)   # a machine resource, not a setting
    assert train(more_threads, tmp_path / "cut", progress=False)["epoch"] == 1
    with pytest.raises(TrainingError, match="--resume"):
        train(cfg2, tmp_path / "cut", progress=False)  # other settings: refuses without --resume
    row = train(cfg2, tmp_path / "cut", resume=True, progress=False)
    assert row["epoch"] == 2
    a = torch.load(tmp_path / "straight" / "checkpoint.pt", weights_only=True)
    b = torch.load(tmp_path / "cut" / "checkpoint.pt", weights_only=True)
    assert a["epoch"] == b["epoch"] == 2
    for k in a["model"]:
        assert torch.equal(a["model"][k], b["model"][k]), k
    assert a["optimiser"]["state"][0]["step"] == b["optimiser"]["state"][0]["step"]
    with open(tmp_path / "cut" / "log.csv") as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == ["1", "2"]
    assert os.path.getsize(tmp_path / "cut" / "curves.png") > 0
    settings = json.load(open(tmp_path / "cut" / "settings.json"))
    assert settings["epochs"] == 2 and settings["lr"] == 2e-4
    load_model_file(tmp_path / "cut")  # a run folder loads its best.safetensors


def test_predict_paths_agree(tiny, model_file, tmp_path):
    """An image given as a linear array, as the PNG write_png makes of it, and as an EXR
    all reach the network as the same 8-bit sRGB pixels."""
    from relight.imageio import read_exr, write_exr, write_png
    model = load_model(model_file)
    linear = read_exr(os.path.join(tiny, "exr", "000000.exr"))
    write_png(tmp_path / "a.png", linear)
    write_exr(tmp_path / "b.exr", linear)
    from PIL import Image
    Image.open(tmp_path / "a.png").save(tmp_path / "c.jpg", quality=100)
    arr = predict_arrays(model, [linear], [30.0])[0]
    files = predict_files(model, [str(tmp_path / "a.png"), str(tmp_path / "b.exr")], 30.0)
    for p in files:
        np.testing.assert_allclose(p["y"], arr["y"], atol=SAME_INPUT_ATOL)
    assert files[0]["id"] == "a" and "sRGB" in files[0]["assumed"] and "linear" in files[1]["assumed"]
    assert set(arr) == {"pan_deg", "tilt_deg", "rgb", "y", "cct_k", "duv", "kappa", "cone90_deg",
                        "camera_tilt_deg", "camera_tilt_source", "to_light_camera"}
    assert arr["camera_tilt_deg"] == 30.0 and arr["camera_tilt_source"] == "given"
    assert np.linalg.norm(arr["rgb"]) == pytest.approx(1.0)
    assert 0 <= arr["pan_deg"] < 360


def test_cli_predict_png_jpeg_exr(tiny, model_file, tmp_path, capsys):
    from PIL import Image

    from relight.imageio import read_exr, write_exr
    img_dir = tmp_path / "imgs"
    img_dir.mkdir()
    Image.open(os.path.join(tiny, "images", "000001.png")).resize((50, 40)).save(img_dir / "photo.jpg")
    Image.open(os.path.join(tiny, "images", "000002.png")).save(img_dir / "shot.png")
    write_exr(img_dir / "hdr.exr", read_exr(os.path.join(tiny, "exr", "000003.exr")))
    out = tmp_path / "pred.json"
    assert main(["predict", str(img_dir), "--model", model_file, "--camera-tilt", "30", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "linear (EXR)" in text and "8-bit sRGB" in text and "30" in text
    preds = read_predictions(out)
    assert sorted(p.id for p in preds.predictions) == ["hdr", "photo", "shot"]


def test_cli_mirror_average_predicts_the_mirrored_light_for_a_mirror_image(tiny, model_file, tmp_path):
    """predict --mirror-average on an image and on its mirror image: pan_rel p and 360 - p,
    the same tilt and colour (without the option an untrained network breaks this)."""
    from PIL import Image
    src = Image.open(os.path.join(tiny, "images", "000001.png"))
    img_dir = tmp_path / "imgs"
    img_dir.mkdir()
    src.save(img_dir / "a.png")
    src.transpose(Image.FLIP_LEFT_RIGHT).save(img_dir / "b.png")
    found = {}
    for opt in ([], ["--mirror-average"]):
        out = tmp_path / f"pred{len(opt)}.json"
        assert main(["predict", str(img_dir), "--model", model_file, "--out", str(out), *opt]) == 0
        found[bool(opt)] = {p["id"]: p for p in json.load(open(out))["predictions"]}
    a, b = found[True]["a"], found[True]["b"]
    from relight.metrics import pan_error_deg
    assert pan_error_deg(a["pan_deg"], 360.0 - b["pan_deg"]) < 1e-3
    assert a["tilt_deg"] == pytest.approx(b["tilt_deg"], abs=1e-4)
    assert np.allclose(a["rgb"], b["rgb"], atol=1e-5)
    a0, b0 = found[False]["a"], found[False]["b"]
    assert abs(a0["tilt_deg"] - b0["tilt_deg"]) > 1e-3 or not np.allclose(a0["rgb"], b0["rgb"], atol=1e-5)
    rep = tmp_path / "rep"
    assert main(["evaluate", "--model", model_file, "--data", tiny, "--split", "all", "--out", str(rep),
                 "--mirror-average"]) == 0
    assert json.load(open(rep / "metrics.json"))["model"] == f"{model_file} (mirror-averaged)"


def test_cli_evaluate_writes_report(tiny, model_file, tmp_path):
    rep = tmp_path / "rep"
    assert main(["evaluate", "--model", model_file, "--data", tiny, "--split", "all", "--out", str(rep)]) == 0
    for name in ("report.md", "metrics.json", "per_image.csv", "predictions.json"):
        assert (rep / name).is_file(), name
    tables = json.load(open(rep / "metrics.json"))["tables"]
    with open(rep / "per_image.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 8 == tables["overall"]["direction"]["n"]
    mean_dir = np.mean([float(r["direction_err_deg"]) for r in rows])
    assert tables["overall"]["direction"]["mean"] == pytest.approx(mean_dir, abs=1e-3)
    assert "Table 2" in open(rep / "report.md").read()
    assert len(read_predictions(rep / "predictions.json").predictions) == 8
    # the direction cones: reliability diagram, coverage and rank correlation
    metrics_doc = json.load(open(rep / "metrics.json"))
    unc = metrics_doc["uncertainty"]
    assert (rep / "reliability.png").stat().st_size > 0
    assert unc["n"] == 8 and 0 <= unc["cone90_coverage"] <= 1
    assert len(unc["reliability"]["observed"]) == len(unc["reliability"]["expected"])
    inside = np.mean([float(r["direction_err_deg"]) <= p.extra["cone90_deg"] for r, p in
                      zip(rows, read_predictions(rep / "predictions.json").predictions)])
    assert unc["cone90_coverage"] == pytest.approx(inside)
    assert "90% cone coverage" in open(rep / "report.md").read()
    # the colour as CCT: errors in kelvin and mireds over the images that have one
    cct = metrics_doc["cct"]
    assert cct["n"] + cct["n_no_cct"] == 8
    if cct["n"]:
        assert cct["kelvin"]["mean"] >= 0 and cct["mired"]["mean"] >= 0
    assert "CCT (mired)" in open(rep / "report.md").read()
    # the pan error by true tilt: its rows add up to Table 1's mean pan error
    by_tilt = metrics_doc["pan_by_tilt"]
    assert sum(r["n"] for r in by_tilt) == 8
    assert sum(r["share"] for r in by_tilt) == pytest.approx(tables["overall"]["pan_all"]["mean"], rel=1e-9)
    # Table 1's pan: the lights below the zenith, the zenith ones counted beside it
    zenith = [float(r["tilt_gt_deg"]) >= 90.0 for r in rows]
    assert tables["overall"]["pan"]["zenith_left_out"] == sum(zenith)
    assert tables["overall"]["pan"]["n"] == 8 - sum(zenith)
    if sum(zenith) < 8:
        assert tables["overall"]["pan"]["mean"] == pytest.approx(
            np.mean([float(r["pan_err_deg"]) for r, z in zip(rows, zenith) if not z]), abs=1e-3)
    assert "| Zenith left out |" in open(rep / "report.md").read()
    assert "Pan error by true light tilt" in open(rep / "report.md").read()


def _one_line_error(capsys):
    err = capsys.readouterr().err
    assert err.startswith("relight: error:") and err.count("\n") == 1, err
    return err


def test_cli_unreadable_image_exit_2(model_file, tmp_path, capsys):
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not a png at all")
    assert main(["predict", str(bad), "--model", model_file, "--out", str(tmp_path / "p.json")]) == 2
    assert "broken.png" in _one_line_error(capsys)
    assert not (tmp_path / "p.json").exists()
    assert main(["predict", str(tmp_path / "missing.png"), "--model", model_file,
                 "--out", str(tmp_path / "p.json")]) == 2
    _one_line_error(capsys)


@pytest.mark.parametrize("content", [b"garbage bytes", None])
def test_cli_wrong_model_file_exit_2(tiny, tmp_path, capsys, content):
    from safetensors.torch import save_file
    bad = tmp_path / "bad.safetensors"
    if content is None:  # a valid safetensors file that is not a relight model
        save_file({"w": torch.zeros(3)}, str(bad), metadata={"format": "something/else"})
    else:
        bad.write_bytes(content)
    img = os.path.join(tiny, "images", "000000.png")
    assert main(["predict", img, "--model", str(bad), "--out", str(tmp_path / "p.json")]) == 2
    assert "bad.safetensors" in _one_line_error(capsys)
    assert main(["evaluate", "--model", str(bad), "--data", tiny, "--out", str(tmp_path / "r")]) == 2
    _one_line_error(capsys)


def test_model_header_agrees_with_the_file_and_refuses_the_same(model_file, tmp_path):
    from safetensors.torch import save_file
    from relight.net.io import read_model_file, read_model_header
    config, state, info = read_model_file(model_file)
    assert state and read_model_header(model_file) == (config, info)
    run = tmp_path / "run"
    run.mkdir()
    shutil.copyfile(model_file, run / "best.safetensors")
    assert read_model_header(run) == (config, info)   # a run folder means its best weights
    bad = tmp_path / "bad.safetensors"
    save_file({"w": torch.zeros(3)}, str(bad), metadata={"format": "something/else"})
    for path, reason in ((bad, "something/else"), (tmp_path / "none.safetensors", "not found"),
                         (tmp_path, "without best.safetensors")):
        with pytest.raises(ModelFileError, match=reason):
            read_model_header(path)


def test_model_file_mismatched_weights(model_file, tmp_path):
    from safetensors import safe_open
    from safetensors.torch import save_file
    with safe_open(model_file, framework="pt") as f:
        meta, state = f.metadata(), {k: f.get_tensor(k) for k in f.keys()}
    state.pop(next(iter(state)))
    save_file(state, str(tmp_path / "cut.safetensors"), metadata=meta)
    with pytest.raises(ModelFileError, match="missing"):
        load_model_file(tmp_path / "cut.safetensors")


def test_shipped_model_loads():
    from relight.net.io import SHIPPED_MODEL
    if not os.path.isfile(SHIPPED_MODEL):
        pytest.skip("no shipped model in this build")
    model = load_model("sid2")   # named: the default may be the photo model
    assert model.config.res == 128 and not model.training


def test_time_budget_stops_after_an_epoch(tiny, tmp_path):
    cfg = TrainConfig(data_dir=tiny, epochs=3, batch_size=8, res=RES, width=8, max_minutes=0.0)
    row = train(cfg, tmp_path / "budget", progress=False)
    assert row["epoch"] == 1  # the budget is checked before each epoch; the first always runs
    row = train(cfg, tmp_path / "budget", resume=True, progress=False)
    assert row["epoch"] == 2


def test_training_calibrates_kappa_on_val(tiny, tmp_path):
    from relight.net.uncertainty import fit_temperature
    from relight.net.evaluate import errors_from_y, run_model
    from relight.net.data import LightDataset
    cfg = TrainConfig(data_dir=tiny, epochs=1, batch_size=4, res=RES, width=8, seed=2, val_split="all")
    row = train(cfg, tmp_path / "cal", progress=False)
    model = load_model_file(tmp_path / "cal" / "last.safetensors")
    assert model.has_kappa and float(model.kappa_temperature) == pytest.approx(row["kappa_temperature"])
    assert 0 <= row["val_cone90_cover"] <= 1 and math.isfinite(row["train_kappa_nll"])
    # the stored temperature is the NLL minimiser on the val split: refitting gives 1
    ds = LightDataset(tiny, "all", RES)
    y, kappa = run_model(model, ds, with_kappa=True)
    assert fit_temperature(kappa, errors_from_y(y, ds.truth())["direction"]) == pytest.approx(1.0, rel=1e-3)
    assert model.info["kappa_temperature"] == pytest.approx(row["kappa_temperature"])


def test_run_from_before_the_kappa_head_resumes_as_it_was(tiny, tmp_path):
    """A checkpoint whose settings have no arch and no kappa weight (older runs) resumes
    with --resume on the network it was trained with (no kappa head)."""

    from relight.net.loss import LossWeights
    old = TrainConfig(data_dir=tiny, epochs=1, batch_size=4, res=RES, width=8,
                      loss_weights=LossWeights(kappa=0.0))
    run = tmp_path / "old"
    train(old, run, progress=False)
    ckpt = torch.load(run / "checkpoint.pt", weights_only=True)
    assert not any(k.startswith("kappa") for k in ckpt["model"])
    ckpt["settings"].pop("arch")
    ckpt["settings"]["loss_weights"].pop("kappa")
    torch.save(ckpt, run / "checkpoint.pt")
    row = train(dataclasses.replace(old, epochs=2, loss_weights=LossWeights()), run, resume=True, progress=False)
    assert row["epoch"] == 2
    assert not load_model_file(run / "last.safetensors").has_kappa


def test_paper_arch_trains_and_is_recorded(tiny, tmp_path):
    cfg = TrainConfig(data_dir=tiny, epochs=1, batch_size=8, res=RES, width=8, arch="paper")
    train(cfg, tmp_path / "paper", progress=False)
    model = load_model_file(tmp_path / "paper")
    assert model.config.arch == "paper" and model.config.arch_name == "sid2-inception-paper/v1"
    from safetensors import safe_open
    with safe_open(str(tmp_path / "paper" / "best.safetensors"), framework="pt") as f:
        assert f.metadata()["arch"] == "sid2-inception-paper/v1"
    with pytest.raises(TrainingError, match="arch"):
        train(TrainConfig(data_dir=tiny, epochs=1, batch_size=8, res=RES, width=8), tmp_path / "paper", resume=True,
              progress=False)   # an arch change cannot resume


def test_kill_9_during_training_then_identical_command_resumes(tiny, tmp_path):
    """A real SIGKILL of a training process at a random moment after its first
    checkpoint; the identical command finishes the run with the weights of an
    uninterrupted one (shuffling and flips depend on (seed, epoch) only)."""
    import signal
    import subprocess
    import sys
    import time
    argv = ["train", "--data", tiny, "--epochs", "4", "--batch-size", "4", "--res", str(RES),
            "--width", "8", "--seed", "3", "--quiet"]
    straight, killed = tmp_path / "straight", tmp_path / "killed"
    assert main(argv + ["--out", str(straight)]) == 0
    proc = subprocess.Popen([sys.executable, "-m", "relight.cli"] + argv + ["--out", str(killed)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while not (killed / "checkpoint.pt").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(float(np.random.default_rng(7).uniform(0.0, 0.5)))
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done = torch.load(killed / "checkpoint.pt", weights_only=True)["epoch"]
    assert 1 <= done < 4, "the kill did not interrupt the run"
    assert main(argv + ["--out", str(killed)]) == 0          # the identical command resumes
    a = torch.load(straight / "checkpoint.pt", weights_only=True)
    b = torch.load(killed / "checkpoint.pt", weights_only=True)
    assert a["epoch"] == b["epoch"] == 4
    for k in a["model"]:
        assert torch.equal(a["model"][k], b["model"][k]), k
    with open(killed / "log.csv") as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == [str(i) for i in range(1, 5)]


def test_float16_model_file_is_half_the_size_and_predicts_alike(tmp_path):
    """The shipped file stores float16 weights (scripts/ship_model.py): half the bytes,
    loaded back as float32, outputs within float16 rounding of the float32 file's."""
    from relight.net.io import save_model
    torch.manual_seed(4)
    net = LightNet(NetConfig(res=RES, width=16, kappa_head=True)).eval()
    save_model(tmp_path / "f32.safetensors", net)
    save_model(tmp_path / "f16.safetensors", net, dtype=torch.float16)
    ratio = os.path.getsize(tmp_path / "f16.safetensors") / os.path.getsize(tmp_path / "f32.safetensors")
    assert 0.45 < ratio < 0.6
    a, b = load_model_file(tmp_path / "f32.safetensors"), load_model_file(tmp_path / "f16.safetensors")
    assert all(p.dtype == torch.float32 for p in b.parameters())
    x = torch.rand(4, 3, RES, RES)
    with torch.no_grad():
        (ya, ka), (yb, kb) = a.forward_with_kappa(x), b.forward_with_kappa(x)
    assert torch.allclose(ya, yb, atol=5e-3) and not torch.equal(ya, yb)
    assert torch.allclose(ka, kb, rtol=2e-2)


def test_training_on_two_folders_joins_them(tiny, tmp_path, capsys):
    # A copy of the dataset as a second folder: each epoch sees both train splits, the
    # val loss covers both val splits, and the identical command resumes the run.
    from relight.net.data import LightDataset
    twin = str(tmp_path / "twin")
    shutil.copytree(tiny, twin)
    argv = ["train", "--data", tiny, "--data", twin, "--epochs", "1", "--batch-size", "4", "--res", str(RES),
            "--width", "8", "--quiet", "--out", str(tmp_path / "run")]
    assert main(argv) == 0
    rows = list(csv.DictReader(open(tmp_path / "run" / "log.csv")))
    one_train, one_val = len(LightDataset(tiny, "train", RES)), len(LightDataset(tiny, "val", RES))
    assert int(rows[0]["n_train"]) == 2 * one_train and int(rows[0]["n_val"]) == 2 * one_val
    settings = json.load(open(tmp_path / "run" / "settings.json"))
    assert settings["data_dir"] == [tiny, twin]
    assert load_model_file(tmp_path / "run").info["data_dir"] == [os.path.abspath(tiny), os.path.abspath(twin)]
    before = (tmp_path / "run" / "checkpoint.pt").read_bytes()
    assert main(argv) == 0   # the identical command: already trained, nothing rewritten
    assert (tmp_path / "run" / "checkpoint.pt").read_bytes() == before
    capsys.readouterr()
    # the same folders in another order are another run; one folder twice is refused
    assert main(argv[:2] + [twin, "--data", tiny] + argv[5:]) == 2
    assert "other settings" in capsys.readouterr().err
    assert main(argv[:4] + [tiny] + argv[5:-1] + [str(tmp_path / "run2")]) == 2
    err = capsys.readouterr().err
    assert "twice" in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "run2").exists()


@pytest.mark.parametrize("n,size", [(10, 3), (7, 7), (5, 12)])
def test_epoch_images_walk_every_image_once_per_pass(n, size):
    from relight.net.train import _epoch_order
    epochs = 3 * n      # enough epochs for several whole passes whatever the sizes
    walk = [i for e in range(epochs) for i in _epoch_order(n, 4, e, size)]
    assert all(len(_epoch_order(n, 4, e, size)) == size for e in range(epochs))
    for start in range(0, len(walk) - n + 1, n):    # each pass is a permutation of all images
        assert sorted(walk[start:start + n]) == list(range(n))
    assert walk[:n] != walk[n:2 * n]                # ... a new one each pass
    assert _epoch_order(n, 4, 5, size) == _epoch_order(n, 4, 5, size)   # (seed, epoch) decide it
    assert _epoch_order(n, 4, 0, size) != _epoch_order(n, 5, 0, size)


def test_resume_with_a_new_lr_and_patience_continues_with_them(tiny, tmp_path):
    cfg = TrainConfig(data_dir=tiny, epochs=1, batch_size=4, res=RES, width=8, lr=1e-3)
    train(cfg, tmp_path / "run", progress=False)
    lower = dataclasses.replace(cfg, epochs=2, lr=1e-5, plateau_patience=7)
    train(lower, tmp_path / "run", resume=True, progress=False)
    with open(tmp_path / "run" / "log.csv") as f:
        assert [float(r["lr"]) for r in csv.DictReader(f)] == [1e-3, 1e-5]
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert state["scheduler"]["patience"] == 7
    # the identical command later keeps the lr the run has reached (a plateau drop is not undone)
    train(dataclasses.replace(lower, epochs=3), tmp_path / "run", resume=True, progress=False)
    with open(tmp_path / "run" / "log.csv") as f:
        assert float(list(csv.DictReader(f))[-1]["lr"]) <= 1e-5


def test_epoch_images_sets_the_images_per_epoch_and_is_kept_on_resume(tiny, tmp_path):
    cfg = TrainConfig(data_dir=tiny, epochs=2, batch_size=4, res=RES, width=8, epoch_images=3)
    row = train(cfg, tmp_path / "short", progress=False)
    with open(tmp_path / "short" / "log.csv") as f:
        assert [int(r["n_train"]) for r in csv.DictReader(f)] == [3, 3]
    assert row["epoch"] == 2
    with pytest.raises(TrainingError, match="epoch_images"):
        train(dataclasses.replace(cfg, epochs=3, epoch_images=5), tmp_path / "short", resume=True,
              progress=False)
    with pytest.raises(TrainingError, match="epoch_images"):
        TrainConfig(data_dir=tiny, epoch_images=0)
