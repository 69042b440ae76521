"""The two encoders side by side: parameters, FLOPs, model-file size, single-image CPU
latency (1 and 2 torch threads) and training images/s, at 128 px.

Both networks are timed in alternation within one run (the machine is shared, so the
absolute milliseconds move with its load; the paper / small ratios hold). The minimum
is the latency of an idle core; the median includes the load of the moment.

    .venv/bin/python benchmarks/bench_arch.py [--threads 1 2] [--repeats 60]

With ``--data DIR`` it then trains both encoders for the same wall time (``--minutes``,
same data, seed and settings) and scores each on a test set (``--test DIR``, all of it;
default: DIR's val split): the equal-time accuracy comparison that chooses the shipped
encoder. Runs go to ``--out`` and resume like ``relight train``.

With ``--runs RUN_A RUN_B`` it compares two runs trained side by side (same data, one
thread each, started together, e.g. ``relight train --arch small`` and ``--arch paper``):
from their ``log.csv``, the val errors each had reached at equal cumulative training
time (every epoch end of either run), and the better one at the last common time.
"""
from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time

import torch

from relight.commands import argtypes as at
from relight.net.io import save_model
from relight.net.loss import light_loss
from relight.net.model import ARCHES, LightNet, NetConfig, count_parameters, flops_per_image

RES = 128


def _latency_s(nets: dict, threads: int, repeats: int) -> dict:
    """Per-network list of single-image forward times, measured in alternation."""
    torch.set_num_threads(threads)
    one = torch.rand(1, 3, RES, RES)
    times = {k: [] for k in nets}
    with torch.no_grad():
        for net in nets.values():
            for _ in range(5):
                net.forward_with_kappa(one)
        for _ in range(repeats):
            for k, net in nets.items():
                t0 = time.perf_counter()
                net.forward_with_kappa(one)
                times[k].append(time.perf_counter() - t0)
    return times


def _train_img_s(net: LightNet, threads: int, steps: int, batch: int = 16) -> float:
    torch.set_num_threads(threads)
    net.train()
    opt = torch.optim.Adam(net.parameters(), lr=2e-4)
    x, y = torch.rand(batch, 3, RES, RES), torch.rand(batch, 7) + 0.1
    times = []
    for _ in range(steps + 1):
        t0 = time.perf_counter()
        loss = light_loss(net(x), y)
        opt.zero_grad()
        loss.backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    net.eval()
    return batch / statistics.median(times[1:])


def equal_time(data: str, test: str | None, minutes: float, res: int, out: str) -> None:
    """Train each encoder for ``minutes`` of wall time and print its test errors."""
    from relight.net.evaluate import evaluate
    from relight.net.predict import load_model
    from relight.net.train import TrainConfig, train
    print(f"\n## equal training time: {minutes:g} min each, {res} px, data {data}")
    print("| arch | epochs | val loss | test n | direction mean / median | colour mean / median |")
    print("|---|---:|---:|---:|---|---|")
    for arch in ARCHES:
        run = os.path.join(out, f"{arch}-{res}px-{minutes:g}min")
        row = train(TrainConfig(data_dir=data, epochs=1000, res=res, arch=arch, max_minutes=minutes),
                    run, resume=os.path.isdir(run), progress=False) or {}
        split = "all" if test else "val"
        tables = evaluate(load_model(run), test or data, os.path.join(run, "eval"), split=split,
                          model_name=arch)
        o = tables["overall"]
        print(f"| {arch} | {row.get('epoch', '-')} | {row.get('val_loss', float('nan')):.4f} | {o['direction']['n']} | "
              f"{o['direction']['mean']:.2f} / {o['direction']['median']:.2f} | "
              f"{o['colour']['mean']:.2f} / {o['colour']['median']:.2f} |")


def read_log(run: str) -> list[dict]:
    """A run's ``log.csv`` rows with ``minutes``: cumulative training wall time at the
    end of each epoch (epoch time summed; a resumed run's rows continue the sum)."""
    import csv
    path = os.path.join(run, "log.csv")
    if not os.path.isfile(path):
        raise SystemExit(f"{path}: no training log (is {run} a relight train run folder?)")
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r.get("epoch_time_s")]
    total = 0.0
    for r in rows:
        total += float(r["epoch_time_s"]) / 60.0
        r["minutes"] = total
    return rows


