"""Recover a point light's direction and colour from one image whose scene is known.

Analysis by synthesis: render the known scene under a candidate light through a
loaded :class:`~relight.scene.build.SceneTemplate` (the scene is never rebuilt per
step, only ``light.position`` / ``light.intensity`` change) and minimise the relative
squared error to the target image, in linear RGB.

Colour (closed form). The render is linear in the light's RGB radiant intensity, so
for a fixed direction the best colour is per-channel least squares against a render
``R`` under unit white light: ``k_c = <I_c, R_c> / <R_c, R_c>``; the light colour is
``k / |k|``. The direction problem is therefore 2-D (3-D with ``fit_radius``): the
*variable-projection* residual ``r(x) = (I - k(x) * R(x)) / |I|``, loss ``|r|^2``.

Direction gradient (the estimator, chosen with evidence). Mitsuba 3.9 registers a
point light's ``position`` as non-differentiable: the ``path``/``direct``
integrators return only the shading term of d(image)/d(position), about 0.22-0.24 of
the finite-difference value once a cast shadow moves (issue 5 measurements; reproduced
by ``benchmarks/bench_inverse.py``), projective integrators return 0 or refuse, and a
projective area-light substitute costs ~100 s per gradient. Shadows are the strongest
direction cue in our scenes, so a shading-only gradient is biased exactly where it
matters. We therefore use **central finite differences with common random numbers**
(the ``+h`` and ``-h`` renders use the same sampler seed as the centre, so the noise
largely cancels and the estimate includes shadow-edge terms), taken in local
tangent-plane coordinates of the light direction (arc steps along pan and along tilt,
in degrees, so the zenith is not singular). The FD Jacobian of the residual feeds a
Levenberg-Marquardt step; each level keeps its sampler seed fixed, so the objective is
deterministic and accepted steps always lower it. Cost: 4 renders per Jacobian (6 with
the radius) + 1 per trial step, at 32-64 px and 8-32 samples per pixel.
``InvertConfig(gradient="ad")`` (``relight invert --gradient ad``) builds the same
Jacobian by automatic differentiation instead, the shadow-edge term included
(:mod:`relight.inverse.ad`); ``benchmarks/bench_gradients.py`` compares the estimators.
Measured by the benchmark (3-6 images of 128 px scenes, 5 deg off the light, against a
64 px / 512 spp / h = 0.25 deg reference): the coarse-level FD gradient is within
~4-8 deg of the reference direction with a magnitude ratio ~1.0; Mitsuba's
shading-only AD gradient has ratio ~0.87 there (down to ~0.5 on 32 px scenes with
large shadows) and costs about twice an FD gradient. Low sample counts also bias the
*loss* (its noise variance depends on the light), so the fine level uses 32 spp.

Live Mitsuba scenes slow every render (Dr.Jit's virtual-call tables grow with each
loaded scene), so callers inverting many images should pass a fresh
:class:`SceneBuilder` per image (``relight invert`` does).

Coarse to fine: a grid of pan/tilt candidates at 32 px / few samples (``init="grid"``)
or a given start (network prediction, predictions file), then LM at each
:class:`Level` (coarse: large FD step, small image; fine: 0.5 deg step, 64 px), and a
final colour fit at more samples. Stops by step tolerance, iteration cap or time budget.

Units: degrees for angles (pan relative to the camera, 0 = front, 90 = camera's right;
tilt = elevation), metres for the radius, seconds for time.
"""
from __future__ import annotations

__all__ = [
    "Level", "GRADIENTS", "MAX_REJECTIONS", "DEFAULT_LEVELS", "InvertConfig", "InverseResult", "fit_to_image",
    "grid_starts", "pick_starts", "invert", "shading_ad_loss_gradient",
]

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from relight import frames, metrics
from relight.scene.spec import SceneSpec
from relight.errors import InverseError
from relight.inverse.objective import LightRenderer, colour_fit, downsample, jacobian, moved, residual


