"""Fault injection through the CLI: nothing lost, ever.

Every class of failure of issue 12 is tried against the command line: outputs equal
to inputs for every verb, concurrent writers, SIGKILL of a single-process and of a
multi-worker ``generate``, images of every PNG mode and bit depth (and broken or
over-large ones), corrupt checkpoints, a bad-argument sweep of every numeric option
of every verb, and half-written leftovers; and those of issue 27: an output folder that
holds an input (``train --init RUN/best.safetensors --out RUN``), a full, and a read-only,
file system (a real small tmpfs, as root), sizes against the image or a documented limit,
one image given twice, library messages cut mid-word, and the committed float references
under last-bit changes. A refused command must exit 2 with exactly one line on stderr, no
traceback, and leave the input tree byte-identical.

Refusals run ``relight.cli.main`` in this process with file-descriptor capture (the
same code path as the console script, and it also sees what C++ libraries print on
fd 1/2); kills, locks and worker processes need real subprocesses.
"""
from __future__ import annotations

import hashlib
import json
import os
import random
import re
import shutil
import signal
import struct
import subprocess
import sys
import time
import zlib

import numpy as np
import pytest

from relight.fileio import is_temp_name

CLI = [sys.executable, "-m", "relight.cli"]
RES = 16                 # tiny renders
SPP = 2
KILL_SEED = 12           # random kill moments, reproducible
WORKER_EXIT_S = 20.0     # orphaned workers must be gone by then
PROCESS_TIMEOUT_S = 300
TEMP_HINT = ".relight-tmp-"   # the mark of an internal temporary file name


# --- helpers ----------------------------------------------------------------------------

def cli(argv, capfd):
    """Run the CLI in this process; returns (exit code, stdout, stderr)."""
    from relight.cli import main
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:   # argparse
        code = exc.code
    out, err = capfd.readouterr()
    return code, out, err


def assert_refused(code, err, contains: str | None = None):
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("relight: error:") and "Traceback" not in err, err
    assert TEMP_HINT not in lines[0], err   # messages name the user's paths, not temporaries
    if contains:
        assert contains in lines[0], err



def tree(root) -> dict:
    """``{relative path: sha256}`` of every file (hidden ones too) and folder under root."""
    out = {}
    for folder, dirs, files in os.walk(root):
        for d in dirs:
            out[os.path.relpath(os.path.join(folder, d), root) + "/"] = "dir"
        for f in files:
            p = os.path.join(folder, f)
            with open(p, "rb") as fh:
                out[os.path.relpath(p, root)] = hashlib.sha256(fh.read()).hexdigest()
    return out


def temps_under(root) -> list[str]:
    return [os.path.join(d, f) for d, _, files in os.walk(root) for f in files if is_temp_name(f)]


def manifest_ids(folder) -> list[str]:
    with open(os.path.join(folder, "manifest.jsonl"), "rb") as f:
        return [json.loads(line)["id"] for line in f.read().split(b"\n") if line.strip()]


def generate_cmd(out, count, seed=5, *extra):
    return CLI + ["generate", "--count", str(count), "--res", str(RES), "--spp", str(SPP), "--seed", str(seed),
                  "--out", str(out), "--quiet", *extra]


def children_of(pid: int) -> list[int]:
    """Pids whose parent is ``pid`` (Linux /proc)."""
    kids = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                kids.append(int(name))
    return kids


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def wait_for_records(folder, n, proc, timeout=PROCESS_TIMEOUT_S) -> None:
    path = os.path.join(folder, "manifest.jsonl")
    deadline = time.time() + timeout
    while time.time() < deadline:
        if os.path.exists(path) and open(path, "rb").read().count(b"\n") >= n:
            return
        if proc.poll() is not None:
            return
        time.sleep(0.02)
    raise AssertionError("generate made no progress")


def check_complete(folder) -> list[dict]:
    """Every record's three files exist and are readable."""
    from relight.dataset import read_manifest
    from relight.imageio import read_exr, read_image
    recs = read_manifest(folder)
    for r in recs:
        assert read_image(os.path.join(folder, r["image"]))[0].shape == (RES, RES, 3)
        assert read_exr(os.path.join(folder, r["exr"])).shape == (RES, RES, 3)
        json.loads(open(os.path.join(folder, r["scene"])).read())
    return recs


# --- a tiny world of inputs, shared by the module ----------------------------------------

@pytest.fixture(scope="module")
def world(tmp_path_factory, mi):
    """Inputs under one root: a 4-image dataset, a predictions file, masks, a scene copy
    named like an image, a broken model file."""
    from PIL import Image

    from relight.dataset import read_manifest
    from relight.generator.run import generate
    from relight.predictions import write_predictions
    from relight.generator.sampling import GeneratorConfig
    root = tmp_path_factory.mktemp("faults")
    inp = root / "in"
    inp.mkdir()
    data = inp / "D"
    generate(data, 4, seed=3, cfg=GeneratorConfig(res=RES, spp=SPP), progress=False)
    recs = read_manifest(data)
    write_predictions(inp / "preds.json", [
        {"id": r["id"], "pan_deg": r["pan_rel_deg"], "tilt_deg": r["light"]["tilt_deg"],
         "rgb": r["light"]["rgb"]} for r in recs], dataset=str(data))
    shutil.copy(data / "images" / "000000.png", inp / "photo.png")
    shutil.copy(data / "scenes" / "000000.json", inp / "scene.png")   # a scene file named like an image
    yy, xx = np.mgrid[:RES, :RES]
    disc = ((xx - RES / 2 + 0.5) ** 2 + (yy - RES / 2 + 0.5) ** 2 < (RES / 3) ** 2).astype(np.uint8) * 255
    Image.fromarray(disc).save(inp / "mask.png")
    Image.fromarray(disc[:8, :8]).save(inp / "small_mask.png")
    (inp / "model.safetensors").write_bytes(b"not a model")
    scratch = root / "out"
    scratch.mkdir()
    return {"root": inp, "D": data, "preds": inp / "preds.json", "photo": inp / "photo.png",
            "scene": data / "scenes" / "000000.json", "exr": data / "exr" / "000000.exr",
            "scene_png": inp / "scene.png", "mask": inp / "mask.png", "small_mask": inp / "small_mask.png",
            "bad_model": inp / "model.safetensors", "out": scratch}


def fill(argv, w, tmp_path):
    keys = {k: str(v) for k, v in w.items()} | {"tmp": str(tmp_path)}
    return [a.format(**keys) for a in argv]


def refused_unchanged(argv, w, tmp_path, capfd, contains=None):
    before = tree(w["root"])
    code, _, err = cli(fill(argv, w, tmp_path), capfd)
    assert_refused(code, err, contains)
    assert tree(w["root"]) == before
    return err


# --- 1. an output equal to an input, every verb -------------------------------------------

