"""The ideal observer behind the colour target's evidence (README "Multi-coloured
objects"): the closed-form density of a surface's colour direction under a light,
against Monte Carlo, and the Bayes floor falling as surfaces are added."""
import numpy as np

from relight.scene.albedo import OBJECT_RANGE, box_direction_logpdf


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def test_box_direction_density_matches_monte_carlo():
    # the fraction of directions of a * l (a uniform in the box) inside a small cone
    # around u0 is proportional to the density at u0: the ratio between two lights must
    # match the closed form's (measured 0.694 vs 0.691 with 4e6 draws; here 1e6)
    rng = np.random.default_rng(0)
    lo, hi = OBJECT_RANGE
    warm, cool = _unit([1.0, 0.8, 0.5]), _unit([0.6, 0.8, 1.0])
    u0 = _unit([0.5, 0.55, 0.5])
    a = rng.uniform(lo, hi, (1_000_000, 3))
    frac = []
    for light in (warm, cool):
        c = a * light
        u = c / np.linalg.norm(c, axis=1, keepdims=True)
        frac.append(np.mean(u @ u0 > np.cos(np.radians(2.5))))
    dens = np.exp(box_direction_logpdf(u0[None], np.stack([warm, cool]), lo, hi))[0]
    assert min(frac) > 1e-3                                  # thousands of draws in each cone
    assert abs(frac[0] / frac[1] - dens[0] / dens[1]) < 0.04 * (dens[0] / dens[1])
    # a direction no box albedo can produce under the light has (near) zero density
    assert box_direction_logpdf(_unit([1.0, 0.01, 0.01])[None], warm[None], lo, hi)[0, 0] < -50


def test_bayes_floor_falls_with_more_surfaces():
    from relight.colour import sample_light_colour
    from relight.metrics import colour_error_deg
    rng = np.random.default_rng(1)
    cands = np.array([sample_light_colour(rng)[2] for _ in range(1500)])
    lo, hi = OBJECT_RANGE

    def floor(n, draws=60):
        errs = []
        for _ in range(draws):
            light = sample_light_colour(rng)[2]
            c = rng.uniform(lo, hi, (n, 3)) * light
            logp = box_direction_logpdf(c / np.linalg.norm(c, axis=1, keepdims=True), cands, lo, hi).sum(0)
            w = np.exp(logp - logp.max())
            errs.append(float(colour_error_deg((w[:, None] * cands).sum(0), light)))
        return np.mean(errs)
    few, many = floor(2), floor(60)
    # README table: 1 surface 8.35, 3 surfaces 5.26, 30 surfaces 2.26, 100 surfaces 1.28
    assert 3.5 < few < 9.0 and many < 2.5 and many < 0.5 * few, (few, many)
