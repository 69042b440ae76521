"""Network speed at 128 px on this machine: single-image latency, batched inference
throughput and training images/s, with parameter count and FLOPs per image.

FLOPs come from ``torch.utils.flop_counter`` (a multiply-add counts 2); a training step
is about 3x the forward FLOPs (forward + two backward products). Ratios in the last
table are measured side by side in this run, so they hold even on a busy machine.

    .venv/bin/python benchmarks/bench_network.py [--res 128] [--threads 1 2] [--repeats 20]
                                                 [--model photo|sid2|FILE|RUN|shipped]

``--model`` times a trained model as ``relight predict`` runs it (``forward_with_kappa``,
eval mode, batch norms folded; a shipped name, or ``shipped``: the default shipped model) instead of a fresh small
network, and prints the folded / unfolded latency ratio measured alternately in the same
run, and the latency of ``--mirror-average`` (:class:`relight.net.model.MirrorAveraged`)
over one image's, timed the same way. The latency columns give the median and the minimum
(an idle core's figure).
"""
from __future__ import annotations

import copy
import statistics
import sys
import time

import torch

from relight.commands import argtypes as at
from relight.net.loss import light_loss
from relight.net.model import LightNet, MirrorAveraged, NetConfig, count_parameters, flops_per_image


def _times(fn, repeats: int) -> list[float]:
    """Wall times of ``fn()`` in seconds after a few warm-up calls."""
    for _ in range(3):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


def _timed(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` in seconds after warm-up calls."""
    return statistics.median(_times(fn, repeats))


def _network(res: int, model: str | None) -> LightNet:
    """A fresh small network, or the model file as training loads it (unfolded)."""
    if model is None:
        torch.manual_seed(0)
        return LightNet(NetConfig(res=res))
    from relight.net.io import load_model_file, resolve_model
    return load_model_file(resolve_model(None if model == "shipped" else model))


def _alternate_ratio(base, other, repeats: int) -> tuple[float, list[float]]:
    """Median time of ``other()`` over ``base()``'s, the two timed alternately (so both see
    the same machine), and ``other``'s times."""
    a, b = [], []
    for _ in range(3):
        base(), other()
    for _ in range(repeats):
        for f, out in ((base, a), (other, b)):
            t0 = time.perf_counter()
            f()
            out.append(time.perf_counter() - t0)
    return statistics.median(b) / statistics.median(a), b


def bench(res: int, threads: int, repeats: int, batch: int, train_batch: int, model: str | None = None) -> dict:
    torch.set_num_threads(threads)
    net = _network(res, model)
    res = net.config.res
    net.eval()
    one = torch.rand(1, 3, res, res)
    many = torch.rand(batch, 3, res, res)
    ratio = mirror_ratio = None
    with torch.no_grad():
        if model is None:
            single = _times(lambda: net.forward_with_kappa(one), repeats)
            batch_s = _timed(lambda: net.forward_with_kappa(many), max(3, repeats // 4))
        else:   # as relight predict runs it: batch norms folded
            folded = copy.deepcopy(net).fold_batchnorm()
            ratio, single = _alternate_ratio(lambda: net.forward_with_kappa(one),
                                             lambda: folded.forward_with_kappa(one), repeats)
            mirrored = MirrorAveraged(folded)
            mirror_ratio, _ = _alternate_ratio(lambda: folded.forward_with_kappa(one),
                                               lambda: mirrored.forward_with_kappa(one), repeats)
            batch_s = _timed(lambda: folded.forward_with_kappa(many), max(3, repeats // 4))
    net.train()
    opt = torch.optim.Adam(net.parameters(), lr=2e-4)
    x = torch.rand(train_batch, 3, res, res)
    y = torch.rand(train_batch, 7) + 0.1

    def step():
        loss = light_loss(net(x), y)
        opt.zero_grad()
        loss.backward()
        opt.step()
    train_s = _timed(step, max(3, repeats // 4))
    return {"threads": threads, "latency_ms": 1e3 * statistics.median(single), "latency_min_ms": 1e3 * min(single),
            "infer_img_s": batch / batch_s, "folded_ratio": ratio,
            "mirror_ratio": mirror_ratio,
            "train_img_s": train_batch / train_s}


def main() -> None:
    ap = at.OneLineParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=at.net_resolution, default=128)
    ap.add_argument("--threads", type=at.threads, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=at.int_in(1, 100_000, "a count"), default=20)
    ap.add_argument("--batch", type=at.batch_size, default=64, help="inference batch size")
    ap.add_argument("--train-batch", type=at.batch_size, default=16, help="training batch size (the paper's 16)")
    at.add_model_option(ap, default_text=False,
                        help="time this model instead of a fresh small network, at its own resolution ('shipped': "
                             "the default shipped model)")
    args = ap.parse_args()
    net = _network(args.res, args.model)
    params, flops = count_parameters(net), flops_per_image(net)
    print(f"{args.model or 'LightNet'} ({net.config.arch}) at {net.config.res} px: {params:,} parameters, {flops / 1e9:.3f} GFLOP/image forward "
          f"(~{3 * flops / 1e9:.3f} GFLOP/image per training step)")
    rows = [bench(args.res, t, args.repeats, args.batch, args.train_batch, args.model) for t in args.threads]
    print(f"\n| threads | latency 1 img, median (ms) | min (ms) | inference img/s (batch {args.batch}) | training img/s "
          f"(batch {args.train_batch}) | inference GFLOP/s | training GFLOP/s |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['threads']} | {r['latency_ms']:.1f} | {r['latency_min_ms']:.1f} | {r['infer_img_s']:.1f} | {r['train_img_s']:.1f} | "
              f"{r['infer_img_s'] * flops / 1e9:.1f} | {r['train_img_s'] * 3 * flops / 1e9:.1f} |")
    print("\n| threads | batched / single-image throughput | inference / training img/s |")
    print("|---:|---:|---:|")
    for r in rows:
        print(f"| {r['threads']} | {r['infer_img_s'] * r['latency_ms'] / 1e3:.2f} | "
              f"{r['infer_img_s'] / r['train_img_s']:.2f} |")
    for r in rows:
        if r["folded_ratio"] is not None:
            print(f"\n{r['threads']} threads: latency with batch norms folded / unfolded = {r['folded_ratio']:.3f} "
                  f"(median, timed alternately)")
            print(f"{r['threads']} threads: latency with --mirror-average / without = {r['mirror_ratio']:.2f} "
                  f"(median, timed alternately; about {r['mirror_ratio'] * r['latency_ms']:.1f} ms)")
    if len(rows) > 1:
        base = rows[0]
        for r in rows[1:]:
            print(f"\n{r['threads']} threads vs {base['threads']}: inference x{r['infer_img_s'] / base['infer_img_s']:.2f}, "
                  f"training x{r['train_img_s'] / base['train_img_s']:.2f}, "
                  f"latency x{base['latency_ms'] / r['latency_ms']:.2f} faster")


if __name__ == "__main__":
    sys.exit(at.run_script(main))
