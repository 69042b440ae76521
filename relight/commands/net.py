"""``relight train``, ``relight calibrate``, ``relight evaluate`` and ``relight predict``."""
from __future__ import annotations

__all__ = [
    "add_commands", "cmd_train", "cmd_calibrate", "cmd_evaluate", "cmd_predict",
]

import os

from relight import engine
from relight.commands import argtypes as at
from relight.commands.argtypes import camera_tilt


def add_commands(sub) -> None:
    t = sub.add_parser("train", help="train the light regression network on a dataset (resumable)",
                       description="Train the paper's network (Adam, ReduceLROnPlateau x0.1 on val loss) "
                                   "on the train split of DATA; the val split drives the scheduler.")
    t.add_argument("--data", required=True, action="append",
                   help="dataset folder (relight generate output); repeat it to train on several "
                        "folders together (their train and val splits are joined)")
    t.add_argument("--out", required=True, help="run folder (checkpoints, log.csv, curves.png, settings.json)")
    t.add_argument("--epochs", type=at.epochs, default=10, help="total epochs (default 10)")
    t.add_argument("--batch-size", type=at.batch_size, default=16, help="batch size (default 16, the paper's)")
    t.add_argument("--lr", type=at.learning_rate, default=2e-4, help="Adam learning rate (default 2e-4)")
    t.add_argument("--res", type=at.net_resolution, default=128, help="network input size, pixels (default 128)")
    t.add_argument("--seed", type=at.seed, default=0, help="initialisation/shuffle seed (default 0)")
    t.add_argument("--patience", type=at.patience, default=2, help="plateau patience in epochs (default 2)")
    t.add_argument("--no-flip", action="store_true", help="disable horizontal-flip augmentation")
    t.add_argument("--torch-threads", type=at.threads, default=1,
                   help="torch CPU threads (default 1: fastest on a busy 2-core machine)")
    t.add_argument("--workers", type=at.loader_workers, default=0, help="DataLoader workers (default 0, images cached)")
    t.add_argument("--loss-weights", type=at.loss_weights, default="1,1,1", metavar="PAN,TILT,COLOUR",
                   help="alpha_1..3 of the paper's loss (colour per radian; default 1,1,1)")
    t.add_argument("--width", type=at.width, default=32, help="network base width (default 32)")
    t.add_argument("--arch", choices=["small", "paper"], default="small",
                   help="encoder: small (0.5 M parameters, CPU-sized) or paper (6.7 M, the paper's five "
                        "modules at Inception-v3 proportions); recorded in the model file (default small)")
    t.add_argument("--kappa-weight", type=at.float_in(0.0, 1e6, "a weight"), default=1.0,
                   help="weight of the direction von Mises-Fisher NLL that trains the confidence (kappa) "
                        "head; 0: no kappa head (default 1; it does not change the paper's terms)")
    t.add_argument("--kappa-into-features", action="store_true",
                   help="let the kappa NLL train the shared encoder too (default: the kappa head reads "
                        "the embedding detached, so the paper's terms alone train the encoder)")
    t.add_argument("--epoch-images", type=at.count, default=None, metavar="N",
                   help="images per epoch (default: the whole train split); on a large set a shorter "
                        "epoch validates, checkpoints and steps the scheduler more often, and every "
                        "image is still seen once before any twice")
    t.add_argument("--max-minutes", type=at.minutes, default=None,
                   help="stop after the epoch that passes this many minutes (resume later)")
    t.add_argument("--resume", action="store_true",
                   help="continue the run in --out with changed settings (e.g. more --epochs); "
                        "re-running the identical command resumes without it")
    at.add_model_option(t, "--init", default_text=False,
                        help="the model to fine-tune (e.g. sid2): its network and "
                             "weights are the starting point (--arch/--width ignored, --res must match); it may "
                             "not lie in --out, whose best.safetensors the run replaces (copy it out first)")
    t.add_argument("--images", choices=["visible", "masked"], default="visible",
                   help="MID-like datasets: train on the images as rendered (visible spheres) or on the "
                        "copies with both spheres painted out (default visible)")
    t.add_argument("--camera-weight", type=at.float_in(0.0, 1e6, "a weight"), default=0.0,
                   help="> 0 adds a camera-tilt head trained with this loss weight, so that predictions on "
                        "photographs need no assumed camera tilt (default 0: no head; docs/photo.md)")
    t.add_argument("--source", choices=["image", "exr"], default="image",
                   help="train on the dataset's 8-bit PNGs (default) or on its linear EXRs (see --augment)")
    from relight.net.augment import AUGMENTS
    t.add_argument("--augment", choices=list(AUGMENTS), default="none",
                   help="camera-pipeline augmentation of --source exr at training time: photo = exposure "
                        "+-2 EV, sensor noise, vignetting, blur, sRGB/gamma/filmic tone curves, JPEG 40-100; "
                        "photo-linear = the same with a linear (no) tone curve drawn too, as machine-vision "
                        "cameras store images; photo-glare = photo with veiling glare on half the images; "
                        "photo-srgb = photo with the sRGB curve only "
                        "(default none: as the PNGs are written; relight/net/augment.py)")
    t.add_argument("--surround", choices=["keep", "black"], default="keep",
                   help="black: train on the objects alone, everything outside the record's object mask set "
                        "to black before the camera pipeline (needs --source exr and a dataset generated with "
                        "\"object_masks\": true; default keep)")
    t.add_argument("--target-frame", choices=["world", "camera"], default="world",
                   help="what the network learns: world = the paper's 7-vector, the light relative to the "
                        "camera in the world's angles (default); camera = the light in the camera frame "
                        "(the paper's encoding for a level camera), turned into the world with the camera "
                        "tilt when decoded; recorded in the model file (docs/photo.md)")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_train)

    c = sub.add_parser("calibrate", help="fit the direction-confidence (kappa) head on a held-out split",
                       description="Refit the kappa head of a trained model on the direction errors of a "
                                   "held-out split (network frozen; vMF negative log-likelihood, early "
                                   "stopping and temperature on a part of the split kept out of the fit) "
                                   "and write the calibrated model file.")
    at.add_model_option(c, "--model", "--run", dest="model", required=True, help="the model whose kappa head is refitted")
    c.add_argument("--data", required=True, action="append",
                   help="dataset folder; repeat it for a model trained on several (their splits are joined)")
    c.add_argument("--split", default="val", choices=["train", "val", "test", "all"],
                   help="held-out split to fit on (default val; never the split you report on)")
    c.add_argument("--mode", default="head", choices=["head", "last", "temperature", "none"],
                   help="refit the whole kappa head (default), only its last layer, only a temperature, or "
                        "nothing (none: with --ood, only the out-of-distribution detector is fitted)")
    c.add_argument("--out", required=True, help="calibrated model file to write (.safetensors)")
    c.add_argument("--ood", action="store_true",
                   help="also fit the out-of-distribution detector on the split (predictions then carry "
                        "ood / ood_score; flagged images get a 180-degree cone; relight/net/ood.py)")
    c.set_defaults(func=cmd_calibrate)

    e = sub.add_parser("evaluate", help="the paper's error tables of a model on a dataset split",
                       description="Evaluate a model (default: the shipped photo model, else sid2) on DATA; "
                                   "write report.md "
                                   "(Tables 1-3), metrics.json, per_image.csv, predictions.json to --out.")
    at.add_model_option(e)
    e.add_argument("--data", required=True, help="dataset folder")
    e.add_argument("--split", default="test", choices=["train", "val", "test", "all"],
                   help="which records (default test; 'all' for a fresh test-only dataset)")
    e.add_argument("--out", required=True, help="report folder")
    at.add_mirror_option(e)
    engine.add_arguments(e, "the network")
    e.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("predict", help="predict light direction and colour of images",
                       description="Predict the light of PNG/JPEG (sRGB) or EXR (linear) images of any size.")
    p.add_argument("images", nargs="+", help="image files or folders of images")
    p.add_argument("--camera-tilt", type=camera_tilt, default=None,
                   help="camera tilt in degrees used to decode the light tilt (default: the model's own estimate "
                        "when it has a camera head, as photo has; else 45, the paper's)")
    at.add_model_option(p)
    p.add_argument("--mask", action="append", default=None, metavar="MASK",
                   help="an object mask per image, in the images' order (a PNG of the image's size, white "
                        "where the objects are): everything outside it is set black first; repeatable. A model "
                        "of the objects alone (trained with --surround black) needs one per image")
    p.add_argument("--linear", action="store_true",
                   help="PNG/JPEG codes are linear values (a camera whose output is proportional to the light: "
                        "measurement and machine-vision cameras); default sRGB. EXR is linear either way")
    p.add_argument("--out", required=True, help="predictions file to write (relight.predictions/v1)")
    at.add_mirror_option(p)
    p.set_defaults(func=cmd_predict)


