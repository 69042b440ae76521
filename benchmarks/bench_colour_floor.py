"""How much light colour a scene can give away: the surface-colour evidence behind the
colour error of the network (issue 8's colour target).

In a one-light scene of diffuse surfaces an image shows ``albedo x light colour``, so
the light's colour is known only as well as the scene's surfaces average out to
something known. Four measurements:

1. **Surfaces averaging out** (no rendering): the angle between the mean colour of N
   surfaces drawn from a prior and that prior's own mean colour, for each prior
   (``hsv`` objects: uniform per channel; ``hsv`` textures; ``munsell`` chips). This is
   gray-world's error on a scene of N equally weighted surfaces, the floor a
   surface-statistics estimator approaches; the paper's ShapeNet objects carry a random
   colour per mesh part, so its images hold many more independent surfaces than ours
   (walls, floor, 1-3 objects of one colour each).
2. **The Bayes floor**: the error of the ideal observer (the posterior mean over the
   generator's light prior, in closed form for uniform-box albedos) given the colours
   of N surfaces: how well *any* estimator can do from N surfaces' colours.
3. **By object count and by object parts** (``--eval DIR --data DIR``): a model's colour
   error on a test set split by the number of objects in each scene and by the number of
   independently coloured object parts (from ``relight evaluate``'s ``per_image.csv``,
   the dataset's manifest and scene files).

4. **The floor of each scene of a dataset** (``--floors DATA``): the surfaces each image
   actually shows (an albedo render matched to the scene file's colours) and the ideal
   observer under the generator's own priors (:func:`scene_floors`); with ``--eval``
   beside a model's colour error on the same images. Sets of ``--preset sid2-paper``: the
   observer's light prior is the preset's 80 Tanner-Helland triplets, its object prior the
   pastel one; on ``library`` backgrounds it knows the library (the backgrounds are shared
   by train and test, so a network can learn them), on ``unseen`` ones only how
   backgrounds are drawn.

    .venv/bin/python benchmarks/bench_colour_floor.py [--draws 2000]
        [--eval /root/relight-data/sid2-test-eval --data /root/relight-data/sid2-test]
    .venv/bin/python benchmarks/bench_colour_floor.py --floors /root/relight-data/sid2p-test
        --scenes 1000 [--eval EVAL]
    .venv/bin/python benchmarks/bench_colour_floor.py --floors PAPER_SET --scenes 200
        (PAPER_SET: relight generate --preset sid2-paper [--backgrounds unseen] ...)

The floor at 2,000 scenes per count takes about 10 minutes on one core (the 300-surface
posterior dominates); its means carry a standard error of 0.13 degree for one surface,
0.08 for five.
"""
from __future__ import annotations

import argparse
import csv
import functools
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.dataset import read_manifest  # noqa: E402
from relight.metrics import colour_error_deg  # noqa: E402
from relight.scene.albedo import (ALBEDO_MAX, ALBEDO_MIN, OBJECT_RANGE, box_direction_logpdf,  # noqa: E402
                                  ideal_observer_errors, munsell_albedos, object_reflectance, texture_colours)

COUNTS = (1, 3, 5, 10, 30, 100, 300)


def samplers(rng: np.random.Generator) -> dict:
    """Name -> function(n) giving ``(n, 3)`` linear albedos of one prior."""
    table = munsell_albedos()
    return {
        "hsv objects": lambda n: np.array([object_reflectance(rng, "hsv") for _ in range(n)]),
        "hsv textures": lambda n: np.array([texture_colours(rng, 1, "hsv")[0] for _ in range(n)]),
        "munsell chips": lambda n: table[rng.integers(0, len(table), n)],
    }


def averaging_table(draws: int, seed: int = 0) -> dict[str, list[float]]:
    """Prior -> mean angle (degrees) of the mean of N surfaces from the prior's mean,
    for each N of :data:`COUNTS`."""
    rng = np.random.default_rng(seed)
    out = {}
    for name, draw in samplers(rng).items():
        ref = draw(20000).mean(0)
        out[name] = [float(colour_error_deg(np.array([draw(n).mean(0) for _ in range(draws)]), ref).mean())
                     for n in COUNTS]
    return out


