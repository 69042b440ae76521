"""``relight demo``: the main job end to end on a small built-in default.

1. render a small SID2-style dataset with Mitsuba 3 (what ``relight generate`` does);
2. predict its lights with the shipped network (``relight evaluate``);
3. re-render every scene under the predicted light and write the paper's Figure 3
   panels and tables (``relight compare``).
It calls the library functions behind those commands.
Re-running resumes the dataset and rewrites the reports.
"""
from __future__ import annotations

__all__ = [
    "add_commands", "cmd_demo",
]

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
    from relight import metrics
    from relight.generator.run import generate
    from relight.fileio import check_folder_target, check_outputs
    from relight.net.evaluate import evaluate
    from relight.net.predict import load_model
    from relight.generator.sampling import GeneratorConfig
    from relight.verify.compare import compare_predictions
    from relight.verify.report import check_out, write_report
    data = os.path.join(args.out, "dataset")
    evaluation = os.path.join(args.out, "evaluation")
    report = os.path.abspath(os.path.join(args.out, "compare"))
    for folder in (evaluation, report):
        check_outputs([folder], [data], replaces_folder=True)
        check_folder_target(folder)
    check_out(report)

    print(f"\n1/3 render {args.count} SID2-style images ({args.res} px, {args.spp} spp) -> {data}", flush=True)
    generate(data, args.count, seed=0, cfg=GeneratorConfig(res=args.res, spp=args.spp))
    print(f"\n2/3 predict their lights with the shipped sid2 network (SID2-style rooms) -> {evaluation}", flush=True)
    tables = evaluate(load_model("sid2"), data, evaluation, split="all", model_name="sid2")
    print(metrics.format_tables(tables, only_table1=True))
    print(f"\n3/3 re-render every scene under its predicted light -> {report}", flush=True)
    predictions = os.path.join(evaluation, "predictions.json")
    comparison = compare_predictions(predictions, data_dir=data)
    write_report(comparison, report, {"command": "demo", "predictions": os.path.abspath(predictions),
                                      "data": os.path.abspath(data), "out": report})
    print(f"\nimages:  {os.path.join(data, 'images')}")
    print(f"tables:  {evaluation}")
    print(f"figure:  {os.path.join(report, 'figure3.png')}  (open {os.path.join(report, 'index.html')})")
    return 0
