"""``--scheduler`` for compare, invert, evaluate and baseline: the same bytes as one process.

One tiny dataset (16 px, 4 spp, 4 images) and one LocalCluster of two worker processes
for the module. The library calls run once in this process and once on the cluster and
their results are compared exactly (arrays bit for bit); the command-line runs (``-m
slow``: each verb's report costs 10-20 s on the shared machine) compare every output
file byte for byte. Fields that measure time (seconds) differ between two runs of the
same path too; they are the only ones left out, and only where named.
"""
import csv
import io
import json
import os

import pytest

from relight.cli import main

distributed = pytest.importorskip("distributed")

N, RES, SPP, SEED = 4, 16, 4, 5
TIME_FIELDS = {"seconds", "render_seconds", "seconds_per_image"}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from relight.generator.run import generate
    from relight.generator.sampling import GeneratorConfig
    path = tmp_path_factory.mktemp("engine_verbs") / "ds"
    generate(path, N, seed=SEED, cfg=GeneratorConfig(res=RES, spp=SPP), progress=False)
    return str(path)


@pytest.fixture(scope="module")
def address():
    """A running Dask scheduler with two one-thread worker processes (the ADDRESS form)."""
    import logging
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.CRITICAL) as cluster:
        yield cluster.scheduler_address


def _drop_times(obj):
    if isinstance(obj, dict):
        return {k: _drop_times(v) for k, v in obj.items() if k not in TIME_FIELDS}
    if isinstance(obj, list):
        return [_drop_times(v) for v in obj]
    return obj


def _same_folders(a, b, timed_json=(), timed_csv=()):
    """Same file names, same bytes; ``timed_json`` / ``timed_csv``: files equal once their
    time fields / ``seconds`` column are left out."""
    names = sorted(os.listdir(a))
    assert names == sorted(os.listdir(b))
    for name in names:
        pa, pb = os.path.join(a, name), os.path.join(b, name)
        if os.path.isdir(pa):
            _same_folders(pa, pb, timed_json, timed_csv)
        else:
            _same_file(pa, pb, name in timed_json, name in timed_csv)


def _same_file(pa, pb, timed_json=False, timed_csv=False):
    with open(pa, "rb") as fa, open(pb, "rb") as fb:
        da, db = fa.read(), fb.read()
    if timed_json:
        da, db = (_drop_times(json.loads(d)) for d in (da, db))
    elif timed_csv:
        da, db = ([{k: v for k, v in row.items() if k != "seconds"}
                   for row in csv.DictReader(io.StringIO(d.decode()))] for d in (da, db))
    assert da == db, os.path.basename(pa)


def _run(*argv):
    assert main(list(argv)) == 0


def _twice(tmp_path, name, argv_for, scheduler):
    """Run ``argv_for(path)`` in this process, move its output aside (``one-NAME``), run it
    again on ``scheduler`` into the same path (outputs record their own path); returns
    (single-process output, engine output)."""
    out = tmp_path / name
    _run(*argv_for(out))
    one = tmp_path / f"one-{name}"
    os.rename(out, one)
    trace = tmp_path / (os.path.splitext(name)[0] + ".trace.csv")
    if trace.exists():
        os.rename(trace, tmp_path / f"one-{trace.name}")
    _run(*argv_for(out), "--scheduler", scheduler)
    return one, out


@pytest.fixture(autouse=True)
def _fixed_pdf_dates(monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "0")   # PDF figures carry their creation date


@pytest.fixture(scope="module")
def moved(dataset, tmp_path_factory):
    """Predictions with every light moved (a known error to re-render and to fit from)."""
    from relight.predictions import write_predictions
    from relight.verify.compare import moved_light_predictions
    path = tmp_path_factory.mktemp("engine_verbs_pred") / "pred.json"
    write_predictions(path, moved_light_predictions(dataset, seed=3), dataset=dataset)
    return str(path)


