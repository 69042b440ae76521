"""Dask engine (``--scheduler``): same bytes as one process, one writer, faults, bad input."""
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from relight.dataset import read_manifest
from relight.generator.run import generate
from relight.engine import EngineError, parse_scheduler, shards
from relight.generator.sampling import GeneratorConfig

distributed = pytest.importorskip("distributed")

CFG = GeneratorConfig(res=16, spp=2)
SEED = 21
FOLDERS = ("images", "exr", "scenes")


def _same_files(a, b, n):
    for i in range(n):
        for sub, ext in zip(FOLDERS, (".png", ".exr", ".json")):
            name = f"{i:06d}{ext}"
            assert (a / sub / name).read_bytes() == (b / sub / name).read_bytes(), f"{sub}/{name}"


def _records_by_id(folder):
    recs = read_manifest(folder)
    ids = [r["id"] for r in recs]
    assert len(ids) == len(set(ids))
    with open(folder / "manifest.jsonl") as f:   # no duplicate line either (read_manifest merges them)
        assert sum(1 for _ in f) == len(ids)
    return {r["id"]: r for r in recs}


@pytest.fixture(scope="module")
def single(tmp_path_factory, mi):
    out = tmp_path_factory.mktemp("single")
    assert generate(out, 12, seed=SEED, cfg=CFG, progress=False).written == 12
    return out


def test_parse_scheduler():
    assert parse_scheduler("local:3").local == 3
    assert parse_scheduler("tcp://10.0.0.5:8786").address == "tcp://10.0.0.5:8786"
    assert parse_scheduler("node12:8786").address == "node12:8786"
    for bad in ("local:0", "local:x", "local", "tcp://a b:1", "", "local:999", "nan", "tcp://host"):
        with pytest.raises(EngineError):
            parse_scheduler(bad)


# every verb on the engine, with its required arguments (parsed only: no file is read)
ENGINE_VERBS = {
    "generate": ["generate", "--out", "o"],
    "compare": ["compare", "p.json", "--out", "o"],
    "invert": ["invert", "--scene", "s.json", "--image", "i.exr", "--out", "o.json"],
    "evaluate": ["evaluate", "--data", "d", "--out", "o"],
    "baseline": ["baseline", "gray-world", "--data", "d", "--out", "o.json"],
}


@pytest.mark.parametrize("verb", sorted(ENGINE_VERBS))
@pytest.mark.parametrize("bad", ["nonsense", "local:0", "tcp://host"])
def test_every_engine_verb_refuses_a_bad_scheduler_in_one_line(verb, bad, capsys):
    from relight.cli import build_parser
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(ENGINE_VERBS[verb] + ["--scheduler", bad])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and "--scheduler" in err, err


@pytest.mark.parametrize("bad", ["0", "-1", "257", "nan", "2.5"])
def test_bad_workers_is_one_line(bad, capsys):
    from relight.cli import build_parser
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(ENGINE_VERBS["generate"] + ["--workers", bad])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and "--workers" in err, err


def test_scheduler_from_args_reads_the_engine_options():
    from relight.cli import build_parser
    from relight.engine import scheduler_from_args
    from relight.errors import ConfigError

    def scheduler(verb, *extra):
        return scheduler_from_args(build_parser().parse_args(ENGINE_VERBS[verb] + list(extra)))
    two = scheduler("generate", "--workers", "2")
    assert (two.local, two.address) == (2, "")                       # --workers 2 is local:2
    assert scheduler("generate") is None and scheduler("generate", "--workers", "1") is None
    given = scheduler("generate", "--scheduler", "local:3")
    assert (given.local, given.fit_to_work) == (3, False)
    for verb in ENGINE_VERBS:
        assert scheduler(verb) is None
        assert scheduler(verb, "--scheduler", "tcp://node1:8786").address == "tcp://node1:8786"
    with pytest.raises(ConfigError, match="exclude each other"):
        scheduler("generate", "--workers", "2", "--scheduler", "local:2")


