"""Tests for relight.scene.textures: shape/range/dtype, determinism, variety, closed forms.
(Speed is measured in benchmarks/bench_generate.py, not here.)"""
import json
import math

import numpy as np
import pytest

from relight.scene import textures as T

SEED_DEPENDENT = [k for k in T.KINDS if k != "gradient"]


def _params(kind, seed):
    return T.sample_texture_params(np.random.default_rng(seed), kind)


def test_closed_form_stripes():
    # angle 0: stripes across x only; count 5 periods with duty 0.3 of colour 0, so each row
    # is the same, colour 0 covers 30% and the colour changes 2 x 5 times along a row
    # (+-1 for the random phase at the edges)
    c0, c1 = [0.1, 0.2, 0.3], [0.7, 0.6, 0.5]
    p = {"kind": "stripes", "seed": 4, "count": 5, "angle": 0.0, "duty": 0.3, "colors": [c0, c1]}
    img = T.make_texture(p, 500)
    assert np.all(img == img[:1])
    is0 = np.all(img[0] == np.float32(c0), axis=-1)
    assert np.all(is0 | np.all(img[0] == np.float32(c1), axis=-1))
    assert is0.mean() == pytest.approx(0.3, abs=1.0 / 500 * 2)
    assert abs(int(np.sum(is0[1:] != is0[:-1])) - 10) <= 1


@pytest.mark.parametrize("kind", T.KINDS)
def test_shape_dtype_range(kind):
    for seed in range(8):
        p = _params(kind, seed)
        assert p["kind"] == kind and isinstance(p["seed"], int)
        for size in (1, 37, 128):
            img = T.make_texture(p, size)
            assert img.shape == (size, size, 3) and img.dtype == np.float32
            assert np.all(np.isfinite(img)) and img.min() >= 0.0 and img.max() <= 1.0
        # sampled colours are albedos in [0.05, 0.9]; every pixel stays in that range too
        cols = np.asarray(p["colors"])
        assert cols.shape[1] == 3 and cols.min() >= T.ALBEDO_MIN and cols.max() <= T.ALBEDO_MAX
        assert img.min() >= T.ALBEDO_MIN - 1e-6 and img.max() <= T.ALBEDO_MAX + 1e-6


@pytest.mark.parametrize("kind", T.KINDS)
def test_deterministic_and_json_roundtrip(kind):
    p = _params(kind, 7)
    assert p == _params(kind, 7)
    q = json.loads(json.dumps(p))
    a, b = T.make_texture(p, 96), T.make_texture(q, 96)
    assert a.tobytes() == b.tobytes()
    assert T.make_texture(p, 96).tobytes() == a.tobytes()


@pytest.mark.parametrize("kind", T.KINDS)
def test_different_seeds_differ(kind):
    imgs = [T.make_texture(_params(kind, s), 64) for s in range(5)]
    for i in range(5):
        for j in range(i + 1, 5):
            assert not np.array_equal(imgs[i], imgs[j]), (i, j)


@pytest.mark.parametrize("kind", SEED_DEPENDENT)
def test_seed_alone_changes_output(kind):
    p = _params(kind, 3)
    q = dict(p, seed=p["seed"] + 1)
    assert not np.array_equal(T.make_texture(p, 64), T.make_texture(q, 64))


@pytest.mark.parametrize("kind", T.KINDS)
def test_nontrivial_variance_and_low_frequency(kind):
    rng = np.random.default_rng(0)
    for seed in range(20):
        img = T.make_texture(_params(kind, seed), 256).astype(np.float64)
        assert img.std(axis=(0, 1)).max() > 0.02, seed
        # not per-pixel noise: neighbours are much more alike than random pixel pairs
        flat = img.reshape(-1, 3)
        far = np.abs(flat[rng.integers(0, len(flat), 4000)] - flat[rng.integers(0, len(flat), 4000)]).mean()
        near = 0.5 * (np.abs(np.diff(img, axis=0)).mean() + np.abs(np.diff(img, axis=1)).mean())
        assert near < 0.4 * far, (seed, near, far)


