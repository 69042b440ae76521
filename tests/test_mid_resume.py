"""``generate --preset mid`` killed and resumed: a SIGKILL mid-run, then the same
command again, gives the dataset of an uninterrupted run; a second writer is refused."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = {"res": 32, "spp": 4, "probe_spp": 4, "cube_res": 8, "cube_spp": 4, "directions": [0, 4],
        "n_clutter": [1, 2]}
COUNT, SEED = 3, 5
TRUTH = ("light", "physical", "procedure")


def _argv(out, cfg) -> list[str]:
    return [sys.executable, "-m", "relight", "generate", "--preset", "mid", "--count", str(COUNT),
            "--seed", str(SEED), "--out", str(out), "--config", str(cfg), "--quiet"]


def _env() -> dict:
    return dict(os.environ, RELIGHT_THREADS="1")


def _run(out, cfg, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run(_argv(out, cfg), capture_output=True, text=True, timeout=timeout, env=_env(), cwd=REPO)


def _manifest_lines(out) -> list[dict]:
    """Every manifest line as written (no de-duplication, unlike ``read_manifest``)."""
    data = (out / "manifest.jsonl").read_bytes()
    assert data.endswith(b"\n"), "partial last line left in the manifest"
    return [json.loads(line) for line in data.splitlines()]


def _check_complete(out) -> list[dict]:
    """The finished dataset's invariants; returns its records."""
    from relight.fileio import is_temp_name
    from relight.imageio import read_exr, read_srgb8
    records = _manifest_lines(out)
    ids = [r["id"] for r in records]
    assert len(ids) == len(set(ids)), f"repeated ids: {sorted(i for i in ids if ids.count(i) > 1)}"
    expected = []
    for i in range(COUNT):
        doc = json.loads((out / "scenes" / f"{i:04d}.json").read_text())
        wanted = {f"{i:04d}_{k:02d}" for k in TINY["directions"]}
        failed = set(doc["procedure_failed"])
        assert set(doc["records"]) | failed == wanted and not set(doc["records"]) & failed
        expected += doc["records"]
    assert sorted(ids) == sorted(expected)          # one record per (scene, direction) the procedure measured
    for rec in records:
        for key, shape in (("image", (32, 32, 3)), ("image_masked", (32, 32, 3))):
            assert read_srgb8(out / rec[key])[0].shape == shape
        exr = read_exr(out / rec["exr"])
        assert exr.shape[:2] == (32, 32) and np.isfinite(exr).all()
    temps = [os.path.join(d, n) for d, _, names in os.walk(out) for n in names if is_temp_name(n)]
    assert not temps, temps
    return records


def test_killed_run_resumes_to_the_uninterrupted_dataset(tmp_path):
    cfg = tmp_path / "tiny.json"
    cfg.write_text(json.dumps(TINY))
    out = tmp_path / "killed"
    first = out / "scenes" / "0000.json"
    last = out / "scenes" / f"{COUNT - 1:04d}.json"
    proc = subprocess.Popen(_argv(out, cfg), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_env(),
                            cwd=REPO, start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        while not first.exists():
            assert proc.poll() is None, f"generate ended before its first scene: {proc.stderr.read()}"
            assert time.monotonic() < deadline, "no scene finished in 300 s"
            time.sleep(0.01)
        # let the second scene get under way (some of its files written), then kill the whole group
        second = out / "exr" / "0001_ref.exr"
        while not second.exists() and not (out / "scenes" / "0001.json").exists() and proc.poll() is None:
            time.sleep(0.01)
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        proc.stderr.close()
    assert not last.exists(), "the kill landed after the last scene: nothing was interrupted"
    assert proc.returncode == -signal.SIGKILL
    killed_ids = [r["id"] for r in _manifest_lines(out)] if (out / "manifest.jsonl").exists() else []
    assert len(killed_ids) <= len(TINY["directions"]) * (COUNT - 1)
    finished = len(os.listdir(out / "scenes"))
    assert 1 <= finished < COUNT

    r = _run(out, cfg)
    assert r.returncode == 0, r.stderr
    assert f"{COUNT - finished} rooms written" in r.stdout and f"{finished} already there" in r.stdout
    resumed = _check_complete(out)

    ref = tmp_path / "uninterrupted"
    r = _run(ref, cfg)
    assert r.returncode == 0, r.stderr
    whole = _check_complete(ref)
    assert {x["id"]: {k: x[k] for k in TRUTH} for x in resumed} == {x["id"]: {k: x[k] for k in TRUTH} for x in whole}


def _snapshot(folder) -> dict:
    out = {}
    for d, _, names in os.walk(folder):
        for n in names:
            p = os.path.join(d, n)
            st = os.stat(p)
            with open(p, "rb") as f:
                out[os.path.relpath(p, folder)] = (f.read(), st.st_mtime_ns)
    return out


def test_second_writer_is_refused(tmp_path):
    from relight.fileio import FolderLock
    cfg = tmp_path / "tiny.json"
    cfg.write_text(json.dumps(TINY))
    out = tmp_path / "held"
    lock = FolderLock.take(out, "dataset")[0]      # as generate_mid takes it
    try:
        (out / "manifest.jsonl").write_bytes(b"")
        before = _snapshot(out)
        r = _run(out, cfg, timeout=120)
        assert r.returncode == 2, (r.returncode, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "another relight process" in lines[0] and str(os.getpid()) in lines[0]
        assert _snapshot(out) == before
    finally:
        lock.release()


def test_other_settings_are_named_when_resume_is_refused(tmp_path):
    import pytest

    from relight.errors import DatasetError
    from relight.experiments.mid.dataset import MidConfig, _write_card
    _write_card(str(tmp_path), 5, MidConfig(), 2, 0)
    _write_card(str(tmp_path), 5, MidConfig(), 2, 1)          # same settings: fine
    card = (tmp_path / "dataset.json").read_bytes()
    with pytest.raises(DatasetError, match=r"other settings \(seed 5 there, 6 here\)"):
        _write_card(str(tmp_path), 6, MidConfig(), 2, 1)
    assert (tmp_path / "dataset.json").read_bytes() == card