OUTPUT_IS_INPUT = [
    ["render", "{scene_png}", "--out", "{scene_png}"],
    ["predict", "{photo}", "--out", "{photo}"],
    ["predict", "{D}/images", "--out", "{D}/images/000001.png"],
    ["evaluate", "--data", "{D}", "--out", "{D}/images"],
    ["evaluate", "--data", "{D}", "--out", "{D}/manifest.jsonl"],
    ["evaluate", "--data", "{D}", "--out", "{D}/masks"],
    ["train", "--data", "{D}", "--out", "{D}/scenes", "--res", "16"],
    ["train", "--data", "{D}", "--out", "{D}"],
    ["compare", "{preds}", "--data", "{D}", "--out", "{D}"],
    ["compare", "{preds}", "--data", "{D}", "--out", "{root}"],
    ["baseline", "gray-world", "--data", "{D}", "--split", "all", "--out", "{D}/manifest.jsonl"],
    ["baseline", "gray-world", "--data", "{D}", "--split", "all", "--out", "{D}/dataset.json"],
    ["invert", "--scene", "{scene}", "--image", "{exr}", "--out", "{scene}"],
    ["invert", "--scene", "{scene}", "--image", "{exr}", "--out", "{tmp}/p.json", "--trace", "{exr}"],
    ["invert", "--data", "{D}", "--out", "{D}/manifest.jsonl"],
    ["probe", "--chrome", "{photo}", "--chrome-mask", "{mask}", "--fov", "40", "--out", "{mask}"],
    ["figure", "pole", "{photo}", "{preds}", "--out", "{photo}"],
    ["figure", "spheres", "{preds}", "--data", "{D}", "--out", "{D}"],
    ["generate", "--out", "{preds}", "--count", "1", "--res", "16"],
]


@pytest.mark.parametrize("argv", OUTPUT_IS_INPUT, ids=lambda a: " ".join(a[:1] + a[-2:]))
def test_output_equal_to_input_is_refused(argv, world, tmp_path, capfd):
    refused_unchanged(argv, world, tmp_path, capfd)


def test_output_refusal_through_the_console_script(world, tmp_path):
    before = tree(world["root"])
    cmd = CLI + ["baseline", "gray-world", "--data", str(world["D"]), "--split", "all",
                 "--out", str(world["D"] / "manifest.jsonl")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=PROCESS_TIMEOUT_S)
    assert_refused(proc.returncode, proc.stderr, "part of the input dataset")
    assert tree(world["root"]) == before


# An output folder that holds an input: the command writes its folder's files by name,
# so an input kept there could be replaced (issue 27: `train --init RUN/best.safetensors
# --out RUN` replaced the init weights). One rule, every verb (relight.fileio.check_outputs).
HOLDS_INPUT = [
    ["train", "--data", "{D}", "--out", "{tmp}/RUN", "--init", "{tmp}/RUN/best.safetensors", "--res", "16",
     "--epochs", "1", "--quiet"],
    ["train", "--data", "{D}", "--out", "{tmp}/RUN", "--init", "{tmp}/link.safetensors", "--res", "16",
     "--epochs", "1", "--quiet"],   # a link to RUN/best.safetensors
    ["train", "--data", "{tmp}/RUN/D", "--out", "{tmp}/RUN", "--res", "16", "--epochs", "1", "--quiet"],
    ["evaluate", "--data", "{D}", "--model", "{tmp}/RUN/best.safetensors", "--out", "{tmp}/RUN"],
    ["evaluate", "--data", "{tmp}/RUN/D", "--out", "{tmp}/RUN"],
    ["generate", "--config", "{tmp}/RUN/config.json", "--out", "{tmp}/RUN", "--count", "1", "--res", "16"],
    ["generate", "--preset", "mid", "--config", "{tmp}/RUN/config.json", "--out", "{tmp}/RUN", "--count", "1"],
    ["compare", "{tmp}/RUN/preds.json", "--data", "{D}", "--out", "{tmp}/RUN"],
    ["figure", "spheres", "{tmp}/RUN/preds.json", "--data", "{D}", "--out", "{tmp}/RUN"],
    ["calibrate", "--data", "{D}", "--model", "{tmp}/RUN/best.safetensors", "--out", "{tmp}/RUN/best.safetensors"],
]


@pytest.mark.parametrize("argv", HOLDS_INPUT, ids=lambda a: " ".join(a[:1] + a[-2:]))
def test_output_folder_holding_an_input_is_refused(argv, world, tmp_path, capfd):
    from conftest import untrained_model
    run = tmp_path / "RUN"
    run.mkdir()
    untrained_model(run / "best.safetensors", res=RES)
    (tmp_path / "link.safetensors").symlink_to(run / "best.safetensors")
    shutil.copytree(world["D"], run / "D")
    (run / "config.json").write_text(json.dumps({"res": RES, "spp": SPP}))
    shutil.copy(world["preds"], run / "preds.json")
    before, inputs = tree(tmp_path), tree(world["root"])
    code, _, err = cli(fill(argv, world, tmp_path), capfd)
    assert_refused(code, err)
    assert "RUN" in err
    assert tree(tmp_path) == before and tree(world["root"]) == inputs


# --- 2. --out of the wrong kind, half-written leftovers -------------------------------------

WRONG_OUT = [
    (["predict", "{photo}", "--out", "{D}/images"], "is a folder"),
    (["probe", "--chrome", "{photo}", "--chrome-mask", "{mask}", "--fov", "40", "--out", "{root}"], "is a folder"),
    (["evaluate", "--data", "{D}", "--out", "{preds}"], "not a folder"),
    (["train", "--data", "{D}", "--out", "{preds}", "--res", "16"], "not a folder"),
    (["compare", "{preds}", "--data", "{D}", "--out", "{photo}"], None),
    (["figure", "spheres", "{preds}", "--data", "{D}", "--out", "{photo}"], "not a folder"),
    (["generate", "--out", "{photo}", "--count", "1"], "not a folder"),
    (["probe", "--chrome", "{photo}", "--chrome-mask", "{small_mask}", "--fov", "40", "--out", "{tmp}/p.json"],
     "pixels"),
    (["predict", "{photo}", "--model", "{bad_model}", "--out", "{tmp}/p.json"], "model"),
]


@pytest.mark.parametrize("argv,contains", WRONG_OUT,
                         ids=lambda a: " ".join(a[:1] + a[-2:]) if isinstance(a, list) else "")
def test_wrong_kind_of_output_or_input_is_refused(argv, contains, world, tmp_path, capfd):
    refused_unchanged(argv, world, tmp_path, capfd, contains)
    assert not temps_under(tmp_path) and not os.path.exists(tmp_path / "p.json")


def test_evaluate_writes_all_four_files_or_none(world, tmp_path, capfd):
    # An older report is there; the fourth file cannot be written (a folder is in its
    # way): the command fails and the older report is left exactly as it was.
    out = tmp_path / "report"
    out.mkdir()
    for name in ("report.md", "metrics.json", "per_image.csv"):
        (out / name).write_text("older\n")
    (out / "predictions.json").mkdir()
    before, inputs = tree(tmp_path), tree(world["root"])
    code, _, err = cli(["evaluate", "--data", world["D"], "--split", "all", "--out", out], capfd)
    assert_refused(code, err, "predictions.json")
    assert tree(tmp_path) == before and tree(world["root"]) == inputs
    # and with the way clear, all four are replaced
    (out / "predictions.json").rmdir()
    code, _, err = cli(["evaluate", "--data", world["D"], "--split", "all", "--out", out], capfd)
    assert code == 0, err
    from relight.net.io import read_model_header, resolve_model
    cones = ["reliability.png"] if read_model_header(resolve_model(None))[0].kappa_head else []   # the default model's
    assert sorted(os.listdir(out)) == sorted(["metrics.json", "per_image.csv", "predictions.json", "report.md"] + cones)
    assert (out / "report.md").read_text() != "older\n"


