"""Render noise: which Mitsuba sampler, and how many samples per pixel reach a target.

What a user of the generator cares about is the time to an image of a given noise,
not the samples per pixel. Noise is measured as the *relative RMSE* of a render
against a converged reference of the same scene (same sampler seed rules):

    rel_rmse = sqrt(mean((image - reference)^2)) / mean(reference)

over all pixels and channels (:func:`relative_rmse`).

:data:`CALIBRATION` holds the relative RMSE of each sampler at each sample count,
measured by ``benchmarks/bench_generate.py --calibrate`` on the 8 fixed default
scenes it renders (128 px, path depth 4, 4096-spp references). Stratified samplers
beat ``independent`` by far at equal time: ``multijitter`` at 16 spp (0.0170) is less
noisy than ``independent`` at 64 spp (0.0217, relight's former default), at about a
quarter of the samples and a third of the render time; it is the generator's default,
and the default target (2%) gives it 16 spp. Sample counts listed per sampler are those it takes exactly
(Mitsuba rounds others: ``stratified`` and ``ldsampler`` want squares / powers of
two, ``multijitter`` a product of two close integers).
"""
from __future__ import annotations

__all__ = [
    "DEFAULT_SAMPLER", "DEFAULT_TARGET_RMSE", "CALIBRATION", "relative_rmse", "spp_for_target",
]

import numpy as np

DEFAULT_SAMPLER = "multijitter"
DEFAULT_TARGET_RMSE = 0.02    # 2%: the noise of the former default (independent, 64 spp)

# sampler -> ((spp, relative RMSE), ...), ascending spp. 128 px default scenes.
CALIBRATION: dict[str, tuple[tuple[int, float], ...]] = {
    "independent": ((4, 0.0853), (8, 0.0601), (16, 0.0427), (32, 0.0300), (64, 0.0217), (128, 0.0153),
                    (256, 0.0110)),
    "multijitter": ((4, 0.0502), (8, 0.0294), (12, 0.0213), (16, 0.0170), (25, 0.0130), (36, 0.0104),
                    (64, 0.0075), (100, 0.0060), (144, 0.0051), (256, 0.0042)),
}


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    """RMSE of ``image`` against ``reference`` over the mean of the reference."""
    image = np.asarray(image, np.float64)
    reference = np.asarray(reference, np.float64)
    if image.shape != reference.shape:
        raise ValueError(f"shapes differ: {image.shape} vs {reference.shape}")
    mean = float(np.mean(reference))
    if not mean > 0:
        raise ValueError("reference image is black")
    return float(np.sqrt(np.mean((image - reference) ** 2)) / mean)


def spp_for_target(target_rmse: float, sampler: str = DEFAULT_SAMPLER) -> int:
    """The smallest calibrated sample count of ``sampler`` whose measured relative
    RMSE is at most ``target_rmse`` (ValueError when no calibrated count reaches it)."""
    if sampler not in CALIBRATION:
        raise ValueError(f"no noise calibration for sampler {sampler!r}; give --spp instead "
                         f"(calibrated: {', '.join(CALIBRATION)})")
    if not (target_rmse > 0 and np.isfinite(target_rmse)):
        raise ValueError(f"target relative RMSE must be a positive number, got {target_rmse!r}")
    for spp, rmse in CALIBRATION[sampler]:
        if rmse <= target_rmse:
            return spp
    best_spp, best = CALIBRATION[sampler][-1]
    raise ValueError(f"target relative RMSE {target_rmse} is below what {sampler} reaches at "
                     f"{best_spp} spp ({best}); give --spp instead")

