"""Every quick command of the "Benchmarks" table (docs/results.md, which README's Results
section points to) runs from a fresh clone as printed:
its arguments are valid (each benchmark's ``--check-args``), a bad setting is one line and
exit 2 like the command line, and (``-m slow``) each command runs to the end."""
from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys

import numpy as np
import pytest

from conftest import load_script

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(REPO, "docs", "results.md")   # the benchmark table (README links it)
RUN_TIMEOUT_S = 1800   # a quick command on the shared 2-core machine


def quick_commands() -> list[list[str]]:
    """The argument lists (script first) of the ``| `.venv/bin/python benchmarks/...` |``
    rows of the "Benchmarks" section of docs/results.md."""
    with open(RESULTS, encoding="utf-8") as f:
        text = f.read()
    section = text.split("\n## Benchmarks", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `\.venv/bin/python (benchmarks/[\w.]+\.py[^`]*)` \|", section, re.M)
    return [shlex.split(r) for r in rows]


COMMANDS = quick_commands()


def _env():
    return dict(os.environ, PYTHONPATH=REPO + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _run(argv, timeout=300):
    return subprocess.run([sys.executable, *argv], capture_output=True, text=True, cwd=REPO, env=_env(),
                          timeout=timeout)


def test_results_page_lists_the_benchmarks():
    names = {os.path.basename(c[0]) for c in COMMANDS}
    assert len(COMMANDS) >= 10 and "bench_mid.py" in names, names
    for argv in COMMANDS:
        assert os.path.isfile(os.path.join(REPO, argv[0])), argv[0]


def _run_here(argv, capfd, monkeypatch):
    """Run a benchmark script as ``__main__`` in this process (its heavy imports are shared
    between the cases); returns (exit code, stdout, stderr)."""
    import runpy
    monkeypatch.setattr(sys, "argv", [os.path.join(REPO, argv[0]), *argv[1:]])
    monkeypatch.chdir(REPO)
    try:
        runpy.run_path(os.path.join(REPO, argv[0]), run_name="__main__")
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    out, err = capfd.readouterr()
    return code, out, err


@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: os.path.basename(a[0]))
def test_quick_command_arguments_are_valid(argv, capfd, monkeypatch):
    code, out, err = _run_here(argv + ["--check-args"], capfd, monkeypatch)
    assert code == 0 and "arguments ok" in out, f"docs/results.md row {' '.join(argv)}: {err.strip()}"


def _bad_variants(argv):
    """The command with each numeric value replaced by a bad one (zero where a count must
    be positive is not always bad, so: not a number, and absurdly large)."""
    for i, a in enumerate(argv):
        if i and re.fullmatch(r"[0-9.]+", a) and argv[i - 1].startswith("--"):
            for bad in ("nan", "1e308"):
                yield argv[i - 1], argv[:i] + [bad] + argv[i + 1:]
            return   # the first numeric option of each command is enough; every type is shared


@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: os.path.basename(a[0]))
def test_bad_benchmark_setting_is_one_line(argv, capfd, monkeypatch):
    variants = list(_bad_variants(argv))
    if not variants:
        pytest.skip("no numeric option in this command")
    for option, bad in variants:
        code, _, err = _run_here(bad, capfd, monkeypatch)
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1, err
        assert "error:" in lines[0] and option in lines[0] and "Traceback" not in err


def test_bad_setting_through_a_real_process():
    r = _run(["benchmarks/bench_compare.py", "--count", "0", "--res", "32"])
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--count" in r.stderr


def test_mid_benchmark_refuses_zero_rooms():
    r = _run(["benchmarks/bench_mid.py", "--scenes", "0", "--epochs", "1", "--out", "/nonexistent/mid"])
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--scenes" in r.stderr
    assert not os.path.exists("/nonexistent/mid")


@pytest.mark.parametrize("argv, option", [
    (["--end-to-end", "--batch", "1"], "--batch"),      # no image after the first to time
    (["--end-to-end", "--batch", "nan"], "--batch"),
    (["--end-to-end", "--batch", "1e308"], "--batch"),
    (["--batch", "4"], "--batch"),                      # the batch form is part of --end-to-end
    (["--end-to-end", "--batch", "4", "--repeats", "0"], "--repeats"),
    (["--targets", "0.02,0"], "--targets"),
    (["--targets", "0.02,x"], "--targets"),
])
def test_cycles_batch_setting_is_one_line(argv, option, capfd, monkeypatch):
    code, out, err = _run_here(["benchmarks/bench_cycles.py", *argv], capfd, monkeypatch)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and option in lines[0] and "error:" in lines[0], err
    assert "skipped" not in out   # refused before looking for Blender


@pytest.mark.parametrize("argv, option", [
    (["--refilter-blur", "1.0"], "--refilter-blur"),                # the blur belongs to --refilter
    (["--refilter", "COPY", "--refilter-blur", "-1"], "--refilter-blur"),
    (["--refilter", "COPY", "--refilter-blur", "nan"], "--refilter-blur"),
    (["--refilter", "SET"], "--refilter"),                          # the copy would overwrite the set
    (["--refilter", "COPY"], "--refilter"),                         # a set with no scenes
    (["--cycles-filter", "blackman-harris"], "--cycles-filter"),    # the filter belongs to --make
    (["--make", "2", "--cycles-filter", "gaussian"], "--cycles-filter"),
    (["--res", "256"], "--res"),                                    # how scenes are drawn belongs to --make
    (["--fov", "30"], "--fov"),
    (["--chrome-radius", "15-20"], "--chrome-radius"),
    (["--make", "2", "--fov", "90"], "--fov"),                      # outside the set's 20-60 deg
    (["--make", "2", "--chrome-radius", "20-15"], "--chrome-radius"),
    (["--make", "2", "--res", "128", "--chrome-radius", "15-20"], "--chrome-radius"),   # > 15% of 128 px
])
def test_probe_refilter_setting_is_one_line(argv, option, capfd, monkeypatch, tmp_path):
    folder, copy = tmp_path / "set", tmp_path / "copy"
    folder.mkdir()
    argv = [str(folder) if a == "SET" else str(copy) if a == "COPY" else a for a in argv]
    code, _, err = _run_here(["benchmarks/bench_probe.py", "--set", str(folder), *argv], capfd, monkeypatch)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and option in lines[0] and "error:" in lines[0], err
    assert not copy.exists() and os.listdir(folder) == []


@pytest.mark.parametrize("recorded, argv", [
    ({"res": 256, "fov_deg": 30.0, "chrome_radius_px": [15, 20], "cycles_filter": "blackman-harris"},
     ["--res", "256", "--fov", "30", "--chrome-radius", "15-20"]),          # begun with Blender's filter
    ({"res": 256, "fov_deg": 30.0, "chrome_radius_px": [15, 20], "cycles_filter": "box"},
     ["--res", "256", "--fov", "30"]),                                      # begun with a radius range
    (None, ["--fov", "30"]),                                               # begun before profiles: the default one
])
def test_a_probe_set_is_completed_only_with_the_options_it_was_begun_with(recorded, argv, capfd, monkeypatch,
                                                                           tmp_path):
    folder = tmp_path / "set"
    folder.mkdir()
    if recorded is None:
        (folder / "probe000.json").write_text("{}")
    else:
        (folder / "set_profile.json").write_text(json.dumps(recorded))
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    code, _, err = _run_here(["benchmarks/bench_probe.py", "--set", str(folder), "--make", "1", "--no-psm", *argv],
                             capfd, monkeypatch)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "other options" in lines[0], err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


@pytest.mark.slow
@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: os.path.basename(a[0]))
def test_quick_command_runs(argv, tmp_path):
    """The command as printed (outputs under /tmp or ~/relight-data, as the README says),
    to the end: exit 0, no traceback."""
    r = _run(argv, timeout=RUN_TIMEOUT_S)
    assert r.returncode == 0, f"{' '.join(argv)}: {r.stderr[-2000:]}"
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("n", [20, 60, 61])
def test_a_probe_median_is_judged_by_its_order_statistic_interval(n):
    # the distribution-free interval of a median: the l-th and (n + 1 - l)-th smallest of n,
    # l - 1 the largest count with a binomial (n, 1/2) probability of at most 2.5% of falling
    # at or below it (the closed form), whatever the values and their order
    from scipy import stats
    verdict = load_script("benchmarks/bench_probe.py").median_verdict
    l = max(j for j in range(n) if stats.binom.cdf(j, n, 0.5) <= 0.025) + 1
    errs = np.random.default_rng(n).permutation(np.geomspace(0.1, 20.0, n))
    ordered = np.sort(errs)
    lo, hi = ordered[l - 1], ordered[n - l]
    assert verdict(errs, 0.5 * (lo + hi)) == (lo, hi, "undecided")
    assert verdict(errs, hi)[2] == "met" and verdict(errs, 1.01 * hi)[2] == "met"
    assert verdict(errs, 0.99 * lo)[2] == "not met"


def test_the_probe_report_gives_each_target_row_its_verdict(capsys):
    bench = load_script("benchmarks/bench_probe.py")
    rows = [("cycles png, circle given", "front", e, f"probe{i}.cycles.png")
            for i, e in enumerate([0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 6.0] * 3)]
    bench.report(rows, [])
    line = next(t for t in capsys.readouterr().out.splitlines() if t.startswith("cycles png, circle given"))
    lo, hi, verdict = bench.median_verdict([r[2] for r in rows], 1.0)
    assert verdict == "met" and f"median 95% [{lo:.2f}, {hi:.2f}]: met" in line and "3 over 5" in line


def test_a_found_outline_is_measured_against_the_true_one_through_the_highlight():
    # closed forms: concentric circles differ by their radii in every direction; a centre
    # moved 1 px right puts the outline 1 px out on the right, 1 px in on the left and
    # r - sqrt(r^2 - 1) px out straight up
    rim = load_script("benchmarks/bench_probe.py").rim_error_px
    for toward in ((20.0, 10.0), (10.0, 0.0), (3.0, 17.0)):
        assert rim((10.0, 10.0, 5.0), (10.0, 10.0, 6.0), toward) == pytest.approx(-1.0, abs=1e-12)
    assert rim((11.0, 10.0, 6.0), (10.0, 10.0, 6.0), (20.0, 10.0)) == pytest.approx(1.0, abs=1e-12)
    assert rim((11.0, 10.0, 6.0), (10.0, 10.0, 6.0), (0.0, 10.0)) == pytest.approx(-1.0, abs=1e-12)
    assert rim((11.0, 10.0, 6.0), (10.0, 10.0, 6.0), (11.0, 0.0)) == pytest.approx(6.0 - 35.0 ** 0.5, abs=1e-12)


def test_automatic_failures_are_told_apart_by_the_circle_given_result(capsys):
    bench = load_script("benchmarks/bench_probe.py")
    assert bench.failure_cause(True, 0.5, 5.0) == "detection"
    assert bench.failure_cause(False, 6.0, 5.0) == "highlight"
    assert bench.failure_cause(False, 4.9, 5.0) == "outline"
    name = "cycles png, automatic"
    autos = [(name, "probe1.cycles.png", 21.4, 2.75, -1.02, False),    # outline
             (name, "probe2.cycles.png", 9.0, 7.1, -0.05, False),      # highlight
             (name, "probe3.cycles.png", 119.0, 0.9, float("nan"), True),   # detection
             (name, "probe4.cycles.png", 7.9, 1.0, -0.5, False),       # under the maximum
             ("mitsuba png, automatic", "probe1.mitsuba.png", 50.0, 1.0, 1.0, False)]   # no target: not listed
    bench.report_causes(autos)
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "cycles png, automatic over 8 deg, by cause: outline 1, highlight 1, detection 1 (of 4)"
    assert out[1].split()[:3] == ["probe1.cycles.png", "21.40", "outline"] and "-1.02 px" in out[1]
    assert out[2].split()[:3] == ["probe2.cycles.png", "9.00", "highlight"] and " px" not in out[2]
    assert out[3].split()[:3] == ["probe3.cycles.png", "119.00", "detection"]
    assert len(out) == 4
