"""Command line: bad input gives one line on stderr and exit 2; nothing half-written."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from relight.cli import main


def run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse errors
        code = exc.code
    err = capsys.readouterr().err.strip()
    return code, err


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    from relight.generator.sampling import GeneratorConfig, sample_scene
    path = tmp_path_factory.mktemp("cli") / "scene.json"
    sample_scene(GeneratorConfig(res=16, spp=2), 0, 1).save(path)
    return path


@pytest.mark.parametrize("argv", [
    ["generate", "--count", "-1", "--out", "{tmp}/d"],
    ["generate", "--count", "2", "--res", "0", "--out", "{tmp}/d"],
    ["generate", "--count", "2", "--config", "{tmp}/missing.json", "--out", "{tmp}/d"],
    ["generate", "--count", "2", "--mesh-dir", "{tmp}/nomeshes", "--out", "{tmp}/d"],
    ["render", "{tmp}/missing.json", "--out", "{tmp}/x.png"],
    ["render", "{scene}", "--out", "{tmp}/x.jpg"],
    ["render", "{scene}", "--out", "{tmp}/x.png", "--rgb", "0,0,0"],
    ["render", "{scene}", "--out", "{tmp}/x.png", "--light-pan", "nan"],
    ["render", "{scene}", "--out", "{tmp}/x.png", "--rgb", "1,2"],
    ["render", "{corrupt}", "--out", "{tmp}/x.png"],
    ["render", "{v9}", "--out", "{tmp}/x.png"],
    ["render", "{scene}", "--out", "{tmp}/x.png", "--out", "{tmp}/x.jpg"],
    ["render", "{scene}", "--out", "{tmp}/x.png", "--out", "{tmp}/x.png"],
    ["render", "{scene}", "--out", "{tmp}/x.png", "--out", "{scene}"],
    ["nosuchcommand"],
])
def test_bad_input_one_line_exit_2(argv, tmp_path, scene_file, capsys):
    corrupt = tmp_path / "corrupt.json"
    corrupt.write_text('{"format": "relight.scene/v1", "id": ')
    v9 = tmp_path / "v9.json"
    v9.write_text(json.dumps({**json.loads(scene_file.read_text()), "format": "relight.scene/v9"}))
    (tmp_path / "nomeshes").mkdir()
    argv = [a.format(tmp=tmp_path, scene=scene_file, corrupt=corrupt, v9=v9) for a in argv]
    code, err = run(argv, capsys)
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("relight: error:"), err
    assert not (tmp_path / "x.png").exists()


def test_render_writes_png_and_exr(tmp_path, scene_file, capsys, mi):
    from relight.imageio import read_exr
    assert main(["render", str(scene_file), "--out", str(tmp_path / "a.exr")]) == 0
    assert main(["render", str(scene_file), "--out", str(tmp_path / "b.exr"), "--light-pan", "90",
                 "--light-tilt", "45", "--rgb", "1,0.8,0.6"]) == 0
    a, b = read_exr(tmp_path / "a.exr"), read_exr(tmp_path / "b.exr")
    assert a.shape == (16, 16, 3) and (a != b).any()
    assert main(["render", str(scene_file), "--out", str(tmp_path / "c.png")]) == 0
    assert (tmp_path / "c.png").stat().st_size > 0
    # one render, two files: the same image as rendering each alone (same scene, same seed)
    assert main(["render", str(scene_file), "--out", str(tmp_path / "d.exr"), "--out", str(tmp_path / "d.png")]) == 0
    assert np.array_equal(read_exr(tmp_path / "d.exr"), a)
    assert (tmp_path / "d.png").read_bytes() == (tmp_path / "c.png").read_bytes()


def test_help_lists_commands():
    out = subprocess.run([sys.executable, "-m", "relight.cli", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "generate" in out.stdout and "render" in out.stdout


def test_bad_libllvm_is_a_clear_error_not_an_abort(tmp_path, scene_file):
    # Dr.Jit with LLVM 14/15 aborts the whole process at the first kernel; relight must
    # refuse such a library up front with one line and exit 2.
    old = [p for p in ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", "/usr/lib/x86_64-linux-gnu/libLLVM-14.so.1")
           if os.path.exists(p)]
    bad = old[0] if old else str(tmp_path / "libLLVM-15.so")
    if not old:
        (tmp_path / "libLLVM-15.so").write_bytes(b"not a library")
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": bad}
    out = subprocess.run([sys.executable, "-m", "relight.cli", "render", str(scene_file), "--out",
                          str(tmp_path / "x.png")], capture_output=True, text=True, env=env)
    assert out.returncode == 2, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "libLLVM" in out.stderr