def test_workers_start_at_most_one_process_per_item():
    from relight.engine import fit_to_work, for_workers
    assert fit_to_work(for_workers(4), 10).local == 4
    assert fit_to_work(for_workers(4), 3).local == 3
    assert fit_to_work(for_workers(4), 1) is None                # one image: this process renders
    assert fit_to_work(parse_scheduler("local:4"), 1).local == 4  # --scheduler local:N as given
    assert fit_to_work(None, 5) is None
    with pytest.raises(EngineError):
        parse_scheduler("tcp://a:1").__class__(address="tcp://a:1", fit_to_work=True)


def test_the_engine_imports_no_verb():
    """Generic: the verbs pass their task functions in; the engine imports none of them."""
    import ast

    import relight.engine
    tree = ast.parse(open(relight.engine.__file__).read())
    names = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    names |= {f"{n.module}.{a.name}" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module
              for a in n.names}
    names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    ours = {n for n in names if n.startswith("relight")}
    assert ours <= {"relight.errors", "relight.errors.EngineError", "relight.errors.RelightError",
                    "relight.errors.ConfigError", "relight", "relight.backend"}, ours


def test_shards_cover_indices_once_in_order():
    todo = [0, 2, 3, 5, 7, 8, 9, 10, 11, 40, 41]
    for workers in (1, 2, 5, 100):
        parts = shards(todo, workers)
        assert [i for p in parts for i in p] == todo
        assert all(1 <= len(p) <= 8 for p in parts)
    assert len(shards(list(range(100)), 1)) == 13    # at most 8 images a task: ceil(100 / 8)
    assert len(shards(list(range(16)), 2)) == 8      # 4 tasks per worker when there are enough
    assert shards([], 3) == []
    assert shards(list(range(5)), 2, size=2) == [[0, 1], [2, 3], [4]]   # fixed size (evaluate: a batch)


def test_local_cluster_is_byte_identical_and_resumes(tmp_path, single):
    out = tmp_path / "dask"
    stats = generate(out, 5, seed=SEED, cfg=CFG, progress=False, scheduler="local:2")
    assert stats.written == 5 and stats.tasks >= 2
    stats = generate(out, 12, seed=SEED, cfg=CFG, progress=False, scheduler="local:2")
    assert stats.written == 7 and stats.skipped == 5
    _same_files(single, out, 12)
    assert _records_by_id(out) == _records_by_id(single)    # same content, any order
    assert (out / "dataset.json").read_bytes() == (single / "dataset.json").read_bytes()


def test_sigkill_of_a_worker_mid_run_loses_and_duplicates_nothing(tmp_path, single):
    out = tmp_path / "killed"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        pids = list(client.run(os.getpid).values())
        result = {}

        def run():
            try:
                result["stats"] = generate(out, 12, seed=SEED, cfg=CFG, progress=False,
                                           scheduler=cluster.scheduler_address)
            except BaseException as exc:  # noqa: BLE001 - reported by the assertion below
                result["error"] = exc
        t = threading.Thread(target=run)
        t.start()
        manifest = out / "manifest.jsonl"
        deadline = time.time() + 120
        while time.time() < deadline and not (manifest.exists() and manifest.stat().st_size):
            time.sleep(0.02)
        os.kill(pids[0], signal.SIGKILL)   # a worker process dies mid-run
        t.join(300)
    assert "error" not in result, result.get("error")
    assert result["stats"].written == 12
    _same_files(single, out, 12)
    assert _records_by_id(out) == _records_by_id(single)


def _broken(context, shard):
    raise OSError(28, "No space left on device")


def test_a_failing_task_is_one_error_not_a_lost_scheduler():
    import cloudpickle

    from relight import engine
    cloudpickle.register_pickle_by_value(sys.modules[__name__])   # workers cannot import tests/
    try:
        with pytest.raises(EngineError, match="a task failed: OSError.*No space left"):
            engine.map_shards("local:1", _broken, None, [0, 1], lambda part, value: None,
                              engine.ShardPlan(mitsuba=False, progress=False))
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "relight.cli", *args], capture_output=True, text=True,
                          timeout=300)


