"""Proxy study: does a mode-seeking direction output undo the shrinkage on photographs?

On psm_objects the photo model's answers are pulled toward an average direction (the
least-squares slope of predicted on true x within each object is 0.2-0.4; docs/photo.md,
seventh round). A regression trained by squared error returns the mean of its posterior;
where an image is ambiguous that mean sits between the candidate directions. This study
reads the *same* embedding four ways and scores each on renders and photographs:

* ``heads``: the model's own pan / tilt regression heads (trained with the encoder);
* ``regress``: a fresh regression head (unit vector, cosine loss) on the frozen embedding;
* ``bins-mean``: a fresh classifier over direction bins (a Fibonacci sphere, soft vMF
  labels, cross-entropy), read out as its normalised mean direction (mean-seeking);
* ``bins-mode``: the same classifier, read out at its mode (the most probable bin,
  refined by the probability-weighted mean of the bins within ``--mode-radius`` of it).

``bins-mean`` against ``bins-mode`` isolates the read-out on one trained classifier;
``regress`` against ``bins-mean`` the loss. The fresh heads learn from renders the model
never saw (records ``--train-from`` on of the photo training set; the shipped model used
the first 20,000), with the training camera pipeline (``--augment photo``) and mirror
flips; the render test is a later, disjoint range, unaugmented. Photographs are only
scored, never used to fit or choose anything (the heads stop at a fixed epoch count).

Usage::

    .venv/bin/python benchmarks/proxy_mode_head.py --data ~/relight-data/photo-train-backdrop \\
        --model relight/models/photo.safetensors [--train 14000] [--test 2000] [--seed 0]

Embeddings are cached next to ``--cache`` (an .npz per model and record range), so
re-runs with other head settings cost seconds.
"""
from __future__ import annotations

import hashlib
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)