def ideal_observer_table(draws: int, seed: int = 0,
                         n_candidates: int = 4000) -> list[tuple[float, float, float]]:
    """The Bayes floor of light-colour recovery from N surfaces, for each N of :data:`COUNTS`:
    (mean, median, standard error of the mean) angle in degrees of the posterior-mean light colour given the
    directions of N surfaces ``albedo * light``, albedos from the ``hsv`` object prior
    (uniform per channel) and lights from the generator's prior (CCT 2500-10000 K
    uniform in mireds, |Duv| <= 0.01), the posterior over ``n_candidates`` lights drawn
    from that prior. No estimator that sees only the surfaces' colours does better on
    average: the network's colour error cannot go below this for N visible surfaces."""
    from relight.colour import sample_light_colour
    rng = np.random.default_rng(seed)
    candidates = np.array([sample_light_colour(rng)[2] for _ in range(n_candidates)])
    out = []
    for n in COUNTS:
        errs = ideal_observer_errors(n, draws, candidates, rng)
        out.append((float(np.mean(errs)), float(np.median(errs)), float(np.std(errs) / np.sqrt(len(errs)))))
    return out


PART_BINS = ((1, 3), (4, 15), (16, 31), (32, 63), (64, 96))   # object parts in a scene (up to 3 x 32)


def _colour_error_by(eval_dir: str, group_of: dict[str, object]) -> dict:
    """Group -> (images, colour error mean, median) of an evaluation, each image in the
    group ``group_of[its id]`` (-1 when unknown)."""
    errors: dict = {}
    with open(os.path.join(eval_dir, "per_image.csv")) as f:
        for row in csv.DictReader(f):
            errors.setdefault(group_of.get(row["id"], -1), []).append(float(row["colour_err_deg"]))
    return {k: (len(v), float(np.mean(v)), float(np.median(v))) for k, v in sorted(errors.items())}


def by_object_count(eval_dir: str, data_dir: str) -> dict[int, tuple[int, float, float]]:
    """Objects in the scene -> (images, colour error mean, median) of an evaluation."""
    return _colour_error_by(eval_dir, {r["id"]: int(r.get("n_objects", -1)) for r in read_manifest(data_dir)})


def by_object_parts(eval_dir: str, data_dir: str) -> dict[tuple[int, int], tuple[int, float, float]]:
    """Independently coloured object parts in the scene, binned by :data:`PART_BINS`
    (from its scene file) -> (images, colour error mean, median) of an evaluation."""
    from relight.scene.spec import load_scene
    group = {}
    for r in read_manifest(data_dir):
        n = sum(len(o.colours) for o in load_scene(os.path.join(data_dir, "scenes", f"{r['id']}.json")).objects)
        group[r["id"]] = next((b for b in PART_BINS if b[0] <= n <= b[1]), (n, n))
    return _colour_error_by(eval_dir, group)


MIN_PIXELS = 4             # a surface counts as seen when at least this many pixels show it
VALUE_TOL = 2e-3           # albedo AOV against a texture colour (bilinear blends at cell edges miss)
DIRECTION_TOL_DEG = 0.5    # objects: the rough diffuse BSDF's albedo is its reflectance times a grey factor
PATTERN_DIRECTION_TOL_DEG = 1.5   # pattern textures' colours, seen through blends and tile variation
VISIBLE_BINS = ((0, 9), (10, 29), (30, 99), (100, 299), (300, 100000))


@functools.lru_cache(maxsize=1)
def _albedo_integrator():
    from relight import backend
    return backend.mitsuba().load_dict({"type": "aov", "aovs": "albedo:albedo"})


def albedo_image(builder, spec) -> np.ndarray:
    """The first-hit albedo of every pixel of a scene file's view, ``(H * W, 3)`` (Mitsuba's
    ``aov`` integrator, loaded once, through the one render path, one sample per pixel)."""
    from relight.render import render_scene
    img = render_scene(builder.template_for(spec).scene, spp=1, seed=0, integrator=_albedo_integrator())
    return img[..., -3:].reshape(-1, 3).astype(np.float64)


