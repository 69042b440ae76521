"""The shipped models by name (relight.net.io.resolve_model): ``photo`` and ``sid2``; no
--model means photo when it is shipped, else sid2; any other value is a file or a run
folder; every verb's --model takes the same values with the same help text, and a bad one
is one line on stderr and exit 2."""
from __future__ import annotations

import importlib.util
import json
import os
import shutil

import numpy as np
import pytest

from relight.cli import main
from relight.net import io

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def models(tmp_path, monkeypatch):
    """An empty models folder in place of the package's (the names resolve into it)."""
    folder = tmp_path / "models"
    folder.mkdir()
    monkeypatch.setattr(io, "MODELS_DIR", str(folder))
    return folder


def _ship(folder, name: str, res: int = 32) -> str:
    from conftest import untrained_model
    return untrained_model(folder / f"{name}.safetensors", res=res)


def _png(path) -> str:
    from relight.imageio import write_png
    rng = np.random.default_rng(0)
    write_png(str(path), rng.uniform(0.05, 0.9, (40, 56, 3)).astype(np.float32))
    return str(path)


def test_the_package_ships_sid2_and_its_old_names_still_mean_it():
    assert io.SHIPPED_NAMES == ("photo", "sid2", "object") and io.DEFAULT_MODELS == ("photo", "sid2")
    assert io.SHIPPED_NAME == "sid2" and io.SHIPPED_MODEL == io.shipped_model_path("sid2")   # exact: paths
    assert os.path.isfile(io.SHIPPED_MODEL)
    assert io.resolve_model("sid2") == io.SHIPPED_MODEL   # exact: paths
    # no --model: photo once its file is shipped, sid2 until then
    photo = os.path.isfile(io.shipped_model_path("photo"))
    assert io.default_model_name() == ("photo" if photo else "sid2")
    assert io.resolve_model(None) == io.shipped_model_path(io.default_model_name())


def test_no_model_means_sid2_while_photo_is_not_shipped(models):
    sid2 = _ship(models, "sid2")
    assert io.resolve_model(None) == sid2 == io.resolve_model("sid2")
    assert io.default_model_name() == "sid2" and io.model_label(None) == "sid2"
    with pytest.raises(io.ModelFileError, match=r"shipped model 'photo' is not in this build.*shipped: sid2"):
        io.resolve_model("photo")


def test_no_model_means_photo_once_it_is_shipped(models):
    _ship(models, "sid2")
    photo = _ship(models, "photo")
    assert io.resolve_model(None) == photo == io.resolve_model("photo") == str(models / "photo.safetensors")
    assert io.resolve_model("sid2") == str(models / "sid2.safetensors")
    assert io.default_model_name() == "photo" and io.model_label(None) == "photo"
    assert io.model_label("sid2") == "sid2" and io.model_label("/x/run") == "/x/run"
    from relight.net.predict import load_model
    assert load_model().config.res == 32   # the photo file, not the package's 128 px sid2


def test_no_shipped_model_at_all_is_one_line(models):
    with pytest.raises(io.ModelFileError) as exc:
        io.resolve_model(None)
    assert "no shipped model" in str(exc.value) and "\n" not in str(exc.value)
    assert io.default_model_name() is None


def test_other_values_are_files_or_run_folders(models, tmp_path, monkeypatch):
    _ship(models, "sid2")
    monkeypatch.chdir(tmp_path)
    file = _ship(tmp_path, "mine")
    assert io.resolve_model(file) == file
    run = tmp_path / "run"
    run.mkdir()
    best = _ship(run, "best")
    assert io.resolve_model(str(run)) == best
    shutil.copy(file, tmp_path / "nosuch")   # a file whose name is no shipped name: a path
    assert io.resolve_model("nosuch") == "nosuch"
    (tmp_path / "sid2").mkdir()              # a folder named like a shipped model: the name wins
    assert io.resolve_model("sid2") == str(models / "sid2.safetensors")
    with pytest.raises(io.ModelFileError, match=r"'other' is neither a shipped model name \(photo, sid2, object\)"):
        io.resolve_model("other")
    with pytest.raises(io.ModelFileError, match="model file not found"):
        io.resolve_model(str(tmp_path / "gone.safetensors"))
    with pytest.raises(io.ModelFileError, match="without best.safetensors"):
        io.resolve_model(str(tmp_path / "sid2"))