def test_kind_none_covers_all_kinds():
    rng = np.random.default_rng(1)
    kinds = {T.sample_texture_params(rng)["kind"] for _ in range(200)}
    assert kinds == set(T.KINDS)


def test_closed_form_checker_and_gradient():
    p = {"kind": "checker", "seed": 0, "cells": 4, "angle": 0.0, "colors": [[0.1, 0.2, 0.3], [0.8, 0.7, 0.6]]}
    img = T.make_texture(p, 64)
    colours = {tuple(c) for c in img.reshape(-1, 3).tolist()}
    assert len(colours) == 2  # exactly the two colours, in about equal amounts
    assert abs(np.mean(img[..., 0] == np.float32(0.1)) - 0.5) < 0.1
    g = {"kind": "gradient", "seed": 0, "mode": "linear", "angle": 0.0, "center": [0.5, 0.5],
         "colors": [[0.1, 0.1, 0.1], [0.9, 0.9, 0.9]]}
    img = T.make_texture(g, 32)
    assert np.all(np.diff(img[0, :, 0]) > 0) and np.all(img[:, 5, 0] == img[0, 5, 0])
    assert img[0, 0, 0] == pytest.approx(0.1, abs=0.02) and img[0, -1, 0] == pytest.approx(0.9, abs=0.02)


def test_closed_form_tiles_and_dots():
    # tiles 4 x 4, grout 0.1 of a cell in x and y, no offset: grout covers 1 - 0.9^2 = 19%;
    # at 400 px a cell is 100 px and its grout band exactly 10 px, so the count is exact
    grout, tile = [0.05, 0.05, 0.05], [0.6, 0.6, 0.6]
    p = {"kind": "tiles", "seed": 1, "rows": 4, "cols": 4, "offset": 0.0, "grout": 0.1,
         "variation": 0.0, "colors": [grout, tile]}
    img = T.make_texture(p, 400)
    is_grout = np.all(img == np.float32(grout), axis=-1)
    assert is_grout.mean() == pytest.approx(0.19, abs=1e-12)
    assert np.all(is_grout[:10, :]) and not np.any(is_grout[10:100, 10:100])
    # dots 4 x 4 without jitter, radius 0.3 of a cell: one centred disc per cell covers pi 0.3^2
    q = {"kind": "dots", "seed": 1, "cells": 4, "radius": 0.3, "jitter": 0.0,
         "colors": [[0.1, 0.1, 0.1], [0.8, 0.2, 0.2]]}
    img = T.make_texture(q, 400)
    dot = np.all(img == np.float32([0.8, 0.2, 0.2]), axis=-1)
    assert dot.mean() == pytest.approx(math.pi * 0.09, rel=0.01)
    assert dot[50, 50] and dot[150, 250] and not dot[0, 0] and not dot[100, 100]


@pytest.mark.parametrize("params,size,match", [
    ({"kind": "plaid", "seed": 0}, 32, "expected one of"),
    ({"seed": 0}, 32, "expected one of"),
    ({"kind": "checker", "seed": -1, "cells": 4, "angle": 0, "colors": [[0.1] * 3, [0.5] * 3]}, 32, "seed"),
    ({"kind": "checker", "seed": 0, "cells": 4, "angle": 0, "colors": [[0.1] * 3, [1.5] * 3]}, 32, "colors"),
    ({"kind": "checker", "seed": 0, "angle": 0, "colors": [[0.1] * 3, [0.5] * 3]}, 32, "cells"),
    ({"kind": "gradient", "seed": 0, "mode": "spiral", "angle": 0, "colors": [[0.1] * 3, [0.5] * 3]},
     32, "mode"),
    ({"kind": "checker", "seed": 0, "cells": 4, "angle": 0, "colors": [[0.1] * 3, [0.5] * 3]}, 0, "size"),
])
def test_bad_input_raises(params, size, match):
    with pytest.raises(ValueError, match=match):
        T.make_texture(params, size)


def test_sample_unknown_kind_lists_kinds():
    with pytest.raises(ValueError, match="checker"):
        T.sample_texture_params(np.random.default_rng(0), "plaid")