def fibonacci_sphere(k: int) -> np.ndarray:
    """``k`` near-uniform unit vectors ``(k, 3)`` (the golden-angle spiral)."""
    i = np.arange(k, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / k
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5 ** 0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def camera_vectors(targets: np.ndarray) -> np.ndarray:
    """Camera-frame unit vectors (x right, y up, z toward the camera) of camera-frame
    network targets ``(N, 7)`` (:func:`relight.frames.y_to_target`, a level camera)."""
    from relight import frames
    pan, tilt, _ = frames.decode_y(np.asarray(targets, np.float64), 0.0)
    return frames.world_to_camera(frames.direction(pan, tilt), 0.0)


def embed_dataset(model, data_dir: str, start: int, count: int, augment: bool, seed: int, cache: str):
    """``(embeddings (N, E) float32, camera-frame truth (N, 3), head outputs (N, 3))`` of
    records ``start .. start + count`` of ``data_dir`` (EXR source; the photo pipeline and
    mirror flips when ``augment``), cached in ``cache``."""
    import torch

    from relight.dataset import read_manifest
    from relight.net.augment import AUGMENTS
    from relight.net.data import LightDataset
    if os.path.exists(cache):
        z = np.load(cache)
        return z["e"], z["t"], z["h"]
    records = read_manifest(data_dir)[start:start + count]
    for r in records:
        r["split"] = "train"
    ds = LightDataset(data_dir, "train", model.config.res, flip=augment, seed=seed, cache=False, records=records,
                      source="exr", target_frame="camera", augment=AUGMENTS["photo"]() if augment else None)
    from tqdm import tqdm
    es, ts, hs = [], [], []
    with torch.no_grad():
        for s in tqdm(range(0, len(ds), 64), desc=f"embed {os.path.basename(cache)}", leave=False, mininterval=30):
            items = [ds[i] for i in range(s, min(s + 64, len(ds)))]
            x = torch.stack([it[0] for it in items])
            e = model.encode(x)
            y, _, _ = model.heads(e)
            es.append(e.numpy().astype(np.float32))
            ts.append(camera_vectors(np.stack([it[1].numpy() for it in items])))
            hs.append(camera_vectors(y.double().numpy()))
    e, t, h = np.concatenate(es), np.concatenate(ts), np.concatenate(hs)
    with open(cache + ".tmp", "wb") as f:   # a killed run leaves no half-written cache
        np.savez(f, e=e, t=t, h=h)
    os.replace(cache + ".tmp", cache)
    return e, t, h


def embed_photos(model, files: list[str]):
    """``(embeddings, head outputs as camera vectors)`` of photographs (the predict path's input)."""
    import torch

    from relight.net.predict import read_input
    x = torch.stack([read_input(f, model.config.res)[0] for f in files])
    with torch.no_grad():
        e = model.encode(x)
        y, _, _ = model.heads(e)
    return e.numpy().astype(np.float32), camera_vectors(y.double().numpy())


class Heads:
    """The fresh heads on a frozen embedding: a regression to a unit vector and a
    classifier over ``bins``; both an MLP like the model's own heads (one hidden layer)."""

    def __init__(self, dim: int, bins: np.ndarray, hidden: int, sigma_deg: float, seed: int):
        import torch
        from torch import nn
        torch.manual_seed(seed)
        self.bins = torch.from_numpy(bins.astype(np.float32))
        self.kappa = 1.0 / np.radians(sigma_deg) ** 2
        self.mu = None
        mlp = lambda out: nn.Sequential(nn.Linear(dim, hidden), nn.ReLU(), nn.Dropout(0.2), nn.Linear(hidden, out))
        self.regress, self.classify = mlp(3), mlp(len(bins))

    def fit(self, e: np.ndarray, t: np.ndarray, epochs: int, lr: float, wd: float, batch: int = 256):
        import torch
        import torch.nn.functional as F
        self.mu, self.sd = e.mean(0), e.std(0) + 1e-6
        x = torch.from_numpy((e - self.mu) / self.sd)
        target = torch.from_numpy(t.astype(np.float32))
        soft = torch.softmax(self.kappa * target @ self.bins.T, dim=1)   # vMF kernel on the bins
        params = [*self.regress.parameters(), *self.classify.parameters()]
        opt = torch.optim.AdamW(params, lr=lr, weight_decay=wd)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs)
        g = torch.Generator().manual_seed(0)
        self.regress.train(), self.classify.train()
        for _ in range(epochs):
            for idx in torch.randperm(len(x), generator=g).split(batch):
                r = F.normalize(self.regress(x[idx]), dim=1)
                loss_r = (1.0 - (r * target[idx]).sum(1)).mean()
                loss_c = -(soft[idx] * F.log_softmax(self.classify(x[idx]), dim=1)).sum(1).mean()
                opt.zero_grad()
                (loss_r + loss_c).backward()
                opt.step()
            sched.step()
        self.regress.eval(), self.classify.eval()
        return self

    def read(self, e: np.ndarray, mode_radius_deg: float) -> dict[str, np.ndarray]:
        """Camera-frame answers ``(N, 3)`` of each read-out."""
        import torch
        import torch.nn.functional as F
        x = torch.from_numpy((e - self.mu) / self.sd)
        with torch.no_grad():
            r = F.normalize(self.regress(x), dim=1)
        return {"regress": r.double().numpy()} | read_bins(self.classify, x.numpy(), self.bins.double().numpy(),
                                                             mode_radius_deg)