@dataclass(frozen=True)
class Level:
    """One resolution level of the descent.

    res: render size in pixels (must divide the target image size);
    spp: samples per pixel; fd_step_deg: central-difference half-step (arc degrees);
    max_step_deg: largest accepted LM step (arc degrees); max_iters: LM iterations;
    tol_deg: an accepted step shorter than this ends the level.
    """
    res: int
    spp: int
    fd_step_deg: float
    max_step_deg: float
    max_iters: int
    tol_deg: float

    def __post_init__(self):
        if self.res < 4 or self.spp < 1 or self.max_iters < 0:
            raise InverseError(f"level: res >= 4, spp >= 1, max_iters >= 0 expected, got {self}")
        if not (self.fd_step_deg > 0 and self.max_step_deg > 0 and self.tol_deg > 0):
            raise InverseError(f"level: positive fd_step_deg, max_step_deg, tol_deg expected, got {self}")


# central finite differences; automatic differentiation with shadow edges (relight.inverse.ad);
# "ad-shading": AD without the shadow-edge term (biased; kept for the gradient benchmark)
GRADIENTS = ("fd", "ad", "ad-shading")
MAX_REJECTIONS = 4  # trial steps per LM iteration before the level gives up (1 render each)

DEFAULT_LEVELS = (
    Level(res=32, spp=8, fd_step_deg=2.0, max_step_deg=15.0, max_iters=12, tol_deg=0.3),
    Level(res=64, spp=32, fd_step_deg=0.5, max_step_deg=3.0, max_iters=8, tol_deg=0.05),
)


@dataclass(frozen=True)
class InvertConfig:
    """Settings of :func:`invert` (see the module docstring).

    grid_*: the coarse search of ``init="grid"`` (pan_rel every ``grid_pan_step_deg``
    at each of ``grid_tilts_deg``, plus the zenith), rendered at ``grid_res`` /
    ``grid_spp``; the ``grid_keep`` best start the first level. ``max_iters`` caps LM
    iterations over all levels and starts; ``time_budget_s`` caps wall time per image
    (checked between iterations). Extra grid starts must lie ``grid_separation_deg``
    from each other and have a grid loss within ``grid_loss_factor`` of the best.
    ``colour_spp``: samples of the final colour render (at the last level's
    resolution). ``fit_radius``: also fit the light distance.
    """
    levels: tuple[Level, ...] = DEFAULT_LEVELS
    grid_res: int = 32
    grid_spp: int = 4
    grid_pan_step_deg: float = 30.0
    grid_tilts_deg: tuple[float, ...] = (35.0, 50.0, 65.0, 80.0)
    grid_keep: int = 3
    grid_separation_deg: float = 45.0
    grid_loss_factor: float = 2.0
    max_iters: int = 60
    time_budget_s: float = 60.0
    colour_spp: int = 64
    fit_radius: bool = False
    radius_fd_step: float = 0.03     # relative
    seed: int = 1
    gradient: str = "fd"             # Jacobian estimator: "fd" or "ad" (relight.inverse.ad)

    def __post_init__(self):
        if not self.levels:
            raise InverseError("at least one level is needed")
        if self.max_iters < 0 or self.time_budget_s <= 0 or self.grid_keep < 1:
            raise InverseError("max_iters >= 0, time_budget_s > 0 and grid_keep >= 1 expected")
        if not 0 < self.grid_pan_step_deg <= 180:
            raise InverseError(f"grid_pan_step_deg must be in (0, 180], got {self.grid_pan_step_deg}")
        if self.gradient not in GRADIENTS:
            raise InverseError(f"gradient must be one of {', '.join(GRADIENTS)}, got {self.gradient!r}")


@dataclass
class InverseResult:
    """What :func:`invert` found for one image."""
    pan_rel_deg: float
    tilt_deg: float
    r_m: float
    rgb: np.ndarray              # unit norm, linear
    loss: float                  # relative squared error at the last level
    iterations: int              # LM iterations (all starts and levels)
    renders: int                 # every render, grid and colour included
    seconds: float
    stopped: str                 # "converged" (every level ended by its tolerance, its own
                                 # cap or no better step), "max_iters" or "time_budget"
    trace: list = field(default_factory=list)

    def entry(self, image_id: str) -> dict:
        """A ``relight.predictions/v1`` entry (plus the cost figures)."""
        return {"id": image_id, "pan_deg": float(self.pan_rel_deg), "tilt_deg": float(self.tilt_deg),
                "rgb": [float(c) for c in self.rgb], "r_m": float(self.r_m), "loss": float(self.loss),
                "iterations": self.iterations, "renders": self.renders,
                "seconds": round(self.seconds, 3), "stopped": self.stopped}