def at_time(rows: list[dict], minutes: float) -> dict | None:
    """The last row finished by ``minutes`` of training (None before the first).

    >>> at_time([{"minutes": 30.0, "e": 1}, {"minutes": 61.0, "e": 2}], 60.0)["e"]
    1
    """
    done = [r for r in rows if r["minutes"] <= minutes + 1e-9]
    return done[-1] if done else None


def compare_runs(runs: list[str]) -> None:
    """Print the val errors of two side-by-side runs at equal cumulative training time."""
    logs = {os.path.basename(os.path.normpath(r)): read_log(r) for r in runs}
    names = list(logs)
    times = sorted({r["minutes"] for rows in logs.values() for r in rows})
    common = min(rows[-1]["minutes"] if rows else 0.0 for rows in logs.values())
    print("\n## equal training time (val split; each run's last finished epoch at that time)")
    print("| minutes | " + " | ".join(f"{n}: epoch, direction, colour" for n in names) + " |")
    print("|---:|" + "---|" * len(names))
    for t in (t for t in times if t <= common + 1e-9):
        cells = []
        for n in names:
            r = at_time(logs[n], t)
            cells.append("-" if r is None else f"{r['epoch']}, {float(r['val_direction_deg']):.2f}, "
                                               f"{float(r['val_colour_deg']):.2f}")
        print(f"| {t:.1f} | " + " | ".join(cells) + " |")
    last = {n: at_time(logs[n], common) for n in names}
    if all(last.values()):
        score = {n: float(r["val_loss"]) for n, r in last.items()}
        print(f"\nat {common:.1f} min, lowest val loss: {min(score, key=score.get)} ("
              + ", ".join(f"{n} {v:.4f}" for n, v in score.items()) + ")")


def main() -> None:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=at.threads, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=at.int_in(1, 100_000, "a count"), default=60)
    ap.add_argument("--train-steps", type=at.int_in(1, 100_000, "a count"), default=5)
    ap.add_argument("--data", default=None, help="dataset: also compare accuracy at equal training time")
    ap.add_argument("--test", default=None, help="test dataset (default: --data's val split)")
    ap.add_argument("--minutes", type=at.minutes, default=60.0, help="training minutes per encoder")
    ap.add_argument("--res", type=at.net_resolution, default=RES, help="training image size")
    ap.add_argument("--out", default=os.path.expanduser("~/relight-data/arch-eqtime"),
                    help="folder of the training runs")
    ap.add_argument("--runs", nargs=2, metavar="RUN", default=None,
                    help="compare two existing runs at equal training time from their logs (no timing)")
    args = ap.parse_args()
    if args.runs:
        compare_runs(args.runs)
        return
    torch.manual_seed(0)
    nets = {arch: LightNet(NetConfig.for_arch(arch, res=RES)).eval() for arch in ARCHES}
    print(f"| arch | name | parameters | GFLOP / image | model file (MB) |")
    print("|---|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for arch, net in nets.items():
            path = os.path.join(tmp, f"{arch}.safetensors")
            save_model(path, net)
            print(f"| {arch} | {net.config.arch_name} | {count_parameters(net):,} | "
                  f"{flops_per_image(net) / 1e9:.3f} | {os.path.getsize(path) / 1e6:.1f} |")
    print("\n| threads | arch | latency min (ms) | latency median (ms) | training img/s (batch 16) |")
    print("|---:|---|---:|---:|---:|")
    ratios = []
    for th in args.threads:
        times = _latency_s(nets, th, args.repeats)
        train = {k: _train_img_s(n, th, args.train_steps) for k, n in nets.items()}
        for k in nets:
            print(f"| {th} | {k} | {1e3 * min(times[k]):.1f} | {1e3 * statistics.median(times[k]):.1f} | "
                  f"{train[k]:.1f} |")
        ratios.append((th, statistics.median(times["paper"]) / statistics.median(times["small"]),
                       train["small"] / train["paper"]))
    print("\n| threads | paper / small latency (median) | small / paper training img/s |")
    print("|---:|---:|---:|")
    for th, lat, tr in ratios:
        print(f"| {th} | {lat:.2f} | {tr:.2f} |")
    if args.data:
        equal_time(args.data, args.test, args.minutes, args.res, args.out)


if __name__ == "__main__":
    sys.exit(at.run_script(main))