def test_predict_records_the_name_the_model_resolves_to(models, tmp_path, capsys):
    _ship(models, "sid2")
    img = _png(tmp_path / "a.png")
    for given, label in ((None, "sid2"), ("sid2", "sid2")):
        out = tmp_path / f"{given}.json"
        assert main(["predict", img, "--out", str(out)] + (["--model", given] if given else [])) == 0
        assert json.loads(out.read_text())["model"] == label
    _ship(models, "photo")
    out = tmp_path / "default.json"
    assert main(["predict", img, "--out", str(out), "--mirror-average"]) == 0
    assert json.loads(out.read_text())["model"] == "photo (mirror-averaged)"
    path = str(models / "sid2.safetensors")
    assert main(["predict", img, "--model", path, "--out", str(out)]) == 0
    assert json.loads(out.read_text())["model"] == path
    capsys.readouterr()


@pytest.mark.parametrize("argv, says", [
    (["predict", "{img}", "--model", "nosuch", "--out", "{tmp}/p.json"], "'nosuch' is neither a shipped model name"),
    (["predict", "{img}", "--model", "photo", "--out", "{tmp}/p.json"], "shipped model 'photo' is not in this build"),
    (["evaluate", "--model", "photo", "--data", "{tmp}", "--out", "{tmp}/e"], "shipped model 'photo'"),
    (["calibrate", "--model", "photo", "--data", "{tmp}", "--out", "{tmp}/c.safetensors"], "shipped model 'photo'"),
    (["train", "--init", "photo", "--data", "{tmp}", "--out", "{tmp}/run"], "shipped model 'photo'"),
])
def test_a_bad_model_is_one_line_and_exit_2(argv, says, models, tmp_path, capfd):
    _ship(models, "sid2")
    img = _png(tmp_path / "a.png")
    argv = [a.format(img=img, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    out, err = capfd.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and "Traceback" not in err, err
    assert not os.path.exists(tmp_path / "p.json") and not os.path.exists(tmp_path / "run")


def test_predict_with_an_unknown_name_through_the_console(tmp_path):
    import subprocess
    import sys
    img = _png(tmp_path / "a.png")
    proc = subprocess.run([sys.executable, "-m", "relight", "predict", img, "--model", "nosuch",
                           "--out", str(tmp_path / "p.json")], capture_output=True, text=True, cwd=tmp_path,
                          env=dict(os.environ, PYTHONPATH=REPO))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "nosuch" in proc.stderr, proc.stderr
    assert not (tmp_path / "p.json").exists()


def test_train_init_takes_a_shipped_name(models, tmp_path):
    """``relight train --init sid2`` fine-tunes the shipped file (its path is recorded)."""
    from conftest import tiny_dataset
    sid2 = _ship(models, "sid2")
    data = tiny_dataset(tmp_path / "d", count=6, seed=4, res=32)
    assert main(["train", "--data", data, "--out", str(tmp_path / "run"), "--init", "sid2", "--res", "32",
                 "--epochs", "1", "--quiet"]) == 0
    settings = json.loads((tmp_path / "run" / "settings.json").read_text())
    assert settings["init"] == os.path.abspath(sid2)


def test_every_network_option_has_the_one_help_text():
    from relight.cli import build_parser
    from relight.commands.argtypes import model_help
    text = model_help()
    assert text == ("shipped model name (photo, sid2, object) or a .safetensors file or run folder "
                    "(default: photo, else sid2)")
    parser = build_parser()
    sub = next(a for a in parser._actions if a.choices and "predict" in a.choices).choices
    for verb, flag in (("predict", "--model"), ("evaluate", "--model"), ("invert", "--model"),
                       ("calibrate", "--model"), ("train", "--init")):
        action = next(a for a in sub[verb]._actions if flag in a.option_strings)
        assert model_help(default=False) in action.help, (verb, action.help)
        assert (text in action.help) == (verb in ("predict", "evaluate", "invert")), (verb, action.help)
    for script in ("bench_photos", "bench_inverse", "bench_network"):
        src = open(os.path.join(REPO, "benchmarks", f"{script}.py")).read()
        assert "add_model_option(ap" in src and 'add_argument("--model"' not in src, script


def test_bench_photos_scores_every_shipped_model_by_name(models, tmp_path, capsys):
    from conftest import tiny_dataset
    data = tiny_dataset(tmp_path / "d", count=3, seed=5, res=32)
    spec = importlib.util.spec_from_file_location("bench_photos", os.path.join(REPO, "benchmarks", "bench_photos.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)

    def rows():
        assert bench.main(["--no-devset", "--photos", str(tmp_path / "none"), "--data", data]) == 0
        lines = capsys.readouterr().out.splitlines()
        return [ln.split()[0] for ln in lines[lines.index(data) + 2:] if ln.startswith("  ") and ln.split()]

    _ship(models, "sid2")
    assert rows() == ["sid2"]
    _ship(models, "photo")
    assert rows() == ["photo", "sid2"]