# --- the optimiser -------------------------------------------------------------------

@dataclass
class _State:
    pan: float
    tilt: float
    r: float
    loss: float = float("inf")
    k: np.ndarray = field(default_factory=lambda: np.ones(3))


class _Run:
    """Book-keeping of one :func:`invert` call: budget, counters, trace."""

    def __init__(self, renderer: LightRenderer, target: np.ndarray, cfg: InvertConfig, t0: float):
        self.renderer, self.cfg, self.t0 = renderer, cfg, t0
        self.target_full = np.asarray(target, dtype=np.float64)
        self._targets: dict[int, np.ndarray] = {}
        self.iterations = 0
        self.trace: list[dict] = []
        self.stopped = "converged"
        self.ad = None
        if cfg.gradient != "fd":
            from relight.inverse.ad import ADJacobian, ADSettings
            self.ad = ADJacobian(renderer, ADSettings(visibility=cfg.gradient == "ad"))

    def target(self, res: int) -> np.ndarray:
        if res not in self._targets:
            self._targets[res] = downsample(self.target_full, res)
        return self._targets[res]

    def out_of_budget(self) -> bool:
        if self.iterations >= self.cfg.max_iters:
            self.stopped = "max_iters"
            return True
        if time.perf_counter() - self.t0 >= self.cfg.time_budget_s:
            self.stopped = "time_budget"
            return True
        return False

    def residual(self, s: _State, res: int, spp: int, seed: int) -> tuple[np.ndarray, float, np.ndarray]:
        return residual(self.renderer, self.target(res), s.pan, s.tilt, s.r, spp, seed)

    def log(self, stage: str, s: _State, start: int = 0) -> None:
        k = s.k / (np.linalg.norm(s.k) or 1.0)
        self.trace.append({"iteration": self.iterations, "stage": stage, "start": start,
                           "loss": s.loss, "pan_deg": s.pan, "tilt_deg": s.tilt, "r_m": s.r,
                           "rgb": [float(c) for c in k], "renders": self.renderer.renders,
                           "seconds": round(time.perf_counter() - self.t0, 4)})

    def moved(self, s: _State, delta: np.ndarray) -> _State:
        return _State(*moved(s.pan, s.tilt, s.r, delta))

    def descend(self, s: _State, level: Level, seed: int, stage: str, start: int = 0) -> _State:
        """Levenberg-Marquardt with a central-difference (common random numbers) Jacobian."""
        n_par = 3 if self.cfg.fit_radius else 2
        steps = np.array([level.fd_step_deg, level.fd_step_deg, self.cfg.radius_fd_step][:n_par])
        res_vec, s.loss, s.k = self.residual(s, level.res, level.spp, seed)
        self.log(stage, s, start)
        lam = 1e-3
        for _ in range(level.max_iters):
            if self.out_of_budget():
                break
            self.iterations += 1
            if self.ad is not None:
                jac = self.ad.residual_jacobian(self.target(level.res), s.pan, s.tilt, s.r, level.spp, seed, n_par)
            else:
                jac = jacobian(self.renderer, self.target(level.res), s.pan, s.tilt, s.r, level.spp, seed, steps)
            jtj, grad = jac.T @ jac, jac.T @ res_vec
            accepted = False
            for _ in range(MAX_REJECTIONS):
                delta = -np.linalg.solve(jtj + lam * (np.diag(np.diag(jtj)) + 1e-12 * np.eye(n_par)), grad)
                arc = float(np.hypot(delta[0], delta[1]))
                if arc > level.max_step_deg:
                    delta *= level.max_step_deg / arc
                    arc = level.max_step_deg
                trial = self.moved(s, delta)
                trial_vec, trial.loss, trial.k = self.residual(trial, level.res, level.spp, seed)
                if trial.loss < s.loss:
                    s, res_vec, accepted = trial, trial_vec, True
                    lam = max(lam / 3.0, 1e-7)
                    break
                lam *= 4.0
            self.log(stage, s, start)
            if not accepted or arc < level.tol_deg:
                break
        return s