def test_invert_writes_out_and_trace_or_neither(world, tmp_path, capfd):
    (tmp_path / "trace.csv").mkdir()   # the trace cannot be written
    code, _, err = cli(["invert", "--scene", world["scene"], "--image", world["exr"], "--out", tmp_path / "p.json",
                        "--trace", tmp_path / "trace.csv", "--max-iters", "1", "--quiet"], capfd)
    assert_refused(code, err, "trace.csv")
    assert sorted(os.listdir(tmp_path)) == ["trace.csv"]


def test_failed_generate_leaves_nothing_and_does_not_block(world, tmp_path, capfd):
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    (meshes / "junk.obj").write_bytes(b"\x00\xff garbage \x01\x02 not an OBJ file\nf 1 2 9\n")
    out = tmp_path / "ds"
    code, _, err = cli(["generate", "--count", "2", "--res", RES, "--spp", SPP, "--mesh-dir", meshes, "--config",
                        world["preds"], "--out", out, "--quiet"], capfd)
    assert_refused(code, err)
    code, _, err = cli(["generate", "--count", "4", "--res", RES, "--spp", SPP, "--seed", "3", "--mesh-dir", meshes,
                        "--out", out, "--quiet"], capfd)
    assert_refused(code, err, "junk.obj")
    assert not out.exists()   # nothing was there before, nothing is left
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = cli(["generate", "--count", "4", "--res", RES, "--spp", SPP, "--seed", "3", "--mesh-dir", meshes,
                        "--out", empty, "--quiet"], capfd)
    assert_refused(code, err, "junk.obj")
    assert os.listdir(empty) == []   # an existing folder is left as it was
    code, _, err = cli(["generate", "--count", "1", "--res", RES, "--spp", SPP, "--out", out, "--quiet"], capfd)
    assert code == 0, err     # the corrected command is not blocked by a leftover card
    assert manifest_ids(out) == ["000000"]


def test_compare_with_nothing_comparable_exits_2(world, tmp_path, capfd):
    from relight.predictions import write_predictions
    preds = tmp_path / "unknown.json"
    write_predictions(preds, [{"id": "nope", "pan_deg": 10.0, "tilt_deg": 40.0, "rgb": [1, 1, 1]}],
                      dataset=str(world["D"]))
    code, _, err = cli(["compare", preds, "--data", world["D"], "--out", tmp_path / "r", "--skip-bad",
                        "--quiet"], capfd)
    assert_refused(code, err, "nothing could be compared")
    assert not (tmp_path / "r").exists()


def test_compare_overflowing_rgb_is_one_line_and_not_doubled(world, tmp_path, capfd):
    from relight.predictions import write_predictions
    preds = tmp_path / "huge.json"
    write_predictions(preds, [{"id": "000000", "pan_deg": 10.0, "tilt_deg": 40.0, "rgb": [1e308, 1e308, 1.0]}],
                      dataset=str(world["D"]))
    code, out, err = cli(["compare", preds, "--data", world["D"], "--out", tmp_path / "r", "--quiet"], capfd)
    # a huge but finite colour is a valid colour (mostly red + green): compared normally
    assert code == 0, err
    assert err.count("entry '000000'") <= 1


# --- 3. one writer per dataset, duplicates ----------------------------------------------------

def test_second_writer_is_refused(world, tmp_path):
    # another process holds the dataset's lock (here: this one): generate refuses it
    from relight.fileio import FolderLock
    data = tmp_path / "D"
    shutil.copytree(world["D"], data)
    before = tree(data)
    with FolderLock(data, "dataset"):
        proc = subprocess.run(generate_cmd(data, 8, 3), capture_output=True, text=True, timeout=PROCESS_TIMEOUT_S)
    assert_refused(proc.returncode, proc.stderr, "another relight process")
    assert tree(data) == before


