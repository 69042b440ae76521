"""scripts/ship_model.py: the model card reads the model's input size, the encoder's
modules, the datasets' sampler / noise target / samples per pixel and colour prior from
their metadata, and reports the colour error on a test set of each colour prior."""
import csv
import importlib.util
import json
import os
import sys

import pytest
import torch

from relight.net.model import NetConfig

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RES = 32


@pytest.fixture(scope="module")
def ship_model():
    spec = importlib.util.spec_from_file_location("ship_model", os.path.join(ROOT, "scripts", "ship_model.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_generate_command_of_a_noise_target_card(ship_model):
    card = {"seed": 2, "spp": 16, "config": {"res": 128, "spp": None, "target_rmse": 0.02,
                                             "sampler": "multijitter", "colour_prior": "munsell",
                                             "split": [0.9, 0.1, 0.0]}}
    cmd, note = ship_model.generate_command(card, "/data/x", 2500)
    assert cmd.startswith("relight generate --count 2500 --out /data/x --seed 2 ")
    assert "--target-rmse 0.02 --sampler multijitter --colour-prior munsell --object-parts 1 " in cmd
    assert "--spp" not in cmd and "--res" not in cmd and "None" not in cmd
    assert "--config CONFIG.json" in cmd and '"split": [0.9, 0.1, 0.0]' in note
    assert ship_model.noise_text(card) == "sampler multijitter, 16 spp (noise target: relative RMSE 0.02)"


def test_generate_command_names_the_object_parts(ship_model):
    card = {"seed": 5, "spp": 16, "config": {"res": 128, "spp": None, "target_rmse": 0.02, "sampler": "multijitter",
                                             "colour_prior": "hsv", "object_parts": [1, 32]}}
    cmd, note = ship_model.generate_command(card, "d", 2500)
    assert "--colour-prior hsv --object-parts 1-32" in cmd and "--config" not in cmd and note == ""
    card["config"]["object_parts"] = [4, 4]
    assert "--object-parts 4 " in ship_model.generate_command(card, "d", 2500)[0] + " "


def test_generate_command_and_settings_name_the_backgrounds(ship_model):
    card = {"seed": 5, "spp": 16, "config": {"res": 128, "spp": None, "target_rmse": 0.02, "sampler": "multijitter",
                                             "colour_prior": "hsv", "object_parts": [1, 32]}}
    assert "--object-parts 1-32 --backgrounds patterns" in ship_model.generate_command(card, "d", 9)[0]
    assert ship_model.settings_text(card).endswith(", patterns backgrounds")   # a card from before the setting
    card["config"]["backgrounds"] = "mosaic"
    cmd, note = ship_model.generate_command(card, "d", 9)
    assert "--backgrounds mosaic" in cmd and "--config" not in cmd and note == ""
    assert ship_model.settings_text(card).endswith(", mosaic backgrounds")


def test_generate_command_of_the_sid2_paper_preset(ship_model):
    """A card of `--preset sid2-paper` gives the command with the preset (its settings not
    repeated) and the backgrounds it used; a card that only shares some of them does not."""
    import dataclasses
    from relight.generator.sampling import sid2_paper_config
    for backgrounds in ("library", "unseen"):
        config = json.loads(json.dumps(dataclasses.asdict(sid2_paper_config(backgrounds=backgrounds, res=64))))
        cmd, note = ship_model.generate_command({"seed": 8, "spp": 16, "config": config}, "d", 200)
        assert cmd.startswith("relight generate --preset sid2-paper --count 200 --out d --seed 8 --res 64 ")
        assert cmd.endswith(f"--backgrounds {backgrounds}") and note == ""
        assert "--colour-prior" not in cmd and "--object-parts" not in cmd
        assert ship_model.settings_text({"seed": 8, "spp": 16, "config": config}).endswith(
            f"{backgrounds} backgrounds, tanner-helland light colours")
    config["object_parts"] = [1, 32]
    cmd, note = ship_model.generate_command({"seed": 8, "spp": 16, "config": config}, "d", 200)
    assert "--preset" not in cmd and "--colour-prior pastel --object-parts 1-32" in cmd
    assert '"light_colour": "tanner-helland"' in note


def test_generate_command_of_a_legacy_card(ship_model):
    """Cards written before the sampler and prior fields: independent sampler, hsv prior."""
    card = {"seed": 1, "config": {"res": 64, "spp": 32, "max_depth": 4}}
    cmd, note = ship_model.generate_command(card, "d", 10)
    assert "--res 64 --spp 32 --sampler independent --colour-prior hsv --object-parts 1 --backgrounds patterns" in cmd
    assert "--target-rmse" not in cmd and "--config" not in cmd and note == ""
    assert ship_model.noise_text(card) == "sampler independent, 32 spp (fixed)"


def test_table1_rows_score_pan_below_the_zenith_and_count_the_rest(ship_model):
    """The card's Table 1 from an evaluation's tables: pan (tilt < 90) with the zenith lights
    left out in its label, and the all-lights pan as its own row; 3 lights below the zenith
    (pan errors 2, 4, 6) and 1 at it (pan error 100): 4.00 and (12 + 100) / 4 = 28.00."""
    from relight.metrics import error_tables
    errors = {"pan": [2.0, 4.0, 6.0, 100.0], "tilt": [1.0] * 4, "direction": [1.0] * 4, "colour": [0.5] * 4}
    overall = error_tables(errors, [30.0, 60.0, 85.0, 90.0], [0.0] * 4)["overall"]
    rows = ship_model.table1_rows(overall)
    assert rows[0] == "| Pan (tilt < 90; 1 zenith lights left out) | 10.46 | 4.00 | 4.00 |"
    assert rows[-1] == "| Pan, all lights | - | 28.00 | 5.00 |"
    assert [r.split(" | ")[0] for r in rows[1:4]] == ["| Tilt", "| Direction", "| Colour"]
    old = {m: {k: v for k, v in st.items() if k != "zenith_left_out"} for m, st in overall.items() if m != "pan_all"}
    assert ship_model.table1_rows(old)[0].startswith("| Pan (all lights) | 10.46 | 4.00 |")   # made before the rule


def test_architecture_text_names_each_encoders_modules(ship_model):
    paper = ship_model.architecture_text(NetConfig(arch="paper"))
    small = ship_model.architecture_text(NetConfig(arch="small"))
    assert "--arch paper" in paper and "factorised inception (1x7, 7x1)" in paper
    assert "expanded inception" in paper and "grid reduction" in paper and "32 x 32" not in paper
    assert "--arch small" in small and "split inception + max pool /2" in small
    assert "factorised inception" not in small and "embedding of 256 units" in small


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    from relight.generator.run import generate
    from relight.net.train import TrainConfig, train
    from relight.generator.sampling import GeneratorConfig
    root = tmp_path_factory.mktemp("ship")
    cfg = GeneratorConfig(res=RES, target_rmse=0.05)
    generate(root / "train", count=8, seed=21, cfg=cfg, progress=False)
    generate(root / "test", count=4, seed=22, cfg=cfg, progress=False)
    generate(root / "test-munsell", count=4, seed=23, cfg=GeneratorConfig(res=RES, spp=4, colour_prior="munsell"),
             progress=False)
    torch.manual_seed(0)
    train(TrainConfig(data_dir=str(root / "train"), epochs=1, res=RES, width=8, batch_size=4, train_split="all",
                      val_split="all"), root / "run", progress=False)
    return root


def test_card_reads_metadata_and_reports_each_prior(ship_model, world, tmp_path, monkeypatch, capsys):
    models = tmp_path / "models"
    argv = ["ship_model.py", "--run", str(world / "run"), "--train-data", str(world / "train"),
            "--test-data", str(world / "test"), "--eval-out", str(tmp_path / "ev"), "--models-dir", str(models),
            "--prior-test", f"hsv={world / 'test'}", "--prior-test", f"munsell={world / 'test-munsell'}"]
    monkeypatch.setattr(sys, "argv", argv)
    assert ship_model.main() == 0
    capsys.readouterr()
    card = (models / "MODEL_CARD.md").read_text()
    assert f"per {RES} px image" in card and f"Input: {RES} x {RES}" in card and "128 px" not in card
    assert "None" not in card
    spp = json.load(open(world / "test" / "dataset.json"))["spp"]
    assert f"sampler multijitter, {spp} spp (noise target: relative RMSE 0.05)" in card
    assert "--target-rmse 0.05 --sampler multijitter --colour-prior hsv" in card
    assert "--arch small" in card and "split inception" in card
    for name, folder in (("hsv", "ev-prior-hsv"), ("munsell", "ev-prior-munsell")):
        overall = json.load(open(tmp_path / folder / "metrics.json"))["tables"]["overall"]
        row = next(line for line in card.splitlines() if line.startswith(f"| {name} ("))
        assert f"| {overall['colour']['mean']:.2f} | {overall['colour']['median']:.2f} |" in row
    assert (models / "sid2.safetensors").is_file() and (models / "sid2_log.csv").is_file()
    assert "not finished" not in card and "--epochs 1 " in card
    mirrored = json.load(open(tmp_path / "ev-mirror" / "metrics.json"))
    assert mirrored["model"] == "shipped model (mirror-averaged)"
    line = next(x for x in card.splitlines() if x.startswith("With `--mirror-average`"))
    assert f"direction {mirrored['tables']['overall']['direction']['mean']:.2f}, " in line
    assert f"cover {100 * mirrored['uncertainty']['cone90_coverage']:.1f}%" in line
    ev = json.load(open(tmp_path / "ev" / "metrics.json"))
    if ev["pan_where_defined"]["zenith"]["n"]:
        assert f"Pan over the other {ev['pan_where_defined']['below_zenith']['n']}:" in card
    # a test set with zenith lights: the pan split is said once, beside Table 1, not again in
    # the embedded evaluate report (which has it too)
    from relight.metrics import format_pan_where_defined
    split = {"zenith": {"n": 1, "mean": 90.0, "median": 90.0}, "below_zenith": {"n": 3, "mean": 4.0, "median": 3.0}}
    line = format_pan_where_defined(split)
    ev["pan_where_defined"] = split
    (tmp_path / "ev" / "metrics.json").write_text(json.dumps(ev))
    report = (tmp_path / "ev" / "report.md").read_text()
    (tmp_path / "ev" / "report.md").write_text(report.replace("**Colour-constancy", line + "\n**Colour-constancy", 1))
    assert (tmp_path / "ev" / "report.md").read_text().count(line) == 1
    zenith_card = ship_model.write_card(json.load(open(models / "sid2.json")), str(tmp_path / "ev"),
                                        str(world / "test"), "notes")
    assert zenith_card.count(line.strip()) == 1 and "Pan over the other 3: mean 4.00" in zenith_card
    # a run stopped before its planned total: the card says so and gives the command of its epochs
    meta = json.load(open(models / "sid2.json"))
    meta["settings"]["epochs"] = 7
    unfinished = ship_model.write_card(meta, str(tmp_path / "ev"), str(world / "test"), "notes")
    assert "after epoch 1 of the planned 7" in unfinished and "--epochs 1 " in unfinished
    # the package's own shipped model is untouched by a run with --models-dir
    assert not os.path.samefile(models, os.path.join(ROOT, "relight", "models"))


def test_card_of_a_two_stage_run(ship_model, world, tmp_path, monkeypatch, capsys):
    """A run fine-tuned from another run's best model (`relight train --init`, e.g. a
    learning-rate drop by hand): the card gives both stages' commands, stage 1 with the
    epochs up to its best one, stage 2 with --init on stage 1's best model."""
    from relight.net.train import TrainConfig, train
    stage2 = tmp_path / "stage2"
    torch.manual_seed(0)
    train(TrainConfig(data_dir=str(world / "train"), epochs=1, res=RES, batch_size=4, train_split="all",
                      val_split="all", lr=2e-5, init=str(world / "run" / "best.safetensors")), stage2, progress=False)
    models = tmp_path / "models"
    monkeypatch.setattr(sys, "argv", ["ship_model.py", "--run", str(stage2), "--train-data", str(world / "train"),
                                      "--test-data", str(world / "test"), "--eval-out", str(tmp_path / "ev"),
                                      "--models-dir", str(models)])
    assert ship_model.main() == 0
    capsys.readouterr()
    card = (models / "MODEL_CARD.md").read_text()
    meta = json.load(open(models / "sid2.json"))
    assert [st["model"] for st in meta["stages"]] == [str(world / "run" / "best.safetensors")]
    assert meta["stages"][0]["best_epoch"] == 1
    reproduce = card.split("## Reproduce")[1]
    stage1 = next(line for line in reproduce.splitlines() if "--out STAGE1" in line)
    stage2_cmd = next(line for line in reproduce.splitlines() if "--init STAGE1/best.safetensors" in line)
    assert "--epochs 1 " in stage1 and "--init" not in stage1 and "--lr" not in stage1
    assert "--lr 2e-05" in stage2_cmd and "--out RUN" in stage2_cmd
    assert reproduce.index(stage1) < reproduce.index(stage2_cmd)
    assert "Two stages" in card and "Stage 2: 1 epochs" in card


def test_card_of_a_three_stage_run_on_other_data(ship_model, world, tmp_path, monkeypatch, capsys):
    """Fine-tuning a shipped two-stage model on another dataset: the chain comes from the
    shipped model's own header (its stage-1 file may be gone), the card gives all three
    commands, each stage --init on the one before, and both datasets' generate commands."""
    from relight.net.train import TrainConfig, train
    from relight.net.io import read_model_file

    def ship(run, data, models):
        monkeypatch.setattr(sys, "argv", ["ship_model.py", "--run", str(run), "--train-data", str(data),
                                          "--test-data", str(world / "test"), "--eval-out", str(tmp_path / "ev"),
                                          "--models-dir", str(models)])
        assert ship_model.main() == 0
        capsys.readouterr()

    torch.manual_seed(0)
    train(TrainConfig(data_dir=str(world / "train"), epochs=1, res=RES, batch_size=4, train_split="all",
                      val_split="all", lr=2e-5, init=str(world / "run" / "best.safetensors")),
          tmp_path / "stage2", progress=False)
    ship(tmp_path / "stage2", world / "train", tmp_path / "models2")
    shipped2 = tmp_path / "models2" / "sid2.safetensors"
    assert [st["model"] for st in read_model_file(str(shipped2))[2]["stages"]] == [str(world / "run" / "best.safetensors")]
    train(TrainConfig(data_dir=str(world / "test"), epochs=1, res=RES, batch_size=4, train_split="all",
                      val_split="all", lr=1e-5, init=str(shipped2)), tmp_path / "stage3", progress=False)
    ship(tmp_path / "stage3", world / "test", tmp_path / "models3")
    meta = json.load(open(tmp_path / "models3" / "sid2.json"))
    assert [st["model"] for st in meta["stages"]] == [str(world / "run" / "best.safetensors"), str(shipped2)]
    card = (tmp_path / "models3" / "MODEL_CARD.md").read_text()
    assert "Three stages" in card and "Stage 3: 1 epochs" in card and f"on other data (`{world / 'test'}`)" in card
    reproduce = card.split("## Reproduce")[1].splitlines()
    s1, s2, s3 = (next(i for i, line in enumerate(reproduce) if pat in line)
                  for pat in ("--out STAGE1", "--out STAGE2", "--out RUN"))
    assert s1 < s2 < s3 and "--init" not in reproduce[s1]
    assert "--init STAGE1/best.safetensors" in reproduce[s2] and f"--data {world / 'train'} " in reproduce[s2]
    assert "--init STAGE2/best.safetensors" in reproduce[s3] and f"--data {world / 'test'} " in reproduce[s3]
    gens = [line for line in reproduce if line.startswith("relight generate")]
    assert any(f"--out {world / 'train'} " in g for g in gens) and any(f"--out {world / 'test'} " in g for g in gens)
    assert "- Earlier stages: `relight generate" in card


def test_card_of_a_run_on_two_folders(ship_model, world, tmp_path, monkeypatch, capsys):
    """A fine-tune on two datasets together (`relight train --data A --data B`): the card's
    train command repeats --data in the run's order, both datasets' generate commands are
    listed (with their settings) and the ship command names both --train-data."""
    from relight.net.train import TrainConfig, train
    train_dir, other = str(world / "train"), str(world / "test-munsell")
    torch.manual_seed(0)
    train(TrainConfig(data_dir=(train_dir, other), epochs=1, res=RES, batch_size=4, train_split="all",
                      val_split="all", lr=2e-5, init=str(world / "run" / "best.safetensors")),
          tmp_path / "both", progress=False)
    from relight.net.calibrate import CalibrationConfig, calibrate_model_file
    calibrated = str(tmp_path / "cal.safetensors")   # calibrated on both folders' joined split
    calibrate_model_file(tmp_path / "both", [train_dir, other], calibrated,
                         CalibrationConfig(split="all", mode="temperature"))
    models = tmp_path / "models"
    monkeypatch.setattr(sys, "argv", ["ship_model.py", "--run", str(tmp_path / "both"), "--train-data", train_dir,
                                      "--model", calibrated,
                                      "--train-data", other, "--test-data", str(world / "test"),
                                      "--eval-out", str(tmp_path / "ev"), "--models-dir", str(models),
                                      "--other-test", f"munsell={other}"])
    assert ship_model.main() == 0
    capsys.readouterr()
    meta = json.load(open(models / "sid2.json"))
    assert [d["path"] for d in meta["train_datasets"]] == [train_dir, other]
    assert meta["train_datasets"][1]["records"] == 4 and meta["train_images_per_epoch"] == [8 + 4, 8 + 4]
    card = (models / "MODEL_CARD.md").read_text()
    reproduce = card.split("## Reproduce")[1].splitlines()
    run_cmd = next(line for line in reproduce if "--out RUN" in line)
    assert f"--data {train_dir} --data {other} --out RUN" in run_cmd
    assert f"--train-data {train_dir} --train-data {other} --test-data" in card
    assert f"relight calibrate --model RUN --data {train_dir} --data {other} --split all" in card
    assert f"of `{train_dir} + {other}` (12 images" in card
    gens = [line for line in reproduce if line.startswith("relight generate")]
    assert [g.split("--out ")[1].split()[0] for g in gens] == [train_dir, other, str(world / "test")]
    assert "--colour-prior munsell" in gens[1] and "colour prior munsell" in card
    assert "joined (12 images) train," in " ".join(card.split())
    assert f"on other data (`{train_dir} + {other}`)" in card
    # the other test set: its four mean errors, and the settings in which it differs from the main one
    overall = json.load(open(tmp_path / "ev-other-munsell" / "metrics.json"))["tables"]["overall"]
    row = next(line for line in card.splitlines() if line.startswith("| munsell ("))
    assert "| 4 spp (fixed), colour prior munsell |" in row
    assert "colour prior hsv" not in row and "32 px" not in row   # settings both sets share are left out
    assert (f"| {overall['pan']['mean']:.2f} | {overall['pan']['zenith_left_out']} | "
            + " | ".join(f"{overall[m]['mean']:.2f}" for m in ("tilt", "direction", "colour"))) in row
    assert row.endswith(f"| {overall['pan_all']['mean']:.2f} |")
    assert f"--other-test munsell={other} " in card
    assert f"- munsell: `relight generate --count 4 --out {other} --seed 23 " in card


def test_ship_as_photo_writes_its_own_files_and_card(ship_model, world, tmp_path, monkeypatch, capsys):
    """``--name photo`` (a dry run into --models-dir): photo.safetensors, photo.json,
    photo_log.csv, photo_reliability.png and MODEL_CARD_photo.md, nothing of sid2's; the card
    names photo as the default model. Its run was fine-tuned from a shipped sid2 model, a file
    that is not a stage of its own chain: the card says it was initialised from that file and
    gives ``--init sid2``; a start file without any training record is said as such too."""
    from conftest import untrained_model
    from relight.net.io import read_model_header
    from relight.net.train import TrainConfig, train

    def ship(run, models, *extra):
        monkeypatch.setattr(sys, "argv", ["ship_model.py", *extra, "--run", str(run), "--train-data",
                                          str(world / "train"), "--test-data", str(world / "test"),
                                          "--eval-out", str(tmp_path / "ev"), "--models-dir", str(models)])
        assert ship_model.main() == 0
        capsys.readouterr()

    ship(world / "run", tmp_path / "sid2models")              # a shipped sid2 to start from
    sid2 = tmp_path / "sid2models" / "sid2.safetensors"
    torch.manual_seed(0)
    train(TrainConfig(data_dir=str(world / "train"), epochs=1, res=RES, batch_size=4, train_split="all",
                      val_split="all", lr=2e-5, init=str(sid2)), tmp_path / "photo-run", progress=False)
    models = tmp_path / "models"
    ship(tmp_path / "photo-run", models, "--name", "photo")
    names = sorted(os.listdir(models))
    assert {"photo.safetensors", "photo.json", "photo_log.csv", "MODEL_CARD_photo.md"} <= set(names)
    assert not any(n.startswith("sid2") for n in names) and "MODEL_CARD.md" not in names
    assert ("photo_reliability.png" in names) == os.path.isfile(tmp_path / "ev" / "reliability.png")
    assert read_model_header(str(models / "photo.safetensors"))[1]["name"] == "photo"
    meta = json.load(open(models / "photo.json"))
    assert meta["name"] == "photo" and meta["stages"] == []
    assert meta["init_from"] == {"model": str(sid2), "name": "sid2",
                                 "why": "the shipped `sid2` model; its training: MODEL_CARD.md"}
    card = (models / "MODEL_CARD_photo.md").read_text()
    assert card.startswith("# Model card: `photo.safetensors`")
    assert "It is the default model of `relight predict` and `relight evaluate`." in card
    assert "SID2-style synthetic rooms" not in card and "sid2.json" not in card
    assert f"- Initialised from `{sid2}` (the shipped `sid2` model" in card
    reproduce = card.split("## Reproduce")[1]
    run_cmd = next(line for line in reproduce.splitlines() if "--out RUN" in line)
    assert "--init sid2 " in run_cmd and "STAGE" not in reproduce
    assert "scripts/ship_model.py --name photo --run RUN" in reproduce
    assert "relight evaluate --model photo --data" in card
    # the sid2 card of the same script says what sid2 is for
    sid2_card = (tmp_path / "sid2models" / "MODEL_CARD.md").read_text()
    assert "It is the model for SID2-style synthetic rooms: `--model sid2`." in sid2_card
    assert "default model of" not in sid2_card
    # a start with no training record at all (an untrained file): said, not an error
    bare = untrained_model(tmp_path / "bare.safetensors", res=RES)
    torch.manual_seed(0)
    train(TrainConfig(data_dir=str(world / "train"), epochs=1, res=RES, batch_size=4, train_split="all",
                      val_split="all", init=bare), tmp_path / "bare-run", progress=False)
    ship(tmp_path / "bare-run", tmp_path / "models-bare", "--name", "photo")
    card = (tmp_path / "models-bare" / "MODEL_CARD_photo.md").read_text()
    assert f"- Initialised from `{bare}` (a model file without a training record)" in card
    assert f"--init {bare} " in card


def test_train_command_gives_the_photo_options(ship_model):
    """A camera-frame run on the EXRs with the pipeline augmentation (the photo model's):
    the card's command names those options, and relight's parser reads them back as run."""
    from relight.cli import build_parser
    s = {"loss_weights": {"pan": 1.0, "tilt": 1.0, "colour": 1.0, "kappa": 1.0}, "epochs": 30,
         "plateau_patience": 2, "lr": 1e-4, "threads": 2, "arch": "paper", "target_frame": "camera",
         "camera_weight": 1.0, "source": "exr", "augment": "photo", "epoch_images": 8000}
    cmd = ship_model.train_command(s, "DATA")
    args = build_parser().parse_args(cmd.split()[1:])
    assert (args.target_frame, args.camera_weight, args.source, args.augment, args.epoch_images) == \
        ("camera", 1.0, "exr", "photo", 8000)
    plain = ship_model.train_command({**s, "target_frame": "world", "camera_weight": 0.0, "source": "image",
                                      "augment": "none", "epoch_images": None}, "DATA")
    assert not any(f in plain for f in ("--target-frame", "--camera-weight", "--source", "--augment", "--epoch-images"))


def test_card_gives_the_rate_the_run_started_at_and_its_split(ship_model, world, tmp_path, monkeypatch, capsys):
    """A run resumed with another --lr and --max-minutes records its last command's settings:
    the card's command and text give the rate of its log's first epoch (the drops are listed
    from the log) and no --max-minutes; the train split's size is given beside the images
    an epoch draws from it (``--epoch-images``)."""
    models = tmp_path / "models"
    monkeypatch.setattr(sys, "argv", ["ship_model.py", "--run", str(world / "run"), "--train-data",
                                      str(world / "train"), "--test-data", str(world / "test"),
                                      "--eval-out", str(tmp_path / "ev"), "--models-dir", str(models)])
    assert ship_model.main() == 0
    capsys.readouterr()
    meta = json.load(open(models / "sid2.json"))
    with open(models / "sid2_log.csv") as f:
        started = float(next(csv.DictReader(f))["lr"])
    meta["settings"] |= {"lr": started / 10, "max_minutes": 24.0}
    split = meta["settings"]["train_split"]
    n_train = meta["train_dataset"]["records" if split == "all" else "split_records"]
    n_train = n_train if split == "all" else n_train[split]
    meta["train_images_per_epoch"] = [n_train - 1, n_train - 1]
    card = ship_model.write_card(meta, str(tmp_path / "ev"), str(world / "test"), "notes")
    assert f"Adam lr {started:g}," in card and f"{started / 10:g}" not in card
    assert "--max-minutes" not in card
    assert f"({n_train:,} images; {n_train - 1:,} drawn per epoch) train" in " ".join(card.split())


def test_card_says_how_a_camera_head_model_answers(ship_model):
    from relight.net.model import NetConfig
    camera = ship_model.output_text(NetConfig(res=RES, width=8, camera_head=True, target_frame="camera"))
    assert "camera frame" in camera and "camera head predicts" in camera and "45 deg" not in camera
    world_frame = ship_model.output_text(NetConfig(res=RES, width=8))
    assert "world frame" in world_frame and "45 deg assumed" in world_frame
    s = {"loss_weights": {"pan": 1.0, "tilt": 1.0, "colour": 1.0, "kappa": 1.0}, "epochs": 3,
         "plateau_patience": 2, "lr": 1e-4, "arch": "small", "init": "sid2.safetensors", "max_minutes": 5.0}
    cmd = ship_model.train_command(s, "DATA", init="sid2")
    assert "--init sid2 " in cmd and "--arch" not in cmd and "--max-minutes" not in cmd
    assert "--arch small" in ship_model.train_command({**s, "init": None}, "DATA")
    assert ship_model.camera_loss_text({"camera_weight": 0.5}) == \
        " + 0.5 x the camera-tilt head's loss (`--camera-weight 0.5`)"
    assert ship_model.camera_loss_text({}) == ""


def test_a_named_script_exists_and_makes_what_the_card_says(ship_model):
    """The photo card names scripts/train_photo.sh: the file exists and its train command is
    the card's (the same options as a train_command of the run's settings would give)."""
    line = ship_model.script_line("photo")
    path = os.path.join(ROOT, ship_model.SCRIPTS["photo"])
    assert ship_model.SCRIPTS["photo"] in line and os.path.isfile(path)
    assert ship_model.script_line("sid2") == ""
    text = open(path).read()
    for opt in ("--target-frame camera", "--source exr", "--augment photo", "relight/models/sid2.safetensors",
                "--init", "--ood"):
        assert opt in text, opt