def finetune(init: str, data_dir: str, out: str, bins: np.ndarray, sigma_deg: float, epochs: int, lr: float,
             head_lr: float, ce_weight: float, seed: int):
    """Fine-tune ``init`` on ``data_dir`` with a classifier over ``bins`` trained with it
    (its soft-label cross-entropy, weight ``ce_weight``, added to the model's own loss, so the
    encoder learns from it too); the weights of the lowest val loss (the model's own loss on
    the val split, as ``relight train`` chooses) are kept in ``out``/best.pt.
    Returns ``(model, classifier)``; a finished ``out`` (its ``done`` marker) is loaded, not
    trained again; an unfinished one (a killed run, minutes long) starts over."""
    import torch
    import torch.nn.functional as F

    from relight.net.augment import AUGMENTS
    from relight.net.data import LightDataset
    from relight.net.io import load_model_file
    from relight.net.loss import LossWeights, light_loss
    from relight.net.model import _head
    from relight.net.train import _camera_tilts, camera_loss, with_heads
    torch.manual_seed(seed)
    model = load_model_file(init)
    if model.config.ood_dims:
        model = with_heads(model, ood_dims=0)
    classify = _head(model.config.embed, model.config.head_hidden, len(bins))
    best_path, done = os.path.join(out, "best.pt"), os.path.join(out, "done")
    if os.path.exists(done):
        state = torch.load(best_path)
        model.load_state_dict(state["model"]), classify.load_state_dict(state["classify"])
        return model.eval(), classify.eval()
    os.makedirs(out, exist_ok=True)
    b = torch.from_numpy(bins.astype(np.float32))
    kappa_t = 1.0 / np.radians(sigma_deg) ** 2
    train_set = LightDataset(data_dir, "train", model.config.res, flip=True, seed=seed, source="exr",
                             target_frame="camera", augment=AUGMENTS["photo"]())
    val_set = LightDataset(data_dir, "val", model.config.res, source="exr", target_frame="camera")
    opt = torch.optim.Adam([{"params": model.parameters(), "lr": lr}, {"params": classify.parameters(), "lr": head_lr}])
    weights, best = LossWeights(), float("inf")

    def losses(x, y, index, dataset):
        e = model.encode(x)
        y_pred, kappa, camera = model.heads(e, calibrated=False)
        parts = light_loss(y_pred, y, weights, parts=True, kappa=kappa,
                           camera_tilt_deg=torch.from_numpy(dataset.target_tilts(index)))
        own = parts["total"] + camera_loss(camera, _camera_tilts(dataset, index))
        t = torch.from_numpy(camera_vectors(y.double().numpy()).astype(np.float32))
        soft = torch.softmax(kappa_t * t @ b.T, dim=1)
        ce = -(soft * F.log_softmax(classify(e), dim=1)).sum(1).mean()
        return own, parts["objective"] - parts["total"] + own + ce_weight * ce, ce

    from tqdm import tqdm
    for epoch in range(epochs):
        train_set.epoch = epoch
        model.train(), classify.train()
        order = torch.randperm(len(train_set), generator=torch.Generator().manual_seed(seed * 1000 + epoch))
        for idx in tqdm(order.split(16), desc=f"epoch {epoch + 1}/{epochs}", leave=False, mininterval=30):
            items = [train_set[int(i)] for i in idx]
            x, y = torch.stack([it[0] for it in items]), torch.stack([it[1] for it in items])
            _, objective, _ = losses(x, y, [it[2] for it in items], train_set)
            opt.zero_grad(set_to_none=True)
            objective.backward()
            opt.step()
        model.eval(), classify.eval()
        own_sum = ce_sum = 0.0
        with torch.no_grad():
            for s in range(0, len(val_set), 64):
                items = [val_set[i] for i in range(s, min(s + 64, len(val_set)))]
                x, y = torch.stack([it[0] for it in items]), torch.stack([it[1] for it in items])
                own, _, ce = losses(x, y, [it[2] for it in items], val_set)
                own_sum, ce_sum = own_sum + float(own) * len(items), ce_sum + float(ce) * len(items)
        val = own_sum / len(val_set)
        print(f"epoch {epoch + 1}: val loss {val:.4f}, val cross-entropy {ce_sum / len(val_set):.3f}", flush=True)
        if val < best:
            best = val
            torch.save({"model": model.state_dict(), "classify": classify.state_dict(), "epoch": epoch + 1},
                       best_path + ".tmp")
            os.replace(best_path + ".tmp", best_path)
    open(done, "w").close()
    state = torch.load(best_path)
    model.load_state_dict(state["model"]), classify.load_state_dict(state["classify"])
    return model.eval(), classify.eval()