@pytest.mark.slow
def test_two_generate_processes(tmp_path):
    out = tmp_path / "ds"
    first = subprocess.Popen(generate_cmd(out, 2000), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for_records(out, 1, first)
        assert first.poll() is None
        second = subprocess.run(generate_cmd(out, 2000), capture_output=True, text=True, timeout=PROCESS_TIMEOUT_S)
        assert_refused(second.returncode, second.stderr, "another relight process")
        assert first.poll() is None   # the first writer is unaffected
    finally:
        first.kill()
        first.wait()
    ids = [r["id"] for r in check_complete(out)]
    assert ids == [f"{i:06d}" for i in range(len(ids))]   # one writer: in order, no duplicate


def test_duplicate_records_read_once_and_repaired(world, tmp_path, capfd):
    from relight.dataset import read_manifest
    data = tmp_path / "D"
    shutil.copytree(world["D"], data)
    lines = (data / "manifest.jsonl").read_bytes().splitlines(keepends=True)
    (data / "manifest.jsonl").write_bytes(b"".join(lines + lines[:2]))   # two writers appended twice
    assert [r["id"] for r in read_manifest(data)] == [f"{i:06d}" for i in range(4)]
    code, _, err = cli(["evaluate", "--data", data, "--split", "all", "--out", tmp_path / "e"], capfd)
    assert code == 0, err
    assert json.loads((tmp_path / "e" / "metrics.json").read_text())["n"] == 4
    code, _, err = cli(["generate", "--count", "4", "--res", RES, "--spp", SPP, "--seed", "3", "--out", data,
                        "--quiet"], capfd)
    assert code == 0, err
    assert manifest_ids(data) == [f"{i:06d}" for i in range(4)]   # repaired in place


@pytest.mark.parametrize("verb", ["evaluate", "train", "compare", "invert"])
def test_conflicting_duplicate_or_malformed_record_is_refused(verb, world, tmp_path, capfd):
    data = tmp_path / "D"
    shutil.copytree(world["D"], data)
    lines = (data / "manifest.jsonl").read_bytes().splitlines(keepends=True)
    rec = json.loads(lines[1])
    rec["light"]["tilt_deg"] = "forty"          # a non-numeric field
    bad = json.dumps(rec).encode() + b"\n"
    for content, words in ((b"".join(lines[:1] + [bad] + lines[2:]), "tilt_deg"),
                           (b"".join(lines + [lines[0].replace(b'"split"', b'"extra": 1, "split"')]), "twice")):
        (data / "manifest.jsonl").write_bytes(content)
        before = tree(tmp_path)
        argv = {"evaluate": ["evaluate", "--data", data, "--split", "all", "--out", tmp_path / "o"],
                "train": ["train", "--data", data, "--out", tmp_path / "o", "--res", "16", "--quiet"],
                "compare": ["compare", world["preds"], "--data", data, "--out", tmp_path / "o", "--quiet"],
                "invert": ["invert", "--data", data, "--split", "all", "--out", tmp_path / "o.json"]}[verb]
        code, _, err = cli(argv, capfd)
        assert_refused(code, err, words)
        assert "manifest.jsonl" in err
        assert tree(tmp_path) == before


# --- 4. kill -9 ------------------------------------------------------------------------------

def _kill_and_resume(tmp_path, count, workers):
    rng = random.Random(KILL_SEED + workers)
    out = tmp_path / "ds"
    extra = ["--workers", str(workers)] if workers > 1 else []
    for attempt in range(2):   # two kills at random moments, then a run to the end
        proc = subprocess.Popen(generate_cmd(out, count, 7, *extra), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        wait_for_records(out, 1 + attempt * 2, proc)
        time.sleep(rng.uniform(0.0, 0.4))
        kids = children_of(proc.pid)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.time() + WORKER_EXIT_S
        while any(alive(k) for k in kids) and time.time() < deadline:
            time.sleep(0.05)
        assert not [k for k in kids if alive(k)], "worker processes outlived their parent"
        recs = check_complete(out)            # every record's files are whole
        assert len(recs) < count
    done = subprocess.run(generate_cmd(out, count, 7, *extra), capture_output=True, text=True,
                          timeout=PROCESS_TIMEOUT_S)
    assert done.returncode == 0, done.stderr
    ids = manifest_ids(out)
    assert sorted(ids) == [f"{i:06d}" for i in range(count)] and len(ids) == len(set(ids))
    check_complete(out)
    assert not temps_under(out), temps_under(out)
    return out


@pytest.mark.slow
def test_kill_9_single_process_generate(tmp_path):
    _kill_and_resume(tmp_path, 40, workers=1)


@pytest.mark.slow
def test_kill_9_multi_worker_generate(tmp_path):
    _kill_and_resume(tmp_path, 40, workers=2)


def test_workers_die_with_their_parent(tmp_path):
    # the quick form of the test above: one kill of a 2-worker run, workers must go
    out = tmp_path / "ds"
    proc = subprocess.Popen(generate_cmd(out, 60, 7, "--workers", "2"), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    wait_for_records(out, 1, proc)
    kids = children_of(proc.pid)
    assert kids, "no worker processes seen"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.time() + WORKER_EXIT_S
    while any(alive(k) for k in kids) and time.time() < deadline:
        time.sleep(0.05)
    assert not [k for k in kids if alive(k)], "worker processes outlived their parent"
    n = len(check_complete(out))
    time.sleep(0.5)
    assert len(manifest_ids(out)) == n     # nobody writes any more


def test_stray_temps_are_ignored_by_readers_and_removed_on_resume(world, tmp_path, capfd):
    data = tmp_path / "D"
    shutil.copytree(world["D"], data)
    (data / "images" / "000219.tmp20245.png").write_bytes(b"")          # an older relight's
    (data / "exr" / ".000001.relight-tmp-99999-abcd.exr").write_bytes(b"half")
    (data / "dataset.json.tmp").write_text("{")
    code, out, err = cli(["predict", data / "images", "--out", tmp_path / "p.json"], capfd)
    assert code == 0, err
    assert "wrote" in out and "(4 predictions)" in out
    code, _, err = cli(["generate", "--count", "4", "--res", RES, "--spp", SPP, "--seed", "3", "--out", data,
                        "--quiet"], capfd)
    assert code == 0, err
    assert not temps_under(data)


# --- 5. images of every PNG mode and bit depth ------------------------------------------------

def _png(width, height, depth, ctype, row: bytes, palette: bytes | None = None) -> bytes:
    """A PNG whose every row is ``row`` (filter 0), written by hand so that every colour
    type and bit depth of the PNG specification can be made."""
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
    head = chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, depth, ctype, 0, 0, 0))
    body = (chunk(b"PLTE", palette) if palette else b"") + chunk(b"IDAT", zlib.compress((b"\0" + row) * height))
    return b"\x89PNG\r\n\x1a\n" + head + body + chunk(b"IEND", b"")


W = 8   # pixels per row: whole bytes at every bit depth
PAL = bytes([0, 0, 0, 40, 200, 90])   # index 1 = (40, 200, 90)
# (name, depth, colour type, row bytes, palette, expected sRGB value per channel, tolerance)
PNG_CASES = [
    ("grey1", 1, 0, b"\xff" * 1, None, (1.0,) * 3, 1e-6),
    ("grey2", 2, 0, b"\xaa" * 2, None, (2 / 3,) * 3, 1e-6),           # value 0b10 = 2 of 3
    ("grey4", 4, 0, b"\x55" * 4, None, (5 / 15,) * 3, 1e-6),
    ("grey8", 8, 0, bytes([64]) * W, None, (64 / 255,) * 3, 1e-6),
    ("grey16", 16, 0, b"\x40\x00" * W, None, (0x4000 / 65535,) * 3, 1e-6),   # was read almost white
    ("rgb8", 8, 2, bytes([200, 100, 50]) * W, None, (200 / 255, 100 / 255, 50 / 255), 1e-6),
    ("rgb16", 16, 2, b"\xc0\x00\x40\x00\x10\x00" * W, None, (0xC000 / 65535, 0x4000 / 65535, 0x1000 / 65535),
     1e-6),
    ("pal1", 1, 3, b"\xff", PAL, (40 / 255, 200 / 255, 90 / 255), 1e-6),
    ("pal2", 2, 3, b"\x55" * 2, PAL, (40 / 255, 200 / 255, 90 / 255), 1e-6),
    ("pal4", 4, 3, b"\x11" * 4, PAL, (40 / 255, 200 / 255, 90 / 255), 1e-6),
    ("pal8", 8, 3, b"\x01" * W, PAL, (40 / 255, 200 / 255, 90 / 255), 1e-6),
    ("greyalpha8", 8, 4, bytes([64, 128]) * W, None, (64 / 255,) * 3, 1e-6),
    ("greyalpha16", 16, 4, b"\x40\x00\x80\x00" * W, None, (0.25,) * 3, 1 / 255),
    ("rgba8", 8, 6, bytes([200, 100, 50, 7]) * W, None, (200 / 255, 100 / 255, 50 / 255), 1e-6),
    ("rgba16", 16, 6, b"\xc0\x00\x40\x00\x10\x00\x00\x10" * W, None,
     (0xC000 / 65535, 0x4000 / 65535, 0x1000 / 65535), 1e-6),
]


@pytest.fixture(scope="module")
def png_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("pngs")
    for name, depth, ctype, row, pal, _, _ in PNG_CASES:
        (d / f"{name}.png").write_bytes(_png(W, 6, depth, ctype, row, pal))
    return d


@pytest.mark.parametrize("case", PNG_CASES, ids=[c[0] for c in PNG_CASES])
def test_every_png_mode_and_depth_reads_its_true_values(case, png_dir):
    from relight import colour
    from relight.imageio import load_image, read_image
    name, depth, _, _, _, want, tol = case
    pixels, encoding, note = load_image(png_dir / f"{name}.png")
    assert encoding == "srgb" and pixels.shape == (6, W, 3)
    np.testing.assert_allclose(pixels, np.broadcast_to(want, pixels.shape), atol=tol)
    assert f"{depth}-bit" in note
    linear, note2 = read_image(png_dir / f"{name}.png")
    np.testing.assert_allclose(linear[0, 0], colour.srgb_decode(np.asarray(want)), atol=max(tol, 1e-6) * 2)
    assert "linear" in note2


def test_predict_reads_every_png_and_says_how(png_dir, tmp_path, capfd):
    code, out, err = cli(["predict", png_dir, "--out", tmp_path / "p.json"], capfd)
    assert code == 0, err
    assert "16-bit sRGB (PNG grey)" in out and "alpha ignored" in out and "palette" in out
    assert len(json.loads((tmp_path / "p.json").read_text())["predictions"]) == len(PNG_CASES)


def _exr(path, channels: dict):
    import OpenEXR
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as f:
        f.write(str(path))


@pytest.mark.parametrize("kind", ["RGB", "RGBA-half", "R,G,B", "Y"])
def test_exr_channel_layouts(kind, tmp_path):
    from relight.imageio import read_image
    value = np.array([0.5, 0.25, 0.125], np.float32)
    img = np.tile(value, (4, 5, 1))
    channels = {"RGB": {"RGB": img},
                "RGBA-half": {"RGBA": np.concatenate([img, np.ones((4, 5, 1), np.float32)], -1).astype(np.float16)},
                "R,G,B": {c: np.ascontiguousarray(img[..., i]) for i, c in enumerate("RGB")},
                "Y": {"Y": np.ascontiguousarray(img[..., 0])}}[kind]
    _exr(tmp_path / "x.exr", channels)
    got, note = read_image(tmp_path / "x.exr")
    want = np.broadcast_to(value if kind != "Y" else value[:1].repeat(3), (4, 5, 3))
    np.testing.assert_allclose(got, want, atol=1e-3)
    assert "EXR" in note


BAD_IMAGES = {
    "truncated.png": lambda d: _png(W, 6, 8, 2, bytes([1, 2, 3]) * W)[:60],
    "empty.png": lambda d: b"",
    "text.png": lambda d: b"hello, not an image\n",
    "bomb.png": lambda d: _png(100_000, 100_000, 8, 0, b"\0" * 16)[:33] + _png(W, 1, 8, 0, b"\0" * W)[33:],
    "truncated.exr": lambda d: (d["exr"].read_bytes()[: len(d["exr"].read_bytes()) * 2 // 3]),
    "header.exr": lambda d: d["exr"].read_bytes()[:300],
}


@pytest.mark.parametrize("name", sorted(BAD_IMAGES))
@pytest.mark.parametrize("verb", ["predict", "probe", "pole"])
def test_unreadable_images_are_one_line(name, verb, world, tmp_path, capfd):
    bad = tmp_path / name
    bad.write_bytes(BAD_IMAGES[name](world))
    argv = {"predict": ["predict", bad, "--out", tmp_path / "p.json"],
            "probe": ["probe", "--chrome", bad, "--chrome-mask", world["mask"], "--fov", "40",
                      "--out", tmp_path / "p.json"],
            "pole": ["figure", "pole", bad, world["preds"], "--id", "000000", "--out", tmp_path / "x.png"]}[verb]
    before = tree(tmp_path)
    code, out, err = cli(argv, capfd)
    assert_refused(code, err, name)
    assert out == "" or verb != "predict" or "Warning" not in out   # no library chatter
    assert tree(tmp_path) == before


# --- 6. corrupt checkpoints, identical re-run resumes ------------------------------------------

TRAIN = ["--res", "16", "--width", "4", "--batch-size", "4", "--seed", "1", "--quiet"]


@pytest.fixture(scope="module")
def run_dir(world, tmp_path_factory):
    from relight.cli import main
    out = tmp_path_factory.mktemp("run") / "r"
    assert main(["train", "--data", str(world["D"]), "--out", str(out), "--epochs", "1"] + TRAIN) == 0
    return out


CORRUPT = {
    "empty": lambda good: b"",
    "garbage": lambda good: b"\x80\x02}q\x00garbage" * 10,
    "truncated": lambda good: good[: len(good) // 2],
    "foreign": None,   # a valid torch file that is not a relight checkpoint
}


@pytest.mark.parametrize("kind", sorted(CORRUPT))
@pytest.mark.parametrize("resume", [True, False])
def test_corrupt_checkpoint_is_one_line(kind, resume, world, run_dir, tmp_path, capfd):
    import torch
    run = tmp_path / "r"
    shutil.copytree(run_dir, run)
    good = (run / "checkpoint.pt").read_bytes()
    if CORRUPT[kind] is None:
        torch.save({"weights": torch.zeros(3)}, run / "checkpoint.pt")
    else:
        (run / "checkpoint.pt").write_bytes(CORRUPT[kind](good))
    before = tree(tmp_path)
    # the identical command (epochs 1 -> 2 changes the settings, so that one needs --resume)
    argv = ["train", "--data", world["D"], "--out", run, "--epochs", "2"] + TRAIN + (["--resume"] if resume else [])
    code, _, err = cli(argv, capfd)
    assert_refused(code, err, "checkpoint" if resume else "--resume")
    assert tree(tmp_path) == before
    assert err.rstrip("\n").isprintable()   # no terminal escape codes or other control characters


def test_library_messages_are_cut_at_a_word_without_terminal_codes():
    """Checkpoint, model, image and mesh errors quote the library's reason through
    relight.errors.brief: the first sentence of its first line, no escape codes, and when
    still long, cut between words (marked ...), never mid-word."""
    from relight.errors import brief
    torchlike = ("\x1b[1mWeights only load failed\x1b[0m. In PyTorch 2.6, we changed the default value of the "
                 "`weights_only` argument in `torch.load` from `False` to `True`.\nRe-running ...")
    assert brief(RuntimeError(torchlike)) == "Weights only load failed"
    long = "PytorchStreamReader failed reading zip archive: failed finding central directory " * 3
    text = brief(long, limit=100)
    assert text.endswith("...") and len(text) <= 103
    assert long.startswith(text[:-3]) and long[len(text) - 3] == " "   # the cut falls between words
    assert brief(EOFError()) == "EOFError"


@pytest.mark.parametrize("given", [["{photo}", "{photo}"], ["{D}/images", "{D}/images/000001.png"],
                                   ["{photo}", "{tmp}/link.png"]])
def test_predict_refuses_one_image_given_twice(given, world, tmp_path, capfd):
    os.symlink(world["photo"], tmp_path / "link.png")
    code, _, err = cli(["predict", *fill(given, world, tmp_path), "--out", tmp_path / "p.json"], capfd)
    assert_refused(code, err, "given twice")
    assert not (tmp_path / "p.json").exists()


def test_bad_input_on_dask_is_one_line_on_stderr(world, tmp_path, capfd):
    """With --scheduler local:2 the engine's "dask: N worker processes" line goes to stdout
    with the other reports: a bad input found by a worker is the one line on stderr."""
    pytest.importorskip("distributed")
    data = tmp_path / "D"
    shutil.copytree(world["D"], data)
    (data / "exr" / "000001.exr").write_bytes(b"not an exr")
    code, out, err = cli(["baseline", "gray-world", "--data", data, "--split", "all", "--out", tmp_path / "b.json",
                          "--scheduler", "local:2"], capfd)
    assert_refused(code, err, "000001.exr")
    assert not (tmp_path / "b.json").exists()


def test_identical_train_command_resumes(world, run_dir, tmp_path, capfd):
    run = tmp_path / "r"
    shutil.copytree(run_dir, run)
    settings = json.loads((run / "settings.json").read_text())
    settings["epochs"] = 2                       # as if a 2-epoch run was killed after epoch 1
    (run / "settings.json").write_text(json.dumps(settings))
    code, out, err = cli(["train", "--data", world["D"], "--out", run, "--epochs", "2"] + TRAIN, capfd)
    assert code == 0, err
    with open(run / "log.csv") as f:
        assert [line.split(",")[0] for line in f.read().splitlines()[1:]] == ["1", "2"]
    assert not temps_under(run)


def test_second_trainer_on_one_run_is_refused(world, run_dir, tmp_path, capfd):
    from relight.fileio import FolderLock
    run = tmp_path / "r"
    shutil.copytree(run_dir, run)
    with FolderLock(run, "training run"):
        code, _, err = cli(["train", "--data", world["D"], "--out", run, "--epochs", "2", "--resume"] + TRAIN, capfd)
    assert_refused(code, err, "another relight process")


# --- 7. every numeric option of every verb: zero, negative, NaN, huge ---------------------------

BASE = {
    "generate": ["generate", "--out", "{tmp}/g"],
    "render": ["render", "{scene}", "--out", "{tmp}/r.png"],
    "train": ["train", "--data", "{D}", "--out", "{tmp}/t"],
    "evaluate": ["evaluate", "--data", "{D}", "--out", "{tmp}/e"],
    "predict": ["predict", "{photo}", "--out", "{tmp}/p.json"],
    "compare": ["compare", "{preds}", "--out", "{tmp}/c"],
    "figure spheres": ["figure", "spheres", "{preds}", "--out", "{tmp}/s"],
    "figure pole": ["figure", "pole", "{photo}", "{preds}", "--out", "{tmp}/pole.png"],
    "invert": ["invert", "--scene", "{scene}", "--image", "{exr}", "--out", "{tmp}/i.json"],
    "baseline": ["baseline", "gray-world", "--data", "{D}", "--out", "{tmp}/b.json"],
    "probe": ["probe", "--chrome", "{photo}", "--chrome-mask", "{mask}", "--fov", "40", "--out", "{tmp}/pr.json"],
    "demo": ["demo", "--out", "{tmp}/demo"],
    "export-blender": ["export-blender", "{scene}", "--out", "{tmp}/x.blend"],
}
GENERIC_BAD = ["nan", "inf", "-inf", "1e308", "-1e308", "1e999", "abc", "", "99999999999999999999"]
# values that are numbers of the right kind but out of range (zero, negative, too big)
RANGE_BAD = {
    "--count": ["0", "-1", "1000001"], "--seed": ["-1", "4294967296"], "--res": ["0", "-16", "100000"],
    "--spp": ["0", "-1"], "--max-depth": ["0"], "--workers": ["-2", "100000"], "--threads": ["0", "-3"],
    "--light-pan": ["1e9"], "--light-tilt": ["95", "-91", "1e308"], "--rgb": ["0,0,0", "-1,1,1", "1e308,1,1", "1,2"],
    "--epochs": ["0"], "--epoch-images": ["0", "-1"], "--batch-size": ["0"], "--lr": ["0", "-1", "2"], "--patience": ["-1"],
    "--torch-threads": ["0"], "--loss-weights": ["0,0,0", "-1,1,1", "1,1"], "--width": ["0"],
    "--max-minutes": ["-1"], "--camera-tilt": ["90", "-90", "1e308"], "--limit": ["0", "-1"],
    "--max-columns": ["0"], "--max-iters": ["0"], "--time-budget": ["0", "-5"],
    "--kappa-weight": ["-1"], "--camera-weight": ["-1", "1e7"], "--fov": ["0", "180", "-1"], "--focal-px": ["0", "-1"],
    "--target-rmse": ["0", "-0.1", "2"], "--scheduler": ["local:0", "local:-1", "local:100000"],
    "--object-parts": ["0", "33", "5-3", "0-4", "1-2-3", "-1", "2-"],
    "--chrome-circle": ["32,32,1e9", "32,32,0", "32,32,-1", "1e9,1,1", "1,2", "1,2,3,4"],
    "--diffuse-circle": ["32,32,1e9", "32,32,0", "-1e9,1,1"],
}


def _subparsers(parser, path=()):
    import argparse
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _subparsers(sub, path + (name,))
    if path:
        yield " ".join(path), parser


def numeric_options():
    """(verb, option) for every option whose value is a number (or numbers)."""
    from relight.cli import build_parser
    out = [("render", "--threads")]   # the global option, given before a verb
    for verb, sub in _subparsers(build_parser()):
        for action in sub._actions:
            t = action.type
            if action.option_strings and t is not None and t is not str and \
                    (t in (int, float) or getattr(t, "__module__", "") in ("relight.commands.argtypes", "relight.engine")):
                out.append((verb, action.option_strings[-1]))
    return out


def test_every_numeric_option_has_a_bounded_type():
    from relight.cli import build_parser
    plain = [(verb, a.option_strings[-1]) for verb, sub in _subparsers(build_parser()) for a in sub._actions
             if a.option_strings and a.type in (int, float)]
    assert not plain, f"options with an unbounded int/float type: {plain}"
    opts = numeric_options()
    assert {verb for verb, _ in opts} <= set(BASE)
    missing = {o for _, o in opts} - set(RANGE_BAD) - {"--threads"}
    assert not missing, f"numeric options without out-of-range cases: {missing}"


def _sweep():
    cases = []
    for verb, opt in numeric_options():
        for value in GENERIC_BAD + RANGE_BAD.get(opt, []):
            cases.append((verb, opt, value))
    return cases


@pytest.mark.parametrize("verb,opt,value", _sweep(), ids=lambda x: str(x))
def test_bad_number_is_one_line(verb, opt, value, world, tmp_path, capfd):
    base = BASE[verb]
    argv = (["--threads", value] + base) if opt == "--threads" and verb == "render" else base + [opt, value]
    refused_unchanged(argv, world, tmp_path, capfd, contains=opt)   # the message names the option
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("argv", [
    ["generate", "--out", "{tmp}/g", "--res", "100000"],
    ["--threads", "-3", "render", "{scene}", "--out", "{tmp}/r.png"],
    ["render", "{scene}", "--out", "{tmp}/r.png", "--light-tilt", "95"],
    ["train", "--data", "{D}", "--out", "{tmp}/t", "--seed", "-1"],
])
def test_bad_number_through_the_console_script(argv, world, tmp_path):
    before = tree(world["root"])
    proc = subprocess.run(CLI + fill(argv, world, tmp_path), capture_output=True, text=True,
                          timeout=PROCESS_TIMEOUT_S)
    assert_refused(proc.returncode, proc.stderr)
    assert tree(world["root"]) == before and os.listdir(tmp_path) == []


# --- 7b. sizes checked against the image or a documented limit before any allocation ---------

@pytest.mark.parametrize("argv,contains", [
    (["probe", "--chrome", "{photo}", "--chrome-circle", "32,32,1e308", "--fov", "40"], "--chrome-circle"),
    (["probe", "--chrome", "{photo}", "--chrome-circle", "32,32,1e9", "--fov", "40"], "--chrome-circle"),
    (["probe", "--chrome", "{photo}", "--chrome-circle", "8,8,1000", "--fov", "40"], "radius"),
    (["probe", "--chrome", "{photo}", "--chrome-circle", "8,8,12", "--fov", "40"], "radius"),   # > half diagonal
    (["probe", "--chrome", "{photo}", "--chrome-circle", "900,8,4", "--fov", "40"], "misses"),
    (["probe", "--diffuse", "{photo}", "--diffuse-circle", "32,32,1e308"], "--diffuse-circle"),
    (["probe", "--diffuse", "{photo}", "--diffuse-circle", "8,8,1000"], "radius"),
], ids=lambda a: " ".join(a[3:5]) if isinstance(a, list) else "")
def test_probe_circle_must_fit_the_image(argv, contains, world, tmp_path, capfd):
    refused_unchanged(argv + ["--out", "{tmp}/p.json"], world, tmp_path, capfd, contains)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("field,value", [("render.res", 100000), ("render.res", 0), ("render.spp", 10 ** 7),
                                         ("render.max_depth", 1000), ("room.texture_res", 100000),
                                         ("room.texture_res", 0), ("render.res", 2.5)])
@pytest.mark.parametrize("verb", ["render", "invert", "compare-dataset"])
def test_scene_file_sizes_are_bounded(verb, field, value, world, tmp_path, capfd):
    """A scene file's sizes have documented limits (relight.scene.spec.MAX_RES...), checked
    when the file is read: one line naming the file and the field, before Mitsuba allocates."""
    doc = json.loads(world["scene"].read_text())
    part, key = field.split(".")
    doc[part][key] = value
    if verb == "compare-dataset":   # a dataset whose scene file is absurd
        data = tmp_path / "D"
        shutil.copytree(world["D"], data)
        (data / "scenes" / "000000.json").write_text(json.dumps(doc))
        argv = ["compare", world["preds"], "--data", data, "--out", tmp_path / "c", "--quiet"]
        contains = "000000.json"
    else:
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps(doc))
        argv = {"render": ["render", bad, "--out", tmp_path / "r.png"],
                "invert": ["invert", "--scene", bad, "--image", world["exr"], "--out", tmp_path / "i.json",
                           "--quiet"]}[verb]
        contains = "bad.json"
    before = tree(tmp_path)
    code, _, err = cli(argv, capfd)
    assert_refused(code, err, contains)
    assert field in err and tree(tmp_path) == before


def test_scene_limits_match_the_options():
    from relight.commands import argtypes
    from relight.scene import spec
    assert (spec.MAX_RES, spec.MAX_SPP) == (argtypes.MAX_RES, argtypes.MAX_SPP)


# --- 8. a full disk, a quota, a read-only file system (issue 27) ---------------------------------

FS_SIZE = "1m"   # a real tmpfs, small enough to fill in a moment


@pytest.fixture
def small_fs(tmp_path):
    """A real 1 MB tmpfs mounted in tmp_path (root only; skipped with the reason otherwise);
    ``fill_to(free)`` fills it to leave ``free`` bytes; ``read_only()`` remounts it read-only."""
    mnt = tmp_path / "fs"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={FS_SIZE}", "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")

    def fill_to(free: int):
        with open(mnt / "filler", "wb") as f:
            try:
                while True:
                    f.write(b"\0" * 65536)
                    f.flush()
            except OSError:
                pass
        with open(mnt / "filler", "r+b") as f:
            f.truncate(max(0, os.path.getsize(mnt / "filler") - free))

    def read_only():
        subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True, capture_output=True)

    try:
        yield mnt, fill_to, read_only
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


FULL_DISK = {
    "generate": ["generate", "--count", "40", "--res", "32", "--spp", "2", "--out", "{fs}/G", "--quiet"],
    "predict": ["predict", "{D}/images", "--out", "{fs}/p.json"],
    "evaluate": ["evaluate", "--data", "{D}", "--split", "all", "--out", "{fs}/E"],
    "train": ["train", "--data", "{D}", "--out", "{fs}/R"] + TRAIN + ["--epochs", "1"],
    "render": ["render", "{scene}", "--out", "{fs}/r.exr"],
    "compare": ["compare", "{preds}", "--data", "{D}", "--out", "{fs}/C", "--quiet"],
    "baseline": ["baseline", "gray-world", "--data", "{D}", "--split", "all", "--out", "{fs}/b.json"],
    "invert": ["invert", "--data", "{D}", "--split", "all", "--limit", "1", "--max-iters", "1", "--out",
               "{fs}/i.json", "--quiet"],
    "figure spheres": ["figure", "spheres", "{preds}", "--data", "{D}", "--out", "{fs}/S"],
}


def _unrecorded(folder) -> list[str]:
    """Files of a dataset folder that no manifest record names (orphans)."""
    from relight.dataset import read_manifest
    named = {r[k] for r in read_manifest(folder) for k in ("image", "exr", "scene")} \
        if os.path.exists(os.path.join(folder, "manifest.jsonl")) else set()
    return [f"{sub}/{n}" for sub in ("images", "exr", "scenes") if os.path.isdir(os.path.join(folder, sub))
            for n in os.listdir(os.path.join(folder, sub)) if f"{sub}/{n}" not in named]


@pytest.mark.parametrize("free", [0, 40_000])
@pytest.mark.parametrize("verb", sorted(FULL_DISK))
def test_full_disk_is_one_line_naming_the_output(verb, free, small_fs, world, tmp_path, capfd):
    mnt, fill_to, _ = small_fs
    fill_to(free)
    inputs = tree(world["root"])
    argv = [a.replace("{fs}", str(mnt)) for a in FULL_DISK[verb]]
    code, _, err = cli(fill(argv, world, tmp_path), capfd)
    if code == 0:   # it fitted (a small output with room left): nothing to check but the inputs
        assert free and tree(world["root"]) == inputs
        print(f"{verb}: fitted in {free} bytes")
        return
    assert_refused(code, err, "no space left")
    option = "--out " + str(mnt)
    assert option in err, err                          # the output as the user gave it
    assert not temps_under(mnt) and tree(world["root"]) == inputs
    left = sorted(os.listdir(mnt))
    if verb == "generate" and "G" in left:             # finished images stay, each with its record
        if check_complete(mnt / "G"):
            assert "images left need about" in err     # the room the rest of the run needs
        assert not _unrecorded(mnt / "G")
        os.remove(mnt / "filler")                      # space comes back: the same command resumes
        code, _, err = cli(fill(argv, world, tmp_path), capfd)
        assert code == 0, err
        assert sorted(manifest_ids(mnt / "G")) == [f"{i:06d}" for i in range(40)]
    else:
        assert left == ["filler"], left                # nothing half-written, no folder left


@pytest.mark.parametrize("verb", ["generate", "train", "render", "predict", "evaluate"])
def test_read_only_output_is_one_line_naming_the_output(verb, small_fs, world, tmp_path, capfd):
    mnt, _, read_only = small_fs
    read_only()
    argv = [a.replace("{fs}", str(mnt)) for a in FULL_DISK[verb]]
    code, _, err = cli(fill(argv, world, tmp_path), capfd)
    assert_refused(code, err, "read-only file system")
    assert "--out " + str(mnt) in err and os.listdir(mnt) == []


def test_read_only_images_folder_leaves_no_orphan_files(small_fs, world, tmp_path, capfd):
    """A dataset whose images/ cannot be written (a read-only mount as root, no write
    permission otherwise): generate stops with one line, every record keeps its three files
    and no exr/ or scenes/ file is left without a record."""
    data = tmp_path / "D"
    shutil.copytree(world["D"], data)
    mnt, _, read_only = small_fs
    shutil.copytree(data / "images", mnt, dirs_exist_ok=True)
    shutil.rmtree(data / "images")
    os.symlink(mnt, data / "images")
    read_only()
    before = tree(data)
    code, _, err = cli(["generate", "--count", "6", "--res", RES, "--spp", SPP, "--seed", "3", "--out", data,
                        "--quiet"], capfd)
    assert_refused(code, err, "--out")
    assert "images/000004.png" in err
    assert not _unrecorded(data) and tree(data) == before


def test_disk_errors_are_named_without_a_disk():
    """The mapping itself (any machine): ENOSPC/EDQUOT/EROFS through errno, a chained
    cause or a library's words; a temporary name is said as its target and its option."""
    import errno as E

    from relight import fileio
    from relight.errors import DiskFullError, OutputError
    fileio.name_outputs({"--out": "/data/run"})
    try:
        tmp = fileio.temp_path("/data/run/best.safetensors")
        assert fileio.describe_output(tmp) == "--out /data/run (best.safetensors)"
        for exc, words in ((OSError(E.ENOSPC, "No space left on device"), "no space left"),
                           (OSError(E.EDQUOT, "Disk quota exceeded"), "disk quota"),
                           (OSError(E.EROFS, "Read-only file system", tmp), "read-only"),
                           (RuntimeError("Error while serializing: I/O error: No space left on device (os "
                                         "error 28)"), "no space left")):
            err = fileio.disk_error(exc, tmp, size=2048)
            assert isinstance(err, DiskFullError) and isinstance(err, OutputError) and words in str(err)
            assert "--out /data/run (best.safetensors)" in str(err) and TEMP_HINT not in str(err)
        assert "2.0 KB" in str(fileio.disk_error(OSError(E.ENOSPC, "x"), tmp, size=2048))
        assert fileio.disk_error(ValueError("bad value"), "/tmp/x") is None   # not a disk problem
        perm = fileio.write_error(PermissionError(E.EACCES, "Permission denied", tmp), "/data/run/best.safetensors",
                                  tmp)
        assert str(perm) == "cannot write --out /data/run (best.safetensors): Permission denied"
    finally:
        fileio.name_outputs({})


# --- 9. the suite on another CPU: committed float references hold with their tolerances -------

def _nudge(value, ulps: int):
    """``value`` with every float moved by ``ulps`` units in the last place (what another
    CPU's vector width or libm may do to a float computed from the same inputs)."""
    if isinstance(value, float):
        for _ in range(ulps):
            value = float(np.nextafter(value, np.inf if value >= 0 else -np.inf))
        return value
    if isinstance(value, dict):
        return {k: _nudge(v, ulps) for k, v in value.items()}
    if isinstance(value, list):
        return [_nudge(v, ulps) for v in value]
    return value


def test_committed_float_references_allow_last_bit_differences():
    """Re-runs the comparisons of the float-reference tests (test_noise, test_scenes) with
    their references moved by a few ulps, as on another machine: they must still pass, and
    a real change (a different draw, a drifted pixel) must still fail."""
    import test_noise
    import test_scenes
    from conftest import render_drift, same_draws_mismatch
    from relight.scene.spec import SceneSpec, load_scene
    legacy = load_scene(test_noise.LEGACY_SCENE)
    doc = json.loads(open(test_noise.LEGACY_SCENE).read())
    assert same_draws_mismatch(SceneSpec.from_dict(_nudge(doc, 4)), legacy) is None
    doc["light"]["pan_deg"] += 1e-6                        # one draw differs: found and named
    assert "pan_deg" in same_draws_mismatch(SceneSpec.from_dict(doc), legacy)
    doc = json.loads(open(test_noise.LEGACY_SCENE).read())
    doc["render"]["seed"] += 1                             # integers stay exact
    assert "seed" in same_draws_mismatch(SceneSpec.from_dict(doc), legacy)
    refs = [np.load(test_noise.LEGACY_RENDER)]
    with np.load(test_scenes.REFERENCES) as stored:
        refs += [stored[name] for name in stored.files]
    rng = np.random.default_rng(0)
    for ref in refs:
        assert render_drift(ref * (1 + 8 * np.finfo(ref.dtype).eps), ref) is None   # last bits
        odd_path = ref.copy()                      # one path sent another way: the largest measured
        odd_path.reshape(-1)[7] += 5e-3
        assert render_drift(odd_path, ref) is None
        assert render_drift(ref * 1.01, ref) is not None                          # a 1% gain
        assert render_drift(ref * (1 + 0.03 * rng.standard_normal(ref.shape)), ref) is not None  # new noise
        assert render_drift(ref[:-1], ref) is not None


def _exact_comparisons_with_committed(source: str) -> list[str]:
    """Lines of a test file that compare, with ``==`` or ``array_equal``, a value loaded
    from a committed reference, directly or through a name assigned from one in the same
    function. A line whose comment says why exactness holds there (``exact``: integers,
    names; ``one machine``: two computations here) is the author's stated choice."""
    committed = re.compile(r"np\.load\(|LEGACY_|REFERENCES|tests/data|SHIPPED_MODEL")
    # == against a value's own kind of literal (a string, an integer, None) is exact by nature
    exact = re.compile(r"array_equal|\bassert [^#]*[^=!<>]==(?!=)(?!\s*(?:[\"'\d]|None\b|True\b|False\b))")
    hits, lines = [], source.splitlines()
    starts = sorted({0} | {i for i, ln in enumerate(lines) if re.match(r"\S", ln)}) + [len(lines)]
    for lo, hi in zip(starts, starts[1:]):
        block, names = lines[lo:hi], set()
        for line in block:
            m = re.match(r"\s*([\w, ]+?)\s*=\s*(.*)", line)
            if m and committed.search(m.group(2)):
                names |= {n.strip() for n in m.group(1).split(",")}
        loaded = committed.pattern + "".join(rf"|\b{re.escape(n)}\b" for n in sorted(names) if n)
        for k, line in enumerate(block, lo + 1):
            code, _, comment = line.partition("#")
            if exact.search(code) and re.search(loaded, code) and not re.search(r"exact|one machine", comment):
                hits.append(f"{k}: {line.strip()}")
    return hits


def test_no_test_compares_committed_floats_exactly():
    """The habit, checked: no line of the suite compares something loaded from a committed
    reference (tests/data, scenes/, the shipped model) with ``==`` or ``array_equal``; the
    check finds the pattern that failed on another CPU (issue 27)."""
    here = os.path.dirname(os.path.abspath(__file__))
    offenders = []
    for name in sorted(os.listdir(here)):
        if name.startswith("test_") and name.endswith(".py") and name != "test_faults.py":
            with open(os.path.join(here, name), encoding="utf-8") as f:
                offenders += [f"{name}:{hit}" for hit in _exact_comparisons_with_committed(f.read())]
    assert not offenders, "exact comparisons with committed floats (use a tolerance):\n" + "\n".join(offenders)
    old = ("    legacy = load_scene(LEGACY_SCENE)\n    new = sample_scene(cfg, 2024, 5)\n"
           "    assert new.room == legacy.room and new.objects == legacy.objects\n")
    assert _exact_comparisons_with_committed(old)   # the line that failed on another CPU


@pytest.mark.parametrize("argv, message", [
    ([], "give --train FOLDER or --load WEIGHTS"),                        # neither
    (["--train", "d", "--load", "w.safetensors"], "give --train FOLDER or --load WEIGHTS"),   # both
    (["--train", "d", "--save", "{weights}"], "exists (give --force to replace it)"),         # would overwrite
])
def test_a_training_scripts_weights_options_are_one_line_errors_and_leave_the_weights(argv, message, tmp_path,
                                                                                      capsys):
    # the probe's training scripts (benchmarks/train_locator.py, train_outline_check.py) check
    # their --train / --load / --save / --force so: one line on stderr, exit 2, the file as it was
    from relight.commands import argtypes
    weights = tmp_path / "w.safetensors"
    weights.write_bytes(b"trained")
    ap = argtypes.OneLineParser(prog="train")
    ap.add_argument("--train", nargs="*", default=[])
    argtypes.add_weights_options(ap)
    args = ap.parse_args([a.format(weights=weights) for a in argv])
    with pytest.raises(SystemExit) as exc:
        argtypes.checked_weights_options(ap, args, args.train)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("train: error: ") and message in err
    assert weights.read_bytes() == b"trained"
    # with --force the same overwrite is allowed
    args = ap.parse_args(["--train", "d", "--save", str(weights), "--force"])
    argtypes.checked_weights_options(ap, args, args.train)
