"""How much light colour a scene can give away: the surface-colour evidence behind the
colour error of the network (issue 8's colour target).

In a one-light scene of diffuse surfaces an image shows ``albedo x light colour``, so
the light's colour is known only as well as the scene's surfaces average out to
something known. Two measurements:

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

    .venv/bin/python benchmarks/bench_colour_floor.py [--draws 2000]
        [--eval /root/relight-data/sid2-test-eval --data /root/relight-data/sid2-test]

The floor at 2,000 scenes per count takes about 10 minutes on one core (the 300-surface
posterior dominates); its means carry a standard error of 0.13 degree for one surface,
0.08 for five.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight.dataset import read_manifest  # noqa: E402
from relight.metrics import colour_error_deg  # noqa: E402
from relight.scene.albedo import (ideal_observer_errors, munsell_albedos, object_reflectance,  # noqa: E402
                                  texture_colours)

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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=2000, help="scenes drawn per count (default 2000)")
    ap.add_argument("--eval", help="a relight evaluate output folder (per_image.csv)")
    ap.add_argument("--data", help="the dataset it evaluated (for the object counts)")
    args = ap.parse_args()
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