def cmd_train(args) -> int:
    import dataclasses
    from relight.fileio import check_folder_target, check_outputs
    from relight.net.io import named_file
    from relight.net.train import TrainConfig, train
    init = named_file(args.init)   # a name: its shipped file
    check_outputs([args.out], [*args.data, init])
    check_folder_target(args.out)
    cfg = TrainConfig(data_dir=tuple(args.data), init=os.path.abspath(init) if init else None,
                      image_key="image_masked" if args.images == "masked" else "image",
                      epochs=args.epochs, batch_size=args.batch_size, lr=float(args.lr),
                      res=args.res, seed=args.seed, flip=not args.no_flip, plateau_patience=args.patience,
                      threads=args.torch_threads, workers=args.workers,
                      max_minutes=args.max_minutes, width=args.width, arch=args.arch,
                      kappa_detach=not args.kappa_into_features,
                      camera_weight=float(args.camera_weight), source=args.source, augment=args.augment,
                      target_frame=args.target_frame, epoch_images=args.epoch_images,
                      surround=args.surround, loss_weights=dataclasses.replace(args.loss_weights, kappa=args.kappa_weight))
    row = train(cfg, args.out, resume=args.resume, progress=not args.quiet)
    if row:
        print(f"{args.out}: epoch {row['epoch']}, val loss {row['val_loss']:.4f}, val mean direction "
              f"{row['val_direction_deg']:.2f} deg; weights {os.path.join(args.out, 'best.safetensors')}")
    return 0


