"""``relight train``, ``relight evaluate`` and ``relight predict``."""
from __future__ import annotations

import os

from relight.commands.argtypes import camera_tilt, finite_float, positive_int


def _loss_weights(text: str):
    import argparse

    from relight.net.loss import LossWeights
    try:
        pan, tilt, colour = (float(v) for v in text.split(","))
        return LossWeights(pan=pan, tilt=tilt, colour=colour)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three finite numbers >= 0 like 1,1,1, got {text!r}") from None


def add_commands(sub) -> None:
    t = sub.add_parser("train", help="train the light regression network on a dataset (resumable)",
                       description="Train the paper's network (Adam, ReduceLROnPlateau x0.1 on val loss) "
                                   "on the train split of DATA; the val split drives the scheduler.")
    t.add_argument("--data", required=True, help="dataset folder (relight generate output)")
    t.add_argument("--out", required=True, help="run folder (checkpoints, log.csv, curves.png, settings.json)")
    t.add_argument("--epochs", type=positive_int, default=10, help="total epochs (default 10)")
    t.add_argument("--batch-size", type=positive_int, default=16, help="batch size (default 16, the paper's)")
    t.add_argument("--lr", type=finite_float, default=2e-4, help="Adam learning rate (default 2e-4)")
    t.add_argument("--res", type=positive_int, default=128, help="network input size, pixels (default 128)")
    t.add_argument("--seed", type=int, default=0, help="initialisation/shuffle seed (default 0)")
    t.add_argument("--patience", type=int, default=2, help="plateau patience in epochs (default 2)")
    t.add_argument("--no-flip", action="store_true", help="disable horizontal-flip augmentation")
    t.add_argument("--torch-threads", type=positive_int, default=1,
                   help="torch CPU threads (default 1: fastest on a busy 2-core machine)")
    t.add_argument("--workers", type=int, default=0, help="DataLoader workers (default 0, images cached)")
    t.add_argument("--loss-weights", type=_loss_weights, default="1,1,1", metavar="PAN,TILT,COLOUR",
                   help="alpha_1..3 of the paper's loss (colour per radian; default 1,1,1)")
    t.add_argument("--width", type=positive_int, default=32, help="network base width (default 32)")
    t.add_argument("--max-minutes", type=finite_float, default=None,
                   help="stop after the epoch that passes this many minutes (resume later)")
    t.add_argument("--resume", action="store_true", help="continue the run in --out")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_train)

    e = sub.add_parser("evaluate", help="the paper's error tables of a model on a dataset split",
                       description="Evaluate a model (default: the shipped one) on DATA; write report.md "
                                   "(Tables 1-3), metrics.json, per_image.csv, predictions.json to --out.")
    e.add_argument("--model", default=None, help="model .safetensors or run folder (default: shipped model)")
    e.add_argument("--data", required=True, help="dataset folder")
    e.add_argument("--split", default="test", choices=["train", "val", "test", "all"],
                   help="which records (default test; 'all' for a fresh test-only dataset)")
    e.add_argument("--out", required=True, help="report folder")
    e.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("predict", help="predict light direction and colour of images",
                       description="Predict the light of PNG/JPEG (sRGB) or EXR (linear) images of any size.")
    p.add_argument("images", nargs="+", help="image files or folders of images")
    p.add_argument("--camera-tilt", type=camera_tilt, default=None,
                   help="camera tilt in degrees used to decode the light tilt (default 45, the paper's)")
    p.add_argument("--model", default=None, help="model .safetensors or run folder (default: shipped model)")
    p.add_argument("--out", required=True, help="predictions file to write (relight.predictions/v1)")
    p.set_defaults(func=cmd_predict)


def cmd_train(args) -> int:
    from relight.net.train import TrainConfig, train
    cfg = TrainConfig(data_dir=args.data, epochs=args.epochs, batch_size=args.batch_size, lr=float(args.lr),
                      res=args.res, seed=args.seed, flip=not args.no_flip, plateau_patience=args.patience,
                      threads=args.torch_threads, workers=args.workers,
                      max_minutes=args.max_minutes, loss_weights=args.loss_weights, width=args.width)
    row = train(cfg, args.out, resume=args.resume, progress=not args.quiet)
    if row:
        print(f"{args.out}: epoch {row['epoch']}, val loss {row['val_loss']:.4f}, val mean direction "
              f"{row['val_direction_deg']:.2f} deg; weights {os.path.join(args.out, 'best.safetensors')}")
    return 0


def cmd_evaluate(args) -> int:
    import torch

    from relight import metrics
    from relight.net.evaluate import evaluate
    from relight.net.predict import load_model
    torch.set_num_threads(1)
    model = load_model(args.model)
    name = args.model or "shipped model"
    tables = evaluate(model, args.data, args.out, split=args.split, model_name=name)
    print(metrics.format_tables({"overall": tables["overall"], "tilt_levels": tables["tilt_levels"],
                                 "pan_levels": tables["pan_levels"]}).split("**Table 2")[0].rstrip())
    print(f"report: {os.path.join(args.out, 'report.md')}")
    return 0


def cmd_predict(args) -> int:
    from relight.net.predict import DEFAULT_CAMERA_TILT_DEG, list_images, load_model, predict_files
    from relight.predictions import write_predictions
    model = load_model(args.model)
    files = list_images(args.images)
    tilt = DEFAULT_CAMERA_TILT_DEG if args.camera_tilt is None else args.camera_tilt
    preds = predict_files(model, files, tilt)
    print(f"camera tilt assumed: {tilt:g} deg{' (default, as the paper for photographs)' if args.camera_tilt is None else ''}")
    print(f"{'id':<20} {'pan_rel':>8} {'tilt':>7}  {'rgb (unit)':<22} input")
    for p in preds:
        rgb = ",".join(f"{v:.3f}" for v in p["rgb"])
        print(f"{p['id'][:20]:<20} {p['pan_deg']:8.1f} {p['tilt_deg']:7.1f}  {rgb:<22} {p['assumed']}")
    entries = [{"id": p["id"], "pan_deg": p["pan_deg"], "tilt_deg": p["tilt_deg"], "rgb": p["rgb"],
                "y": p["y"], "file": os.path.abspath(p["file"])} for p in preds]
    write_predictions(args.out, entries, model=args.model or "shipped", camera_tilt_deg=tilt)
    print(f"wrote {args.out} ({len(entries)} predictions)")
    return 0