def test_bad_scheduler_is_one_line_exit_2(tmp_path):
    proc = _cli("generate", "--out", str(tmp_path / "x"), "--count", "1", "--scheduler", "local:0")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1


def test_workers_and_scheduler_exclude_each_other(tmp_path):
    proc = _cli("generate", "--out", str(tmp_path / "x"), "--count", "1", "--workers", "2",
                "--scheduler", "local:2")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_kill_minus_9_of_the_client_takes_its_workers_and_resumes(tmp_path, single):
    out = tmp_path / "client_killed"
    cmd = [sys.executable, "-m", "relight.cli", "generate", "--out", str(out), "--count", "12", "--res", "16",
           "--spp", "2", "--seed", str(SEED), "--scheduler", "local:2", "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    manifest = out / "manifest.jsonl"
    deadline = time.time() + 120
    while time.time() < deadline and not (manifest.exists() and manifest.stat().st_size):
        time.sleep(0.02)
    children = subprocess.run(["ps", "-o", "pid=", "--ppid", str(proc.pid)], capture_output=True,
                              text=True).stdout.split()
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 30
    while time.time() < deadline and any(os.path.exists(f"/proc/{c}") for c in children):
        time.sleep(0.2)
    assert children and not [c for c in children if os.path.exists(f"/proc/{c}")]
    assert subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0
    _same_files(single, out, 12)
    assert _records_by_id(out) == _records_by_id(single)


@pytest.mark.slow
def test_unreachable_scheduler_is_one_line_exit_2(tmp_path):
    proc = _cli("generate", "--out", str(tmp_path / "y"), "--count", "1", "--res", "16", "--spp", "2",
                "--scheduler", "tcp://127.0.0.1:9", "--quiet")
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "scheduler" in proc.stderr
    assert not (tmp_path / "y").exists()   # nothing made: the folder is left as it was


@pytest.mark.slow
def test_lost_scheduler_stops_with_one_line_and_rerun_resumes(tmp_path, single):
    out = tmp_path / "lost"
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", "0",
                              "--no-dashboard", "--scheduler-file", str(tmp_path / "s.json")],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = None
    try:
        deadline = time.time() + 60
        while not (tmp_path / "s.json").exists() and time.time() < deadline:
            time.sleep(0.1)
        import json
        address = json.loads((tmp_path / "s.json").read_text())["address"]
        worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                   "--nthreads", "1", "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        gen = subprocess.Popen([sys.executable, "-m", "relight.cli", "generate", "--out", str(out),
                                "--count", "40", "--res", "16", "--spp", "2", "--seed", str(SEED),
                                "--scheduler", address, "--quiet"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        manifest = out / "manifest.jsonl"
        while time.time() < deadline + 120 and not (manifest.exists() and manifest.stat().st_size):
            time.sleep(0.05)
        sched.kill()
        _, err = gen.communicate(timeout=120)
    finally:
        for p in (sched, worker):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    assert gen.returncode == 2, err
    assert len(err.strip().splitlines()) == 1 and "re-run" in err
    proc = _cli("generate", "--out", str(out), "--count", "12", "--res", "16", "--spp", "2",
                "--seed", str(SEED), "--scheduler", "local:1", "--quiet")
    assert proc.returncode == 0, proc.stderr
    _same_files(single, out, 12)


# --- threads per worker and GPUs -------------------------------------------------------

def test_local_worker_env_gives_each_worker_one_gpu():
    from relight.engine import local_worker_env
    assert local_worker_env(3, ["0", "1"]) == [{"CUDA_VISIBLE_DEVICES": "0"}, {"CUDA_VISIBLE_DEVICES": "1"},
                                               {"CUDA_VISIBLE_DEVICES": "0"}]
    assert local_worker_env(2, []) == [{}, {}]


def test_cuda_devices_follow_cuda_visible_devices(monkeypatch):
    from relight import backend
    for value, expected in (("2,3", ["2", "3"]), ("", []), ("-1", []), ("GPU-5f2e", ["GPU-5f2e"])):
        monkeypatch.setenv("CUDA_VISIBLE_DEVICES", value)
        assert backend.cuda_devices() == expected


