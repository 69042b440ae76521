"""Network speed at 128 px on this machine: single-image latency, batched inference
throughput and training images/s, with parameter count and FLOPs per image.

FLOPs come from ``torch.utils.flop_counter`` (a multiply-add counts 2); a training step
is about 3x the forward FLOPs (forward + two backward products). Ratios in the last
table are measured side by side in this run, so they hold even on a busy machine.

    .venv/bin/python benchmarks/bench_network.py [--res 128] [--threads 1 2] [--repeats 20]
"""
from __future__ import annotations

import argparse
import statistics
import time

import torch

from relight.net.loss import light_loss
from relight.net.model import LightNet, NetConfig, count_parameters, flops_per_image


def _timed(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` in seconds after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench(res: int, threads: int, repeats: int, batch: int, train_batch: int) -> dict:
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    net = LightNet(NetConfig(res=res))
    net.eval()
    one = torch.rand(1, 3, res, res)
    many = torch.rand(batch, 3, res, res)
    with torch.no_grad():
        latency_s = _timed(lambda: net(one), repeats)
        batch_s = _timed(lambda: net(many), max(3, repeats // 4))
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
    return {"threads": threads, "latency_ms": 1e3 * latency_s, "infer_img_s": batch / batch_s,
            "train_img_s": train_batch / train_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--batch", type=int, default=64, help="inference batch size")
    ap.add_argument("--train-batch", type=int, default=16, help="training batch size (the paper's 16)")
    args = ap.parse_args()
    net = LightNet(NetConfig(res=args.res))
    params, flops = count_parameters(net), flops_per_image(net)
    print(f"LightNet at {args.res} px: {params:,} parameters, {flops / 1e9:.3f} GFLOP/image forward "
          f"(~{3 * flops / 1e9:.3f} GFLOP/image per training step)")
    rows = [bench(args.res, t, args.repeats, args.batch, args.train_batch) for t in args.threads]
    print(f"\n| threads | latency 1 img (ms) | inference img/s (batch {args.batch}) | training img/s "
          f"(batch {args.train_batch}) | inference GFLOP/s | training GFLOP/s |")
    print("|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['threads']} | {r['latency_ms']:.1f} | {r['infer_img_s']:.1f} | {r['train_img_s']:.1f} | "
              f"{r['infer_img_s'] * flops / 1e9:.1f} | {r['train_img_s'] * 3 * flops / 1e9:.1f} |")
    print("\n| threads | batched / single-image throughput | inference / training img/s |")
    print("|---:|---:|---:|")
    for r in rows:
        print(f"| {r['threads']} | {r['infer_img_s'] * r['latency_ms'] / 1e3:.2f} | "
              f"{r['infer_img_s'] / r['train_img_s']:.2f} |")
    if len(rows) > 1:
        base = rows[0]
        for r in rows[1:]:
            print(f"\n{r['threads']} threads vs {base['threads']}: inference x{r['infer_img_s'] / base['infer_img_s']:.2f}, "
                  f"training x{r['train_img_s'] / base['train_img_s']:.2f}, "
                  f"latency x{base['latency_ms'] / r['latency_ms']:.2f} faster")


if __name__ == "__main__":
    main()