def visible_surfaces(spec, albedos: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """``(texture colours seen, object part colours seen)`` of a scene: the albedos of its
    scene file that at least :data:`MIN_PIXELS` pixels of ``albedos`` (:func:`albedo_image`)
    show. Texture colours come per texture (walls in order, then the floor; a colour the
    floor's tiles repeat counts once), as a list of ``(n_k, 3)`` arrays."""
    textures = [*spec.room.wall_textures, spec.room.floor_texture]
    colours = np.array([c for t in textures for c in t["colors"]], dtype=np.float64)
    owner = np.array([k for k, t in enumerate(textures) for _ in t["colors"]])
    mosaic = np.array([t["kind"] == "mosaic" for t in textures])[owner]
    values, pixels = np.unique(np.round(albedos, 5), axis=0, return_counts=True)
    gap = np.abs(values[:, None, :] - colours[None]).max(-1)
    nearest = gap.argmin(1)
    hit = gap[np.arange(len(values)), nearest] < VALUE_TOL
    seen = np.bincount(nearest[hit], weights=pixels[hit], minlength=len(colours)) >= MIN_PIXELS
    # pattern kinds blend their colours (gradient, noise) or vary each tile's brightness: a
    # colour counts as seen when pixels share its direction (generous: a floor, not an estimate)
    unit = lambda c: c / np.maximum(np.linalg.norm(c, axis=-1, keepdims=True), 1e-12)
    near = (unit(values) @ unit(colours).T) > np.cos(np.radians(PATTERN_DIRECTION_TOL_DEG))
    seen |= ~mosaic & ((near * pixels[:, None]).sum(0) >= MIN_PIXELS)
    seen_tex = [np.unique(colours[seen & (owner == k)], axis=0) for k in range(len(textures))]
    parts = np.unique(np.array([c for o in spec.objects for c in o.colours], dtype=np.float64), axis=0)
    rest, rest_pixels = values[~hit & (values.sum(1) > 0)], pixels[~hit & (values.sum(1) > 0)]
    cos = unit(rest) @ unit(parts).T
    nearest = cos.argmax(1)
    hit = cos[np.arange(len(rest)), nearest] > np.cos(np.radians(DIRECTION_TOL_DEG))
    seen_parts = parts[np.bincount(nearest[hit], weights=rest_pixels[hit], minlength=len(parts)) >= MIN_PIXELS]
    return seen_tex, seen_parts


BASE_HUES = 48   # the hsv prior's texture base hue, integrated over on a grid of this many values
LIBRARY_SIGMA = 1e-3   # library backgrounds: chromaticity tolerance of a seen colour against a library one
PASTEL_DRAWS = 200_000  # draws of the pastel object prior behind its chromaticity density


def light_candidates(card_config: dict, n_candidates: int, rng: np.random.Generator) -> np.ndarray:
    """``(M, 3)`` draws of a dataset's light prior for the ideal observer, each carrying the
    same prior weight: ``n_candidates`` draws of relight's (CCT, Duv) prior, or for
    Tanner-Helland lights (``--preset sid2-paper``) its 80 triplets, 2000-9900 K in 100 K
    steps, each once (the prior is uniform over them)."""
    from relight.colour import (CCT_STEP_K, TANNER_HELLAND_RANGE_K, kelvin_to_rgb_tanner_helland,
                                sample_light_colour)
    if card_config.get("light_colour", "planckian") == "tanner-helland":
        lo, hi = TANNER_HELLAND_RANGE_K
        rgb = kelvin_to_rgb_tanner_helland(np.arange(lo, hi + CCT_STEP_K / 2, CCT_STEP_K))
        return rgb / np.linalg.norm(rgb, axis=1, keepdims=True)
    return np.array([sample_light_colour(rng)[2] for _ in range(n_candidates)])


def library_logpdf(seen: list[tuple[int, np.ndarray]], light: np.ndarray, candidates: np.ndarray,
                   sigma: float = LIBRARY_SIGMA) -> np.ndarray:
    """``log p(x | l)`` (M,) of the colours a scene shows of its library background, for each
    candidate light ``l``: ``seen`` holds ``(role, albedos (n, 3))``, role 0 the walls'
    texture and 1 the floor's. The observer knows the library: the background is one of its
    entries (uniform), each seen colour one of that entry's colours for its role, its
    chromaticity that of ``albedo * l`` within a Gaussian of ``sigma``; the entry is summed
    out."""
    from scipy.special import logsumexp

    from relight.scene.albedo import chromaticity
    from relight.scene.textures import background_library
    library = background_library()
    per_entry = np.zeros((len(library), len(candidates)))
    for role, albedos in seen:
        x = chromaticity(albedos * light)                                          # (n, 2)
        for k, background in enumerate(library):
            c = np.asarray(background[role]["colors"], dtype=np.float64)           # (C, 3)
            pred = chromaticity(c[None, :, :] * candidates[:, None, :])            # (M, C, 2)
            d2 = ((x[:, None, None, :] - pred[None]) ** 2).sum(-1)                 # (n, M, C)
            per_entry[k] += (logsumexp(-d2 / (2 * sigma ** 2), axis=2) - np.log(len(c))).sum(0)
    return logsumexp(per_entry, axis=0) - np.log(len(library))


def scene_floors(data_dir: str, n_scenes: int, n_candidates: int = 4000, seed: int = 0,
                 texture_draws: int = 40_000) -> list[dict]:
    """The Bayes floor of each of the first ``n_scenes`` scenes of a dataset: the error of the
    posterior-mean light colour given the colours of the surfaces its image shows, under
    the generator's priors, over ``n_candidates`` lights of its light prior. Walls and
    floor: an ``hsv`` pattern texture's colours share a base hue, integrated out on
    :data:`BASE_HUES` values (``texture_draws`` colours each); mosaic cells and ``munsell``
    colours are independent draws. Objects: the object prior (the box in closed form for
    ``hsv``, the chips for ``munsell``, a density of draws for ``pastel``). Only the surfaces'
    colours count (no shading, no interreflections, no noise): no estimator of those colours
    does better on average. A texture several walls share (one background) counts once.
    ``--preset sid2-paper`` sets (read from the dataset card): the light prior is its 80
    Tanner-Helland triplets (:func:`light_candidates`), and on ``library`` backgrounds the
    observer knows the library (:func:`library_logpdf`)."""
    from scipy.special import logsumexp

    from relight.scene.albedo import (chromaticity, chromaticity_log_density, hsv_texture_albedos,
                                      munsell_albedos, posterior_mean_light, scaled_chromaticity_logpdf,
                                      shared_hue_logpdf)
    from relight.scene.build import SceneBuilder
    from relight.scene.spec import load_scene
    from tqdm import tqdm
    from relight.dataset import read_card
    from relight.scene.albedo import pastel_albedos
    from relight.scene.textures import LIBRARY
    rng = np.random.default_rng(seed)
    card_config = read_card(data_dir).get("config", {})
    candidates = light_candidates(card_config, n_candidates, rng)
    library_mode = card_config.get("backgrounds") == LIBRARY
    by_hue = np.stack([chromaticity_log_density(hsv_texture_albedos(rng, texture_draws, (j + 0.5) / BASE_HUES))
                       for j in range(BASE_HUES)])                      # log p(chromaticity | base hue)
    hsv_marginal = logsumexp(by_hue, axis=0) - np.log(BASE_HUES)
    munsell = chromaticity_log_density(np.clip(munsell_albedos(), ALBEDO_MIN, ALBEDO_MAX))
    pastel = chromaticity_log_density(pastel_albedos(rng, PASTEL_DRAWS))
    lo, hi = OBJECT_RANGE
    builder, out = SceneBuilder(), []
    for rec in tqdm(read_manifest(data_dir)[:n_scenes], desc="scenes", leave=False):
        spec = load_scene(os.path.join(data_dir, "scenes", f"{rec['id']}.json"))
        prior = spec.colour_prior or "hsv"
        tex, parts = visible_surfaces(spec, albedo_image(builder, spec))
        light = np.asarray(spec.light.rgb, dtype=np.float64)
        textures = [*spec.room.wall_textures, spec.room.floor_texture]
        total = np.zeros(len(candidates))
        unique: dict = {}   # one background's walls share one texture: its colours count once
        for k, (texture, seen) in enumerate(zip(textures, tex)):
            key = (k == len(textures) - 1, json.dumps(texture, sort_keys=True))
            old_texture, old_seen = unique.get(key, (texture, np.zeros((0, 3))))
            unique[key] = (texture, np.unique(np.concatenate([old_seen, seen]), axis=0) if len(seen) else old_seen)
        if library_mode:    # the observer knows the library: walls (role 0) and floor (role 1)
            seen_roles = [(int(is_floor), seen) for (is_floor, _), (_, seen) in unique.items() if len(seen)]
            if seen_roles:
                total += library_logpdf(seen_roles, light, candidates)
        for texture, seen in ([] if library_mode else unique.values()):
            if not len(seen):
                continue
            x = chromaticity(seen * light)
            if prior == "munsell":
                total += scaled_chromaticity_logpdf(x, candidates, munsell).sum(0)
            elif texture["kind"] == "mosaic":   # every cell its own base hue
                total += scaled_chromaticity_logpdf(x, candidates, hsv_marginal).sum(0)
            else:                               # one base hue for the texture's colours
                total += shared_hue_logpdf(x, candidates, by_hue)
        if len(parts):
            c = parts * light
            if prior == "hsv":
                logp = box_direction_logpdf(c / np.linalg.norm(c, axis=1, keepdims=True), candidates, lo, hi)
            else:
                density = pastel if prior == "pastel" else munsell
                logp = scaled_chromaticity_logpdf(chromaticity(c), candidates, density)
            total += logp.sum(0)
        estimate = posterior_mean_light(total[None], candidates)
        out.append({"id": rec["id"], "textures": int(sum(len(t) for t in tex)), "parts": len(parts),
                    "floor_deg": float(colour_error_deg(estimate, light))})
    return out


def print_scene_floors(rows: list[dict], data_dir: str, eval_dir: str | None) -> None:
    """The per-scene floors by the number of surfaces seen, beside a model's colour error
    on the same images (``eval_dir``: its ``relight evaluate`` output)."""
    model = {}
    if eval_dir:
        with open(os.path.join(eval_dir, "per_image.csv")) as f:
            model = {r["id"]: float(r["colour_err_deg"]) for r in csv.DictReader(f)}
    print(f"\nBayes floor per scene of {data_dir} ({len(rows)} scenes; the surfaces each image shows, "
          "from an albedo render), degrees:\n")
    print("| surfaces seen | scenes | floor mean | floor median |" + (" model colour mean |" if model else ""))
    print("|---|---:|---:|---:|" + ("---:|" if model else ""))
    groups = [(f"{lo}-{hi}" if hi < 100000 else f">= {lo}", [r for r in rows if lo <= r["textures"] + r["parts"] <= hi])
              for lo, hi in VISIBLE_BINS] + [("all", rows)]
    for label, group in groups:
        if not group:
            continue
        f = [r["floor_deg"] for r in group]
        line = f"| {label} | {len(group)} | {np.mean(f):.2f} | {np.median(f):.2f} |"
        if model:
            line += f" {np.mean([model[r['id']] for r in group if r['id'] in model]):.2f} |"
        print(line)
    seen = [r["textures"] + r["parts"] for r in rows]
    print(f"\nSurfaces seen per scene: median {np.median(seen):.0f} (walls and floor {np.median([r['textures'] for r in rows]):.0f}, "
          f"object parts {np.median([r['parts'] for r in rows]):.0f}).")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=2000, help="scenes drawn per count (default 2000)")
    ap.add_argument("--eval", help="a relight evaluate output folder (per_image.csv)")
    ap.add_argument("--data", help="the dataset it evaluated (for the object counts)")
    ap.add_argument("--floors", metavar="DATA", help="the Bayes floor of each scene of this dataset (the "
                    "surfaces its image shows); with --eval, beside that model's colour error")
    ap.add_argument("--scenes", type=int, default=300, help="scenes for --floors (default 300)")
    args = ap.parse_args()
    if args.floors:
        print_scene_floors(scene_floors(args.floors, args.scenes), args.floors, args.eval)
        return 0
    table = averaging_table(args.draws)
    print("Mean colour of N surfaces vs the prior's mean colour (gray-world's error), mean degrees:\n")
    print("| prior | " + " | ".join(f"N={n}" for n in COUNTS) + " |")
    print("|---|" + "---:|" * len(COUNTS))
    for name, row in table.items():
        print(f"| {name} | " + " | ".join(f"{v:.2f}" for v in row) + " |")
    print("\nBayes floor (ideal observer, posterior mean; hsv object albedos, the generator's "
          "light prior), degrees, mean +- standard error (median):\n")
    print("| surfaces | " + " | ".join(f"N={n}" for n in COUNTS) + " |")
    print("|---|" + "---:|" * len(COUNTS))
    floor = ideal_observer_table(args.draws)
    print("| hsv objects | " + " | ".join(f"{m:.2f} +- {se:.2f} ({md:.2f})" for m, md, se in floor) + " |")
    if args.eval and args.data:
        print(f"\nColour error by objects in the scene ({args.eval}):\n")
        print("| objects | images | colour mean | colour median |")
        print("|---:|---:|---:|---:|")
        for k, (n, mean, median) in by_object_count(args.eval, args.data).items():
            print(f"| {k} | {n} | {mean:.2f} | {median:.2f} |")
        print(f"\nColour error by coloured object parts in the scene ({args.eval}):\n")
        print("| parts | images | colour mean | colour median |")
        print("|---:|---:|---:|---:|")
        for (lo, hi), (n, mean, median) in by_object_parts(args.eval, args.data).items():
            print(f"| {lo}-{hi} | {n} | {mean:.2f} | {median:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