def cmd_calibrate(args) -> int:
    from relight.fileio import check_file_target, check_outputs
    from relight.net.calibrate import CalibrationConfig, calibrate_model_file
    from relight.net.io import named_file, resolve_model
    model_file = resolve_model(args.model)   # a shipped name, a file or a run folder's best.safetensors
    check_outputs([args.out], [*args.data, model_file, named_file(args.model)])
    check_file_target(args.out)
    rep = calibrate_model_file(model_file, args.data, args.out,
                               CalibrationConfig(split=args.split, mode=args.mode, ood=args.ood), progress=True)
    if args.mode != "none":
        b, a = rep["check_before"], rep["check_after"]
        fmt = (lambda s: f"NLL {s['nll_mean']:.3f}, 90% cone covers {100 * s['cone90_coverage']:.1f}%, Spearman "
                         + ("-" if s["spearman_cone90_error"] is None else f"{s['spearman_cone90_error']:.2f}"))
        print(f"{rep['n_images']} images of split {rep['split']} ({rep['n_fit']} fit / {rep['n_check']} check "
              f"predictions), mode {args.mode}, {rep['best_step']} steps, temperature {rep['temperature']:.3f}")
        print(f"check part before: {fmt(b)}")
        print(f"check part after:  {fmt(a)}")
    if "ood" in rep:
        print(f"out-of-distribution detector: {rep['ood']['ood_dims']} components, threshold "
              f"{rep['ood']['ood_threshold']:.3f} ({100 * rep['ood']['quantile']:g}% of {rep['ood']['n']} images below)")
    print(f"wrote {args.out}")
    return 0


def _model_label(args) -> str:
    """The model as reports and predictions files name it: the shipped name it resolves to
    (no --model: the default's), else the --model given; and how it was run."""
    from relight.net.io import model_label
    return model_label(args.model) + (" (mirror-averaged)" if args.mirror_average else "")