def fit_to_image(cfg: InvertConfig, image_res: int) -> InvertConfig:
    """``cfg`` with every render size capped at the image size (a 32 px image is
    fitted at 32 px at every level)."""
    if image_res < 4:
        raise InverseError(f"expected a square (H, H, 3) image of at least 4 px, got size {image_res}")
    levels = tuple(dataclasses.replace(lv, res=min(lv.res, image_res)) for lv in cfg.levels)
    return dataclasses.replace(cfg, levels=levels, grid_res=min(cfg.grid_res, image_res))


def grid_starts(cfg: InvertConfig) -> list[tuple[float, float]]:
    """(pan_rel_deg, tilt_deg) candidates of the coarse search, zenith last."""
    pans = np.arange(0.0, 360.0, cfg.grid_pan_step_deg)
    return [(float(p), float(t)) for t in cfg.grid_tilts_deg for p in pans] + [(0.0, 90.0)]


def pick_starts(scored, cfg: InvertConfig) -> list[tuple[float, float]]:
    """The best grid candidates, ``scored`` sorted by loss as ``(loss, pan, tilt, ...)``:
    at most ``grid_keep``, each at least ``grid_separation_deg`` from the ones kept (other
    basins, not neighbours of the best) and with a loss within ``grid_loss_factor`` of
    the best (a clear winner is descended alone)."""
    kept = []
    for loss, pan, tilt, *_ in scored:
        if len(kept) == cfg.grid_keep or loss > cfg.grid_loss_factor * scored[0][0]:
            break
        d = frames.direction(pan, tilt)
        if all(metrics.angle_deg(d, frames.direction(p, t)) >= cfg.grid_separation_deg
               for p, t in kept):
            kept.append((pan, tilt))
    return kept


def invert(spec: SceneSpec, image: np.ndarray, init=None, cfg: InvertConfig | None = None,
           builder=None) -> InverseResult:
    """Recover the light of ``image`` (linear ``(H, H, 3)``) rendered from ``spec``'s scene.

    Args:
        spec: the scene (geometry, materials, camera; its light radius starts the fit,
            its light direction and colour are NOT used).
        image: the target, linear RGB; H a multiple of every level's resolution.
        init: ``None`` / ``"grid"`` for the coarse search, or a ``(pan_rel_deg,
            tilt_deg)`` start (e.g. a network prediction).
        cfg: settings; ``builder``: a shared :class:`SceneBuilder` (optional).

    Returns:
        An :class:`InverseResult`: the light's ``pan_rel_deg`` (relative to the camera),
        ``tilt_deg``, distance ``r_m``, linear unit-norm ``rgb``, the final relative loss,
        and what it cost (iterations, renders, seconds, why it stopped).

    The example scene's light (pan_rel 90, tilt 30) found again from 14 degrees away:

    >>> import os, relight
    >>> spec = relight.load_scene(os.path.join(os.path.dirname(relight.__file__), "..", "scenes",
    ...                                        "sphere_right.json"))
    >>> spec = dataclasses.replace(spec, render=dataclasses.replace(spec.render, res=32, spp=8))
    >>> cfg = InvertConfig(levels=(Level(res=32, spp=8, fd_step_deg=2.0, max_step_deg=15.0, max_iters=6,
    ...                                  tol_deg=0.3),), colour_spp=8)
    >>> found = invert(spec, relight.render_spec(spec), init=(80.0, 40.0), cfg=cfg)
    >>> abs(found.pan_rel_deg - 90.0) < 1.0, abs(found.tilt_deg - 30.0) < 1.0, found.stopped
    (True, True, 'converged')
    """
    cfg = fit_to_image(cfg or InvertConfig(), np.shape(image)[0] if np.ndim(image) == 3 else 0)
    t0 = time.perf_counter()
    renderer = LightRenderer(spec, builder)
    run = _Run(renderer, image, cfg, t0)
    for lv in cfg.levels:
        run.target(lv.res)  # validates sizes before any work
    r0 = spec.light.r_m
    first = cfg.levels[0]
    if init is None or isinstance(init, str):
        if init not in (None, "grid"):
            raise InverseError(f"init must be 'grid' or a (pan_rel_deg, tilt_deg) pair, got {init!r}")
        target = run.target(cfg.grid_res)
        scored = []
        for pan, tilt in grid_starts(cfg):
            render = renderer.image(pan, tilt, r0, cfg.grid_res, cfg.grid_spp, cfg.seed)
            k, loss = colour_fit(target, render)
            scored.append((loss, pan, tilt, k))
        scored.sort(key=lambda x: x[0])
        best = _State(scored[0][1], scored[0][2], r0, scored[0][0], scored[0][3])
        run.log("grid", best)
        starts = [_State(p, t, r0) for p, t in pick_starts(scored, cfg)]
    else:
        pan, tilt = (float(v) for v in init)
        if not (math.isfinite(pan) and math.isfinite(tilt)):
            raise InverseError(f"init direction must be finite, got {init!r}")
        starts = [_State(float(frames.wrap360(pan)), float(np.clip(tilt, -90.0, 90.0)), r0)]
    ends = [run.descend(s, first, cfg.seed, "L0", i) for i, s in enumerate(starts)]
    s = min(ends, key=lambda e: e.loss)
    for n, lv in enumerate(cfg.levels[1:], start=1):
        if run.out_of_budget():
            break
        s = run.descend(s, lv, cfg.seed + n, f"L{n}")
    # final colour: more samples at the last level's size, same direction
    last = cfg.levels[-1]
    _, loss, k = run.residual(s, last.res, cfg.colour_spp, cfg.seed + 100)
    s.loss, s.k = loss, k
    run.log("colour", s)
    norm = np.linalg.norm(k)
    if not norm > 0:
        raise InverseError("the fitted light colour is zero: the scene looks unlit at this direction")
    return InverseResult(pan_rel_deg=float(frames.wrap360(s.pan)), tilt_deg=s.tilt, r_m=s.r,
                         rgb=k / norm, loss=loss, iterations=run.iterations,
                         renders=renderer.renders, seconds=time.perf_counter() - t0,
                         stopped=run.stopped, trace=run.trace)


