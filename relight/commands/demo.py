"""``relight demo``: the main job end to end on a small built-in default.

1. render a small SID2-style dataset with Mitsuba 3 (``relight generate``);
2. predict its lights with the shipped network (``relight evaluate``);
3. re-render every scene under the predicted light and write the paper's Figure 3
   panels and tables (``relight compare``).
Re-running resumes the dataset and rewrites the reports.
"""
from __future__ import annotations

import os

from relight.commands import argtypes as at


def add_commands(sub) -> None:
    d = sub.add_parser("demo", help="small end-to-end run: generate, predict, compare",
                       description=__doc__.split("\n\n")[0])
    d.add_argument("--out", default="demo_out", help="output folder (default demo_out)")
    d.add_argument("--count", type=at.count, default=12, help="images to generate (default 12)")
    d.add_argument("--res", type=at.resolution, default=128, help="image size (default 128)")
    d.add_argument("--spp", type=at.spp, default=64, help="samples per pixel (default 64)")
    d.set_defaults(func=cmd_demo)


def cmd_demo(args) -> int:
    from relight.cli import main
    data = os.path.join(args.out, "dataset")
    steps = [
        ["generate", "--count", str(args.count), "--res", str(args.res), "--spp", str(args.spp),
         "--out", data],
        ["evaluate", "--data", data, "--split", "all", "--out", os.path.join(args.out, "evaluation")],
        ["compare", os.path.join(args.out, "evaluation", "predictions.json"), "--data", data,
         "--out", os.path.join(args.out, "compare")],
    ]
    for argv in steps:
        print(f"\n$ relight {' '.join(argv)}", flush=True)
        code = main(argv)
        if code:
            return code
    print(f"\nimages:  {os.path.join(data, 'images')}")
    print(f"tables:  {os.path.join(args.out, 'evaluation')}")
    print(f"figure:  {os.path.join(args.out, 'compare', 'figure3.png')}")
    return 0