def _infos(scheduler, n, **kw):
    from relight import engine
    infos = []
    engine.map_shards(scheduler, engine.worker_info, None, list(range(n)),
                      lambda part, value: infos.append(value), engine.ShardPlan(progress=False, shard_size=1, **kw))
    return infos


def test_local_workers_get_one_gpu_each_and_cores_over_n_threads(monkeypatch):
    """Without a GPU too: the local cluster is built as with two GPUs (each worker sees one
    in CUDA_VISIBLE_DEVICES; Mitsuba then finds none and renders on the CPU)."""
    from relight import backend, engine
    monkeypatch.delenv("RELIGHT_THREADS", raising=False)
    monkeypatch.setattr(backend, "cuda_devices", lambda: ["0", "1"])
    with engine.client("local:2") as (c, threads):
        seen = c.run(os.getenv, "CUDA_VISIBLE_DEVICES")
        assert sorted(seen.values()) == ["0", "1"]
        assert threads == max(1, (os.cpu_count() or 1) // 2)
        infos = []
        engine.run_shards(c, engine.worker_info, None, [[0], [1]], lambda p, r: infos.append(r.value), threads)
    assert {i["threads"] for i in infos} == {threads}


def test_remote_worker_uses_its_dask_threads_unless_told(monkeypatch):
    """On a cluster reached by address, a worker's Dr.Jit thread count is its Dask thread
    count (its cores: ``dask worker --nthreads``); ``threads`` (``--threads``) overrides it."""
    import logging
    monkeypatch.delenv("RELIGHT_THREADS", raising=False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=3, processes=True, dashboard_address=None,
                                  silence_logs=logging.CRITICAL) as cluster:
        assert {i["threads"] for i in _infos(cluster.scheduler_address, 2)} == {3}
        assert {i["threads"] for i in _infos(cluster.scheduler_address, 2, threads=2)} == {2}


def _gpus():
    from relight import backend
    return backend.cuda_devices()


@pytest.mark.skipif(not _gpus(), reason="no CUDA GPU")
def test_gpu_workers_render_on_their_own_gpu_and_match_one_process(tmp_path):
    gpus = _gpus()
    infos = _infos(f"local:{len(gpus)}", 2 * len(gpus))
    assert {i["variant"] for i in infos} == {"cuda_ad_rgb"}
    assert {i["cuda_visible_devices"] for i in infos} <= set(gpus)
    one = tmp_path / "one"
    generate(one, 4, seed=SEED, cfg=CFG, progress=False)   # this process renders on its GPU too
    dask = tmp_path / "dask"
    generate(dask, 4, seed=SEED, cfg=CFG, progress=False, scheduler=f"local:{len(gpus)}")
    _same_files(one, dask, 4)   # on identical GPUs


def _slow_echo(seconds, shard):
    time.sleep(seconds)
    return list(shard)


@pytest.mark.slow
def test_every_shard_value_arrives_once_when_a_worker_is_killed_mid_task():
    """The engine under every verb: a worker SIGKILLed while its tasks run; Dask re-runs
    them elsewhere and the client receives each shard's value exactly once."""
    import cloudpickle

    from relight import engine
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    got, killed = [], []

    def kill(pid):
        os.kill(pid, signal.SIGKILL)
        killed.append(time.monotonic())
    try:
        with engine.client("local:2") as (c, threads):
            pids = list(c.run(os.getpid).values())
            killer = threading.Timer(1.0, kill, (pids[0],))
            killer.start()
            engine.run_shards(c, _slow_echo, 0.4, [[i] for i in range(10)],
                              lambda part, r: got.append((part, r.value, time.monotonic())), threads,
                              mitsuba=False)
            killer.join()
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert killed and killed[0] < got[-1][2]   # the kill came before the last result: mid-run
    assert sorted(p[0] for p, _, _ in got) == list(range(10))
    assert all(p == v for p, v, _ in got)
