"""The stage timer (relight.timing) in the generator: every stage of every image is timed,
the stages add up to the wall time, Dr.Jit's kernel history lands in the kernel stage,
and timing or running the stages one after the other changes no byte of the dataset."""
from __future__ import annotations

import os

import pytest

from relight import timing
from relight.errors import DatasetError
from relight.generator.run import generate
from relight.generator.sampling import GeneratorConfig

CFG = GeneratorConfig(res=24, spp=2)
N_IMAGES = 3
STAGE_SUM_TOL = 0.05   # the stages of a one-thread run add up to the wall time within 5%

# what every image goes through (the template load happens once per structure)
IMAGE_STAGES = ("scene sampling", "meshes", "textures", "template: parameters",
                "template: update + acceleration structure", "render: tracing + launch", "render: kernel",
                "render: readback", "write: scene JSON", "write: EXR", "write: PNG", "write: manifest append")


def _files(folder) -> dict[str, bytes]:
    out = {}
    for sub in ("images", "exr", "scenes"):
        for name in sorted(os.listdir(folder / sub)):
            out[f"{sub}/{name}"] = (folder / sub / name).read_bytes()
    out["manifest.jsonl"] = (folder / "manifest.jsonl").read_bytes()
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory, mi):
    from relight import backend
    base = tmp_path_factory.mktemp("timing")
    generate(base / "warm", 2, seed=5, cfg=CFG, progress=False)   # kernels compiled once
    out = {}
    for name, overlap, timed in (("serial", False, True), ("pipeline", True, True), ("plain", True, False)):
        timer = timing.StageTimer(drjit=backend.drjit(), kernels=True) if timed else None
        stats = generate(base / name, N_IMAGES, seed=9, cfg=CFG, progress=False, timer=timer, overlap=overlap)
        if timer is not None:
            timer.close()
        out[name] = (base / name, stats, timer)
    return out


def test_every_image_has_every_stage(runs):
    _, stats, timer = runs["serial"]
    assert stats.written == N_IMAGES and timer.images() == list(range(N_IMAGES))
    for image in timer.images():
        stages = timer.per_image(image)
        missing = [s for s in IMAGE_STAGES if s not in stages]
        assert not missing, f"image {image}: no {missing}"
        assert all(v >= 0 for v in stages.values())
    assert "template: load (new structure)" in timer.per_image(0)   # a new builder loads one


def test_stages_add_up_to_the_wall_time(runs):
    _, stats, timer = runs["serial"]
    counted = timer.total()
    assert counted <= stats.total_s * (1 + 1e-6)   # one thread: no second is counted twice
    assert abs(stats.total_s - counted) <= STAGE_SUM_TOL * stats.total_s, (counted, stats.total_s)


def test_pipeline_render_thread_never_counts_past_the_wall(runs):
    _, stats, timer = runs["pipeline"]
    assert len(timer.threads()) == 3   # prepare, render (main) and write threads
    assert timer.total(thread="MainThread") <= stats.total_s * (1 + 1e-6)
    assert timer.total("scene sampling", thread="MainThread") == 0.0   # done on the helper thread
    assert timer.total("scene sampling") > 0.0


def test_kernel_history_lands_in_the_kernel_stage(runs):
    from relight import backend
    dr = backend.drjit()
    _, _, timer = runs["serial"]
    for image in timer.images():
        k = timer.kernel[(image, "render: kernel")]
        assert k.jit_kernels >= 1 and k.largest_ms > 0.0
        # the path-tracing kernel ran inside the stage that waited for it
        assert k.largest_ms / 1000.0 <= timer.per_image(image)["render: kernel"] + timer.per_image(image)[
            "render: tracing + launch"] + 1e-3
    assert not dr.flag(dr.JitFlag.KernelHistory)   # close() restored the flag


def test_timing_and_order_change_no_byte(runs):
    plain = _files(runs["plain"][0])
    assert len(plain) == 3 * N_IMAGES + 1
    for name in ("serial", "pipeline"):
        assert _files(runs[name][0]) == plain, name


def test_nested_stages_count_once(monkeypatch):
    clock = iter(range(100))   # each clock read is 1 s later
    monkeypatch.setattr(timing.time, "perf_counter", lambda: float(next(clock)))
    t = timing.StageTimer()
    with t.image(7):
        with t.stage("outer"):          # reads 0 ... 3: 3 s, of which inner 1 s
            with t.stage("inner"):      # reads 1, 2
                pass
    assert t.per_image(7) == {"outer": 2.0, "inner": 1.0}
    assert t.total() == 3.0


def test_no_timer_is_one_shared_empty_context():
    assert timing.NO_TIMER.stage("a") is timing.NO_TIMER.stage("b", sync=True) is timing.NO_TIMER.image(3)


def test_timer_refuses_several_processes(tmp_path):
    with pytest.raises(DatasetError, match="one process"):
        generate(tmp_path / "d", 2, cfg=CFG, progress=False, workers=2, timer=timing.StageTimer())
    assert not (tmp_path / "d").exists()