def read_bins(classify, e: np.ndarray, bins: np.ndarray, mode_radius_deg: float) -> dict[str, np.ndarray]:
    """The classifier's mean and mode read-outs (camera frame) on embeddings ``e``."""
    import torch
    import torch.nn.functional as F
    b = torch.from_numpy(bins.astype(np.float32))
    with torch.no_grad():
        p = torch.softmax(classify(torch.from_numpy(e)), dim=1)
    peak = b[p.argmax(1)]
    near = (peak @ b.T) >= np.cos(np.radians(mode_radius_deg))
    return {"bins-mean": F.normalize(p @ b, dim=1).double().numpy(),
            "bins-mode": F.normalize((p * near) @ b, dim=1).double().numpy(),
            "peak_prob": (p * near).sum(1).double().numpy()}


def score(label: str, answers: dict, truth: np.ndarray, groups=None) -> list[str]:
    from relight import metrics
    from relight.net.photos import shrinkage
    rows = []
    for name in ("heads", "regress", "bins-mean", "bins-mode"):
        if name not in answers:
            continue
        err = metrics.angle_deg(answers[name], truth)
        s = shrinkage(answers[name], truth, groups)
        rows.append(f"| {label} | {name} | {len(err)} | {np.median(err):.1f} | {np.mean(err):.1f} | "
                    f"{s['slope_x']:.2f} / {s['slope_y']:.2f} | {s['bias_x']:+.2f} / {s['bias_y']:+.2f} |")
    return rows


def report(model, read, e_test: np.ndarray, t_test: np.ndarray, h_test: np.ndarray, shared: str | None) -> None:
    """Print the table: each read-out (``read(embeddings)``, plus the model's own ``heads``) on
    the render test range and on the psm photographs (skipped with one line where absent)."""
    from relight.net.photos import read_photo_set, shared_data_dir
    print("| set | read-out | n | median | mean | slope x / y | bias x / y |")
    print("|---|---|---|---|---|---|---|")
    for row in score("renders (unseen)", read(e_test) | {"heads": h_test}, t_test):
        print(row)
    shared = shared_data_dir(shared)
    for label, sub, names in (("psm_objects", "psm_objects", None), ("gray ball", "psm_spheres", ("gray",)),
                              ("chrome ball", "psm_spheres", ("chrome",))):
        folder = os.path.join(shared, sub)
        if not os.path.isdir(folder):
            print(f"{label}: skipped ({folder} not present)")
            continue
        files, truth = read_photo_set(folder, names)
        e, h = embed_photos(model, files)
        answers = read(e) | {"heads": h}
        for row in score(label, answers, truth, [os.path.basename(f).split(".")[0] for f in files]):
            print(row)
        print(f"| {label} | peak mass (bins-mode) | {len(files)} | {np.median(answers['peak_prob']):.2f} | | | |")


