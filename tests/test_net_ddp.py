"""``torchrun --nproc-per-node 2 -m relight train``: DDP on CPU (gloo), rank 0 writes, resume."""
import csv
import os
import shutil
import subprocess
import sys

import pytest
import torch

from relight.net.train import distributed_rank_world

RES = 16
TORCHRUN_TIMEOUT_S = 180


@pytest.fixture(scope="module")
def tiny(tmp_path_factory, mi):
    from relight.generator.run import generate
    from relight.generator.sampling import GeneratorConfig
    root = tmp_path_factory.mktemp("ddp_data")
    generate(root, count=12, seed=5, cfg=GeneratorConfig(res=RES, spp=2), progress=False)
    return str(root)


def _train_cmd(nproc, data, out, epochs):
    torchrun = [sys.executable, "-m", "torch.distributed.run", "--nproc-per-node", str(nproc),
                "--standalone", "-m", "relight"] if nproc else [sys.executable, "-m", "relight"]
    return torchrun + ["train", "--data", data, "--out", str(out), "--epochs", str(epochs), "--res", str(RES),
                       "--width", "4", "--batch-size", "2", "--quiet"]


def _run(cmd):
    """Run torchrun in its own process group; on a time-out the whole group (torchrun
    and its ranks) is killed, so no rank outlives the test."""
    import signal
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=TORCHRUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def _log(out):
    with open(os.path.join(out, "log.csv")) as f:
        return list(csv.DictReader(f))


def test_rank_world_from_environment(monkeypatch):
    monkeypatch.delenv("WORLD_SIZE", raising=False)
    assert distributed_rank_world() == (0, 1)
    monkeypatch.setenv("WORLD_SIZE", "1")
    assert distributed_rank_world() == (0, 1)
    monkeypatch.setenv("WORLD_SIZE", "4")
    monkeypatch.setenv("RANK", "3")
    assert distributed_rank_world() == (3, 4)


@pytest.mark.slow
def test_two_cpu_processes_train_write_once_and_resume(tmp_path, tiny):
    from relight.dataset import read_manifest
    from relight.net.data import split_records
    out = tmp_path / "run"
    proc = _run(_train_cmd(2, tiny, out, 1))
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = _log(out)
    n_train = len(split_records(read_manifest(tiny), "train"))
    # both shares are counted (a DistributedSampler pads each to ceil(n / 2))
    assert len(rows) == 1 and int(rows[0]["n_train"]) == 2 * -(-n_train // 2)
    names = sorted(os.listdir(out))
    assert "checkpoint.pt" in names and "best.safetensors" in names
    assert not [n for n in names if ".relight-tmp-" in n]    # no left-over temporaries
    # resume to 2 epochs: continues from the checkpoint (one more row)
    proc = _run(_train_cmd(2, tiny, out, 2) + ["--resume"])
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows2 = _log(out)
    assert [r["epoch"] for r in rows2] == ["1", "2"] and rows2[0] == rows[0]
    state = torch.load(out / "checkpoint.pt", weights_only=True)
    assert state["epoch"] == 2


@pytest.mark.slow
def test_one_process_under_torchrun_equals_plain_path(tmp_path, tiny):
    a, b = tmp_path / "plain", tmp_path / "torchrun"
    assert _run(_train_cmd(0, tiny, a, 1)).returncode == 0
    proc = _run(_train_cmd(1, tiny, b, 1))
    assert proc.returncode == 0, proc.stderr[-2000:]
    sa = torch.load(a / "checkpoint.pt", weights_only=True)["model"]
    sb = torch.load(b / "checkpoint.pt", weights_only=True)["model"]
    assert sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)
    shutil.rmtree(a), shutil.rmtree(b)