def test_compare_on_the_cluster_gives_the_same_comparison(moved, address):
    import numpy as np

    from relight.verify.compare import compare_predictions
    one = compare_predictions(moved, progress=False)
    dask = compare_predictions(moved, progress=False, scheduler=address)
    assert len(one.items) == N and [it.id for it in dask.items] == [it.id for it in one.items]
    for a, b in zip(one.items, dask.items):
        assert np.array_equal(a.rerender, b.rerender) and np.array_equal(a.original, b.original)
        assert a.row() == b.row()
    assert dask.bad == one.bad


def test_invert_on_the_cluster_gives_the_same_fits(dataset, moved, address, tmp_path):
    from relight.inverse.jobs import dataset_jobs, invert_jobs, write_trace_csv
    from relight.inverse.optimize import InvertConfig
    jobs = dataset_jobs(dataset, "all")[:3]   # three jobs on two workers: one a task, any order
    cfg = InvertConfig(max_iters=2)
    one = invert_jobs(jobs, moved, cfg, progress=False)
    dask = invert_jobs(jobs, moved, cfg, progress=False, scheduler=address)
    assert [job.id for job, _ in dask] == [job.id for job in jobs]   # job order
    assert [_drop_times(r.entry(j.id)) for j, r in dask] == [_drop_times(r.entry(j.id)) for j, r in one]
    write_trace_csv(str(tmp_path / "one.csv"), one)
    write_trace_csv(str(tmp_path / "dask.csv"), dask)
    _same_file(tmp_path / "one.csv", tmp_path / "dask.csv", timed_csv=True)


@pytest.mark.slow
def test_compare_command_on_the_cluster_writes_the_same_report(moved, address, tmp_path):
    one, dask = _twice(tmp_path, "report", lambda out: ["compare", moved, "--out", str(out), "--quiet"],
                       address)
    _same_folders(one, dask, timed_json=("summary.json",))


@pytest.mark.slow
def test_invert_command_on_the_cluster_writes_the_same_predictions(dataset, moved, address, tmp_path):
    one, dask = _twice(tmp_path, "inv.json", lambda out: ["invert", "--data", dataset, "--split", "all",
                                                          "--init", moved, "--max-iters", "2", "--quiet",
                                                          "--out", str(out)], address)
    _same_file(one, dask, timed_json=True)
    _same_file(tmp_path / "one-inv.trace.csv", tmp_path / "inv.trace.csv", timed_csv=True)


@pytest.mark.slow
def test_evaluate_command_on_the_cluster_writes_the_same_report(dataset, address, tmp_path):
    one, dask = _twice(tmp_path, "eval", lambda out: ["evaluate", "--data", dataset, "--split", "all",
                                                      "--out", str(out)], address)
    _same_folders(one, dask)


def test_evaluate_one_task_a_batch_gives_the_same_numbers(dataset, address, tmp_path):
    """Several batches, so several tasks, gathered in order (two images a batch)."""
    import torch

    from relight.net.evaluate import evaluate
    from relight.net.predict import load_model
    torch.set_num_threads(1)
    model = load_model(None)
    evaluate(model, dataset, tmp_path / "eval", split="all", batch_size=2)
    os.rename(tmp_path / "eval", tmp_path / "one")
    evaluate(model, dataset, tmp_path / "eval", split="all", batch_size=2, scheduler=address)
    _same_folders(tmp_path / "one", tmp_path / "eval")


def test_baseline_command_on_local_workers_writes_the_same_predictions(dataset, tmp_path):
    one, dask = _twice(tmp_path, "gray.json", lambda out: ["baseline", "gray-edge", "--data", dataset,
                                                           "--split", "all", "--out", str(out)], "local:1")
    _same_file(one, dask)


def test_bad_input_met_in_a_worker_is_the_same_one_line(dataset, address, tmp_path, capsys):
    """An unreadable image found by a worker: the same one line and exit 2 as one process."""
    import shutil
    broken = tmp_path / "broken"
    shutil.copytree(dataset, broken)
    (broken / "exr" / "000001.exr").write_bytes(b"not an exr")
    lines = []
    for extra in ([], ["--scheduler", address]):
        code = main(["baseline", "gray-world", "--data", str(broken), "--split", "all",
                     "--out", str(tmp_path / "x.json"), *extra])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and not (tmp_path / "x.json").exists()
        lines.append(err[-1])
    assert lines[0] == lines[1] and "000001.exr" in lines[0]