def main(argv=None) -> int:
    from relight.commands import argtypes as at
    count, deg = at.int_in(1, 10_000_000, "a count"), at.float_in(0.0, 180.0, "an angle in degrees", open_lo=True)
    p = at.OneLineParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="a photo-preset dataset folder (EXR kept)")
    p.add_argument("--model", default=os.path.join(REPO, "relight", "models", "photo.safetensors"),
                   help="the model whose embedding the fresh heads read (default: the shipped photo model)")
    p.add_argument("--train-from", type=at.int_in(0, 10_000_000, "a record index"), default=20000,
                   help="first record of the heads' training range (default 20000: after the shipped model's)")
    p.add_argument("--train", type=count, default=14000, help="records the heads learn from (default 14000)")
    p.add_argument("--test-from", type=at.int_in(0, 10_000_000, "a record index"), default=44000,
                   help="first record of the render test range (default 44000)")
    p.add_argument("--test", type=count, default=2000, help="render test records (default 2000)")
    p.add_argument("--bins", type=at.int_in(12, 100_000, "a bin count"), default=1024,
                   help="direction classes on a Fibonacci sphere (default 1024, about 6 degrees apart)")
    p.add_argument("--sigma", type=deg, default=8.0, help="soft label width, degrees (default 8)")
    p.add_argument("--mode-radius", type=deg, default=15.0,
                   help="degrees around the peak bin averaged by the mode read-out (default 15)")
    p.add_argument("--hidden", type=count, default=256, help="hidden units of the fresh heads (default 256)")
    p.add_argument("--epochs", type=count, default=30, help="epochs of the fresh heads (default 30)")
    p.add_argument("--lr", type=at.positive_float, default=1e-3, help="the fresh heads' learning rate (default 1e-3)")
    p.add_argument("--wd", type=at.finite_float, default=1e-2, help="their weight decay (default 1e-2)")
    p.add_argument("--seed", type=at.int_in(0, 2**31 - 1, "a seed"), default=0)
    p.add_argument("--cache", default=os.path.expanduser(os.path.join("~", "relight-data", "eval", "mode-head")),
                   help="folder of the cached embeddings")
    p.add_argument("--shared", default=None, help="folder holding psm_objects/ and psm_spheres/ (default: "
                   "$RELIGHT_SHARED_DATA, else shared/data next to the checkout)")
    p.add_argument("--threads", type=at.int_in(1, 256, "a thread count"), default=2)
    p.add_argument("--finetune", metavar="DATA", help="instead: fine-tune --init with a bin classifier on DATA "
                   "(its train / val splits) and score its heads against the classifier's read-outs")
    p.add_argument("--init", default=os.path.expanduser(os.path.join("~", "relight-data", "runs", "photo-bd",
                                                                      "best.safetensors")),
                   help="--finetune's starting weights (default: the shipped photo model's uncalibrated run)")
    p.add_argument("--out", help="--finetune's run folder (required with it; a finished one is only scored)")
    p.add_argument("--ft-epochs", type=count, default=6, help="--finetune's epochs (default 6)")
    p.add_argument("--ft-lr", type=at.positive_float, default=3e-5,
                   help="--finetune's rate for the network (default 3e-5; the classifier uses --lr)")
    p.add_argument("--ce-weight", type=at.positive_float, default=0.1,
                   help="weight of the classifier's cross-entropy in --finetune's loss (default 0.1)")
    a = p.parse_args(argv)
    if a.finetune and not a.out:
        p.error("--finetune needs --out (the run folder)")
    if a.finetune:
        return main_finetune(a)

    import torch

    from relight.net.io import load_model_file
    torch.set_num_threads(a.threads)
    model = load_model_file(a.model).eval()
    os.makedirs(a.cache, exist_ok=True)
    tag = hashlib.sha1(open(a.model, "rb").read()).hexdigest()[:10]
    t0 = time.time()
    e_tr, t_tr, _ = embed_dataset(model, a.data, a.train_from, a.train, True, a.seed,
                                  os.path.join(a.cache, f"{tag}-train-{a.train_from}-{a.train}-{a.seed}.npz"))
    e_te, t_te, h_te = embed_dataset(model, a.data, a.test_from, a.test, False, 0,
                                     os.path.join(a.cache, f"{tag}-test-{a.test_from}-{a.test}.npz"))
    print(f"embeddings: {len(e_tr)} train, {len(e_te)} test ({time.time() - t0:.0f} s)")
    heads = Heads(e_tr.shape[1], fibonacci_sphere(a.bins), a.hidden, a.sigma, a.seed)
    heads.fit(e_tr, t_tr, a.epochs, a.lr, a.wd)

    report(model, lambda e: heads.read(e, a.mode_radius), e_te, t_te, h_te, a.shared)
    return 0


def main_finetune(a) -> int:
    import torch
    torch.set_num_threads(a.threads)
    bins = fibonacci_sphere(a.bins)
    model, classify = finetune(a.init, a.finetune, a.out, bins, a.sigma, a.ft_epochs, a.ft_lr, a.lr, a.ce_weight,
                               a.seed)
    e_te, t_te, h_te = embed_dataset(model, a.data, a.test_from, a.test, False, 0, os.path.join(a.out, "test.npz"))
    report(model, lambda e: read_bins(classify, e, bins, a.mode_radius), e_te, t_te, h_te, a.shared)
    return 0


if __name__ == "__main__":
    from relight.commands import argtypes
    sys.exit(argtypes.run_script(main))