def cmd_evaluate(args) -> int:
    import torch

    from relight import metrics
    from relight.net.evaluate import evaluate
    from relight.fileio import check_folder_target, check_outputs
    from relight.net.io import named_file, resolve_model
    from relight.net.predict import load_model
    model_file = resolve_model(args.model)
    check_outputs([args.out], [args.data, model_file, named_file(args.model)])
    check_folder_target(args.out)
    torch.set_num_threads(1)
    model = load_model(model_file, mirror_average=args.mirror_average)
    name = _model_label(args)
    tables = evaluate(model, args.data, args.out, split=args.split, model_name=name,
                      scheduler=engine.scheduler_from_args(args))
    print(metrics.format_tables(tables, only_table1=True))
    import json
    with open(os.path.join(args.out, "metrics.json")) as f:
        doc = json.load(f)
    unc, cct = doc.get("uncertainty"), doc["cct"]
    if cct["n"]:
        print(f"CCT error: mean {cct['kelvin']['mean']:.0f} K, {cct['mired']['mean']:.1f} mired "
              f"({cct['n']} images with a CCT)")
    if unc:
        rho = unc["spearman_cone90_error"]
        print(f"90% direction cones cover {100 * unc['cone90_coverage']:.1f}% of true directions; "
              f"rank correlation cone vs error {'-' if rho is None else f'{rho:.2f}'}; "
              f"reliability diagram {os.path.join(args.out, 'reliability.png')}")
    print(f"report: {os.path.join(args.out, 'report.md')}")
    return 0


def cmd_predict(args) -> int:
    from relight.net.predict import DEFAULT_CAMERA_TILT_DEG, list_images, load_model, predict_files
    from relight.fileio import check_file_target, check_outputs
    from relight.net.io import named_file, resolve_model
    from relight.predictions import write_predictions
    model_file = resolve_model(args.model)
    check_outputs([args.out], args.images + (args.mask or []) + [model_file, named_file(args.model)])
    check_file_target(args.out)
    model = load_model(model_file, mirror_average=args.mirror_average)
    files = list_images(args.images)
    check_outputs([args.out], files)
    own_tilt = args.camera_tilt is None and getattr(model, "has_camera", False)
    tilt = None if own_tilt else (DEFAULT_CAMERA_TILT_DEG if args.camera_tilt is None else args.camera_tilt)
    preds = predict_files(model, files, tilt, masks=args.mask, linear=args.linear)
    grey = [p["id"] for p in preds if p.get("colour_reliable") is False]
    if grey:
        import sys
        names = ", ".join(grey[:3]) + (f" and {len(grey) - 3} more" if len(grey) > 3 else "")
        print(f"warning: {names}: grayscale image{'s' if len(grey) > 1 else ''}, the colour estimate is "
              'meaningless (marked "colour_reliable": false)', file=sys.stderr)
    if own_tilt:
        print("camera tilt: the model's own estimate per image (--camera-tilt overrides it)")
    else:
        print(f"camera tilt assumed: {tilt:g} deg{' (default, as the paper for photographs)' if args.camera_tilt is None else ''}")
    print(f"{'id':<20} {'pan_rel':>8} {'tilt':>7} {'cone90':>7}  {'rgb (unit)':<22} {'CCT K':>6} input")
    for p in preds:
        rgb = ",".join(f"{v:.3f}" for v in p["rgb"])
        cone = f"{p['cone90_deg']:7.1f}" if "cone90_deg" in p else f"{'-':>7}"
        cct = f"{p['cct_k']:6.0f}" if p["cct_k"] is not None else f"{'-':>6}"
        print(f"{p['id'][:20]:<20} {p['pan_deg']:8.1f} {p['tilt_deg']:7.1f} {cone}  {rgb:<22} {cct} {p['assumed']}")
    fields = ("id", "pan_deg", "tilt_deg", "rgb", "y", "cct_k", "duv", "kappa", "cone90_deg", "colour_reliable",
              "camera_tilt_deg", "to_light_camera", "ood", "ood_score")
    entries = [{k: p[k] for k in fields if k in p} | {"file": os.path.abspath(p["file"])} for p in preds]
    for entry, mask in zip(entries, args.mask or []):
        entry["mask"] = os.path.abspath(mask)
    meta = {"camera_tilt_deg": tilt} if tilt is not None else {"camera_tilt": "predicted per image"}
    if args.linear:
        meta["pixel_codes"] = "linear"
    write_predictions(args.out, entries, model=_model_label(args), inputs=files, **meta)
    print(f"wrote {args.out} ({len(entries)} predictions)")
    return 0