def shading_ad_loss_gradient(renderer: LightRenderer, target: np.ndarray, pan_rel_deg: float, tilt_deg: float,
                     r_m: float, spp: int, seed: int) -> tuple[float, np.ndarray]:
    """The alternative estimator, kept for the benchmark: Mitsuba's automatic gradient of
    the same loss per arc degree along (pan, tilt), through ``light.position`` (grad
    enabled on the parameter itself). It holds the shading term only: shadow-edge
    (visibility) terms are missing, hence biased wherever a cast shadow moves. ``k`` is
    held at its closed form (envelope theorem: its own derivative term vanishes)."""
    from relight import backend
    mi, dr = backend.mitsuba(), backend.drjit()
    res = target.shape[0]
    k, loss = colour_fit(target, renderer.image(pan_rel_deg, tilt_deg, r_m, res, spp, seed))
    tpl = renderer.template(res)
    position = tpl.params["light.position"]
    dr.enable_grad(position)
    tpl.params.update()
    image = mi.render(tpl.scene, tpl.params, spp=int(spp), seed=int(seed), seed_grad=int(seed) + 1)
    renderer.renders += 1
    t = np.asarray(target, dtype=np.float32)
    residual_img = mi.TensorXf(t) - mi.TensorXf(np.broadcast_to(k.astype(np.float32), t.shape).copy()) * image
    dr.backward(dr.sum(dr.square(residual_img), axis=None) / float(np.sum(t.astype(np.float64) ** 2)))
    grad_position = np.array(dr.grad(position), dtype=np.float64).ravel()
    dr.disable_grad(position)
    e_pan, e_tilt = frames.tangent_basis(frames.pan_from_rel(pan_rel_deg, renderer.spec.camera.pan_deg), tilt_deg)
    per_deg = r_m * math.pi / 180.0  # metres of light travel per arc degree
    return loss, np.array([grad_position @ e_pan, grad_position @ e_tilt]) * per_deg
