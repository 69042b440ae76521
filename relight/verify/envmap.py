"""Environment maps as light predictions: read and check a map, its dominant light, a
map made from a point light, and the two converters of ``relight envmap``.

A map is an equirectangular ``(H, W, 3)`` linear-RGB radiance image, ``W == 2 H``, in
the frame of docs/conventions.md ("Environment-map predictions"; the geometry lives in
:mod:`relight.frames`). Radiance units: a map made by :func:`disc_envmap` from a scene's
light gives the scene centre the irradiance the point light gives it, so it re-renders
at the dataset's exposure.

**Dominant light** (:func:`dominant_light`):

1. luminous power per pixel: Rec.709 luminance x the pixel's solid angle, summed into
   blocks (the map reduced by an integer factor to at most 64 x 32 blocks);
2. blur: each block gets the power inside the 10-degree cap around its centre (a box
   blur on the sphere);
3. brightest region: the connected blocks (periodic in u) whose blurred power is at
   least half the maximum, around the maximum;
4. direction: the power-weighted mean direction of the full-resolution pixels of that
   region (its centroid), normalised; colour: their solid-angle weighted mean RGB, unit
   norm; ``share``: the region's part of the map's luminous power.

A disc (a distant point light) gives its own centre and colour; a blurred light gives
the centre of its plateau.
"""
from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass

import numpy as np

from relight import colour, frames
from relight.errors import ImageError, PredictionsError

__all__ = [
    "DOMINANT_BLUR_DEG",
    "DOMINANT_COARSE_HEIGHT",
    "DOMINANT_REGION_FRACTION",
    "MIN_HEIGHT",
    "MAX_PIXELS",
    "DEFAULT_WIDTH",
    "DISC_RADIUS_PX",
    "MIN_DISC_RADIUS_DEG",
    "DISC_SUPERSAMPLE",
    "LUMINANCE",
    "EnvmapError",
    "check_envmap",
    "read_envmap",
    "write_envmap",
    "mitsuba_layout",
    "DominantLight",
    "dominant_light",
    "irradiance_rgb",
    "disc_radius_deg",
    "disc_envmap",
    "rotate_envmap",
    "blur_envmap",
    "envmap_light",
    "light_envmap",
    "from_light",
    "to_light",
]

DOMINANT_BLUR_DEG = 10.0         # the blur: luminous power in caps of this radius
DOMINANT_COARSE_HEIGHT = 32      # ... on the map summed into <= 64 x 32 blocks
DOMINANT_REGION_FRACTION = 0.5   # brightest region: blurred power >= this x its maximum
MIN_HEIGHT = 4                   # the smallest map: 8 x 4 pixels
MAX_PIXELS = 16384 * 8192        # the largest map read (also imageio's own limit applies)
DEFAULT_WIDTH = 256              # maps written by ``relight envmap from-light``
DISC_RADIUS_PX = 1.5             # disc radius in pixel widths ...
MIN_DISC_RADIUS_DEG = 1.0        # ... but never smaller than this
DISC_SUPERSAMPLE = 4             # per-axis coverage samples of a disc's edge pixels
LUMINANCE = colour.REC709_LUMA   # Rec.709 / sRGB primaries (relight.colour owns the weights)


class EnvmapError(ImageError):
    """An environment map cannot be used (one line naming the file)."""


# --- reading and checking --------------------------------------------------------------

def check_envmap(image: np.ndarray, name: str) -> np.ndarray:
    """``image`` as float32 if it is a usable map, else :class:`EnvmapError` naming ``name``:
    ``(H, W, 3)`` with ``W == 2 H`` and ``H >= MIN_HEIGHT``, finite, non-negative, not all zero."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise EnvmapError(f"{name}: an environment map is (H, W, 3), got shape {img.shape}")
    h, w = img.shape[:2]
    if w != 2 * h:
        raise EnvmapError(f"{name}: an equirectangular map is twice as wide as high, got {w} x {h}")
    if h < MIN_HEIGHT:
        raise EnvmapError(f"{name}: map of {w} x {h} pixels is too small (at least "
                          f"{2 * MIN_HEIGHT} x {MIN_HEIGHT})")
    img = img.astype(np.float32)
    if not np.isfinite(img).all():
        raise EnvmapError(f"{name}: map holds NaN or infinite values")
    if (img < 0).any():
        raise EnvmapError(f"{name}: map holds negative radiance (min {float(img.min()):.4g})")
    if not (img > 0).any():
        raise EnvmapError(f"{name}: map is black everywhere (no light)")
    return img


def read_envmap(path: str | os.PathLike) -> np.ndarray:
    """Read and check an environment map (OpenEXR, linear RGB); one-line
    :class:`EnvmapError` naming the file for a missing, unreadable or unusable map."""
    from relight.imageio import read_exr
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise EnvmapError(f"environment map not found: {path}")
    with open(path, "rb") as f:
        magic = f.read(4)
    if magic != b"\x76\x2f\x31\x01":   # the OpenEXR magic number
        raise EnvmapError(f"{path}: not an OpenEXR file (an environment map must be a linear HDR EXR)")
    try:
        img = read_exr(path)
    except ImageError as exc:
        text = str(exc).splitlines()[0]
        if "NaN" in text:
            text = f"{path}: map holds NaN or infinite values"
        raise EnvmapError(text) from None
    if img.shape[0] * img.shape[1] > MAX_PIXELS:
        raise EnvmapError(f"{path}: map of {img.shape[1]} x {img.shape[0]} pixels is too large")
    return check_envmap(img, path)


def write_envmap(path: str | os.PathLike, image: np.ndarray, inputs=()) -> None:
    """Check and write a map as a float32 EXR, atomically."""
    from relight.imageio import write_exr
    write_exr(path, check_envmap(image, os.fspath(path)), inputs)


def mitsuba_layout(image: np.ndarray) -> np.ndarray:
    """The map resampled to the rows Mitsuba's ``envmap`` plugin reads: it puts row j at
    ``v = j / (H - 1)`` (the first and last rows on the poles; columns at ``(i + 0.5) / W``
    like ours), where our rows sit at ``v = (j + 0.5) / H``. Linear in v, at most half a
    row of shift; same shape."""
    img = np.asarray(image, np.float32)
    h = img.shape[0]
    y = np.arange(h) / (h - 1) * h - 0.5          # Mitsuba's rows in our row coordinates
    i0 = np.clip(np.floor(y).astype(int), 0, h - 1)
    i1 = np.clip(i0 + 1, 0, h - 1)
    f = np.clip(y - i0, 0.0, 1.0)[:, None, None].astype(np.float32)
    return np.ascontiguousarray((1 - f) * img[i0] + f * img[i1])


# --- analysis -------------------------------------------------------------------------

@dataclass(frozen=True)
class DominantLight:
    """The dominant light of a map: unit direction in the map's own frame, unit-norm
    linear RGB, and the share of the map's luminous power (luminance x solid angle) in
    its cap."""
    direction: tuple[float, float, float]
    rgb: tuple[float, float, float]
    share: float


def dominant_light(image: np.ndarray, blur_deg: float = DOMINANT_BLUR_DEG) -> DominantLight:
    """The dominant light of a checked map (module docstring: blur, brightest region,
    its centroid direction and mean colour)."""
    from scipy import ndimage
    img = np.asarray(image, np.float64)
    h, w = img.shape[:2]
    power = (img @ LUMINANCE) * frames.equirect_solid_angles(h, w)          # (h, w)
    f = _coarse_factor(h)
    ch, cw = h // f, w // f
    coarse = power.reshape(ch, f, cw, f).sum(axis=(1, 3))
    blurred = (_cap_matrix(ch, cw, float(blur_deg)) @ coarse.reshape(-1)).reshape(ch, cw)  # cap integrals
    labels, _ = ndimage.label(blurred >= DOMINANT_REGION_FRACTION * blurred.max())
    for row in range(ch):   # u is periodic: regions touching both sides are one
        a, b = labels[row, 0], labels[row, -1]
        if a and b and a != b:
            labels[labels == b] = a
    peak = np.unravel_index(int(np.argmax(blurred)), blurred.shape)
    region_c = labels == labels[peak]
    region = np.repeat(np.repeat(region_c, f, axis=0), f, axis=1)            # full resolution
    dirs = _pixel_directions(h, w)[region]
    centre = power[region] @ dirs
    centre = centre / np.linalg.norm(centre)
    omega = np.broadcast_to(frames.equirect_solid_angles(h, w), (h, w))[region]
    colour = omega @ img[region]
    colour = colour / np.linalg.norm(colour)
    share = float(power[region].sum() / power.sum())
    return DominantLight(tuple(float(c) for c in centre), tuple(float(c) for c in colour), share)


@functools.lru_cache(maxsize=8)
def _cap_matrix(height: int, width: int, radius_deg: float) -> np.ndarray:
    """``(n, n)`` float32: 1 where pixel centres of a ``height x width`` map are within
    ``radius_deg`` of each other."""
    dirs = frames.equirect_pixel_directions(height, width).reshape(-1, 3)
    return (dirs @ dirs.T >= math.cos(math.radians(radius_deg))).astype(np.float32)


@functools.lru_cache(maxsize=8)
def _pixel_directions(height: int, width: int) -> np.ndarray:
    return frames.equirect_pixel_directions(height, width)


def _coarse_factor(height: int) -> int:
    """The smallest divisor f of ``height`` with ``height / f <= DOMINANT_COARSE_HEIGHT``."""
    f = max(1, math.ceil(height / DOMINANT_COARSE_HEIGHT))
    while height % f:
        f += 1
    return f


def irradiance_rgb(image: np.ndarray, normal) -> np.ndarray:
    """Irradiance (per channel) the map gives a surface of unit ``normal`` (map frame):
    the sum of radiance x solid angle x max(0, cos)."""
    img = np.asarray(image, np.float64)
    h, w = img.shape[:2]
    cos = np.clip(frames.equirect_pixel_directions(h, w) @ np.asarray(normal, np.float64), 0.0, None)
    return np.einsum("hw,hwc->c", cos * frames.equirect_solid_angles(h, w), img)


# --- synthesis ------------------------------------------------------------------------

def disc_radius_deg(width: int) -> float:
    """Angular radius of a light's disc in a map ``width`` pixels wide."""
    return max(MIN_DISC_RADIUS_DEG, DISC_RADIUS_PX * 360.0 / width)


def disc_envmap(direction_map, irradiance_rgb_wm2, width: int = DEFAULT_WIDTH,
                radius_deg: float | None = None) -> np.ndarray:
    """A black map with one uniform disc: a distant light toward ``direction_map`` (map
    frame, any length) of angular radius ``radius_deg`` (default :func:`disc_radius_deg`)
    whose irradiance on a surface facing it is ``irradiance_rgb_wm2`` per channel.

    Edge pixels are weighted by the share of ``DISC_SUPERSAMPLE**2`` sub-pixel
    directions inside the disc; the radiance is then set so the map's irradiance
    toward the disc's centre equals the target exactly."""
    width = int(width)
    if width < 2 * MIN_HEIGHT or width % 2:
        raise ValueError(f"map width must be an even number >= {2 * MIN_HEIGHT}, got {width}")
    h = width // 2
    d = np.asarray(direction_map, np.float64)
    d = d / np.linalg.norm(d)
    radius_deg = disc_radius_deg(width) if radius_deg is None else float(radius_deg)
    cos_r = math.cos(math.radians(radius_deg))
    s = DISC_SUPERSAMPLE
    # only pixels whose centre is within the disc's radius + a pixel's diagonal can be covered
    near_cos = math.cos(min(math.pi, math.radians(radius_deg + 1.5 * 360.0 / width)))
    rows, cols = np.nonzero(_pixel_directions(h, width) @ d >= near_cos)
    offsets = (np.arange(s) + 0.5) / s
    u = (cols[:, None, None] + offsets[None, None, :]) / width          # (n, 1, s)
    v = (rows[:, None, None] + offsets[None, :, None]) / h              # (n, s, 1)
    sub = frames.equirect_to_direction(u, v)                            # (n, s, s, 3)
    coverage = np.zeros((h, width))
    coverage[rows, cols] = (sub @ d >= cos_r).mean(axis=(1, 2))
    target = np.asarray(irradiance_rgb_wm2, np.float64)
    img = coverage[..., None] * np.ones(3)
    e = irradiance_rgb(img, d)[0]
    if not e > 0:
        raise ValueError("the disc covers no pixel")
    return (img * (target / e)).astype(np.float32)


def rotate_envmap(image: np.ndarray, rotation) -> np.ndarray:
    """The map turned by the 3x3 ``rotation`` (map frame): a light at ``d`` moves to
    ``rotation @ d``. Bilinear resampling of the source (periodic in u)."""
    img = np.asarray(image, np.float32)
    h, w = img.shape[:2]
    src = frames.equirect_pixel_directions(h, w) @ np.asarray(rotation, np.float64)   # R^T d
    u, v = frames.direction_to_equirect(src)
    x, y = u * w - 0.5, np.clip(v * h - 0.5, 0.0, h - 1.0)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0m, x1m = x0 % w, (x0 + 1) % w
    y1 = np.minimum(y0 + 1, h - 1)
    return ((1 - fy) * ((1 - fx) * img[y0, x0m] + fx * img[y0, x1m])
            + fy * ((1 - fx) * img[y1, x0m] + fx * img[y1, x1m])).astype(np.float32)


def blur_envmap(image: np.ndarray, radius_deg: float) -> np.ndarray:
    """The map averaged over caps of ``radius_deg``: each pixel becomes the solid-angle
    weighted mean radiance of the source inside the cap around it (total power kept up
    to the cap's discretisation). Cost grows with the source's non-zero pixels."""
    img = np.asarray(image, np.float64)
    h, w = img.shape[:2]
    dirs = frames.equirect_pixel_directions(h, w).reshape(-1, 3)
    omega = np.broadcast_to(frames.equirect_solid_angles(h, w), (h, w)).reshape(-1)
    rgb = img.reshape(-1, 3)
    live = (rgb > 0).any(axis=1)
    cos_r = math.cos(math.radians(radius_deg))
    cap_omega = 2.0 * math.pi * (1.0 - cos_r)
    out = np.zeros_like(rgb)
    for start in range(0, len(dirs), 4096):
        near = (dirs[start:start + 4096] @ dirs[live].T) >= cos_r
        out[start:start + 4096] = (near * omega[live]) @ rgb[live] / cap_omega
    return out.reshape(h, w, 3).astype(np.float32)


# --- a map's light in a scene -----------------------------------------------------------

def envmap_light(image: np.ndarray, frame: str, camera_tilt_deg: float, camera_pan_deg: float = 0.0):
    """``(pan_rel_deg, tilt_deg, rgb unit, DominantLight)`` of a map's dominant light seen
    in a scene whose camera has the given tilt and pan (degrees)."""
    dom = dominant_light(image)
    world = frames.envmap_to_world(np.asarray(dom.direction), frame, camera_tilt_deg, camera_pan_deg)
    _, pan_deg, tilt_deg = frames.cartesian_to_spherical(world)
    pan_rel = float(frames.pan_rel_deg(float(pan_deg), camera_pan_deg))
    return pan_rel, float(tilt_deg), np.asarray(dom.rgb), dom


def light_envmap(spec, width: int = DEFAULT_WIDTH, frame: str = "camera",
                 pan_rel_deg: float | None = None, tilt_deg: float | None = None, rgb=None) -> np.ndarray:
    """The disc map of a scene's light (or of the given pan_rel/tilt/rgb at the scene
    light's strength) in the scene camera's frame (or ``world``): the irradiance
    at the scene centre equals the point light's (``strength * sqrt(3) * rgb``)."""
    light_spec = spec.with_light(pan_rel_deg, tilt_deg, rgb).light
    cam = spec.camera
    d_world = frames.direction(light_spec.pan_deg, light_spec.tilt_deg)
    d_map = frames.world_to_envmap(d_world, frame, cam.tilt_deg, cam.pan_deg)
    irradiance = light_spec.strength * math.sqrt(3.0) * np.asarray(light_spec.rgb)
    return disc_envmap(d_map, irradiance, width)


# --- the two converters ---------------------------------------------------------------

def from_light(predictions_path: str, data_dir: str | None, out_dir: str, width: int = DEFAULT_WIDTH,
               frame: str = "camera", progress: bool = True) -> int:
    """``relight envmap from-light``: one disc map per point-light entry, in the camera
    frame of that entry's scene (``OUTDIR/maps/ID.exr``), and ``OUTDIR/predictions.json``
    (v2) whose entries carry only the map. Written as one folder, atomically; returns the
    number of maps."""
    from tqdm import tqdm

    from relight.dataset import load_spec, read_manifest
    from relight.fileio import atomic_folder
    from relight.imageio import write_exr
    from relight.predictions import read_predictions, write_predictions
    from relight.predictions import resolve_dataset_dir
    if frame not in frames.ENVMAP_FRAMES:
        raise PredictionsError(f"frame must be one of {', '.join(frames.ENVMAP_FRAMES)}, got {frame!r}")
    pfile = read_predictions(predictions_path)
    dataset_dir = resolve_dataset_dir(predictions_path, data_dir, pfile.dataset)
    records = {r.get("id"): r for r in read_manifest(dataset_dir)}
    jobs = []
    for p in pfile.predictions:
        if not p.has_point_light:
            raise PredictionsError(f"{predictions_path}: entry {p.id!r}: no point light to convert")
        if p.id not in records:
            raise PredictionsError(f"{predictions_path}: entry {p.id!r}: id not in the manifest of {dataset_dir}")
        spec = load_spec(dataset_dir, records[p.id])
        pan, tilt, rgb = p.resolve(float(spec.camera.tilt_deg))
        jobs.append((p.id, spec, pan, tilt, rgb))
    if not jobs:
        raise PredictionsError(f"{predictions_path}: no entries to convert")
    entries = [{"id": pid, "envmap": f"maps/{pid}.exr", "envmap_frame": frame} for pid, *_ in jobs]

    def write(tmp):
        os.makedirs(os.path.join(tmp, "maps"))
        for pid, spec, pan, tilt, rgb in tqdm(jobs, desc="maps", unit="map", disable=None if progress else True):
            write_exr(os.path.join(tmp, "maps", f"{pid}.exr"),
                      light_envmap(spec, width, frame, pan, tilt, rgb))
        write_predictions(os.path.join(tmp, "predictions.json"), entries, dataset=dataset_dir,
                          source=os.path.abspath(predictions_path), envmap_width=int(width))

    atomic_folder(out_dir, write)
    return len(jobs)


def to_light(predictions_path: str, out_path: str, data_dir: str | None = None, progress: bool = True) -> int:
    """``relight envmap to-light``: every map entry becomes the point light of its
    dominant light (v1 file; entries without a map are copied as they are). A camera-frame
    map needs its image's camera tilt: from the dataset's record (``--data`` or the file's
    ``dataset``), else the entry's ``camera_tilt_deg``. Returns the number of maps."""
    import json

    from tqdm import tqdm

    from relight.predictions import read_predictions, write_predictions
    pfile = read_predictions(predictions_path)
    with open(predictions_path) as f:
        raw = {e["id"]: e for e in json.load(f)["predictions"]}
    records = None
    if data_dir or pfile.dataset:
        from relight.dataset import read_manifest
        from relight.predictions import resolve_dataset_dir
        dataset_dir = resolve_dataset_dir(predictions_path, data_dir, pfile.dataset)
        if os.path.isdir(dataset_dir):
            records = {r.get("id"): r for r in read_manifest(dataset_dir)}
    entries, n_maps = [], 0
    for p in tqdm(pfile.predictions, desc="maps", unit="map", disable=None if progress else True):
        e = {k: v for k, v in raw[p.id].items() if k not in ("envmap", "envmap_frame", "envmap_scale")}
        if p.envmap is None:
            entries.append(e)
            continue
        image = read_envmap(p.envmap)
        tilt_c = _camera_tilt(p, records) if p.envmap_frame == "camera" else 0.0
        pan, tilt, rgb, dom = envmap_light(image, p.envmap_frame, tilt_c)
        for k in ("pan_deg", "tilt_deg", "rgb", "y"):
            e.pop(k, None)
        e.update(pan_deg=pan, tilt_deg=tilt, rgb=[float(c) for c in rgb], envmap_share=dom.share)
        if p.envmap_frame == "camera":
            e["to_light_camera"] = [float(c) for c in frames.world_to_camera(frames.direction(pan, tilt), tilt_c)]
        entries.append(e)
        n_maps += 1
    meta = {k: v for k, v in pfile.meta.items() if k != "colour_only"}
    write_predictions(out_path, entries, dataset=pfile.dataset, inputs=[predictions_path], **meta)
    return n_maps


def _camera_tilt(p, records) -> float:
    """The camera tilt (degrees) of a camera-frame map's image."""
    if records is not None and p.id in records:
        try:
            return float(records[p.id]["camera"]["tilt_deg"])
        except (KeyError, TypeError, ValueError):
            pass
    tilt = p.extra.get("camera_tilt_deg")
    if isinstance(tilt, (int, float)) and not isinstance(tilt, bool) and math.isfinite(tilt) and abs(tilt) < 90:
        return float(tilt)
    raise PredictionsError(f"entry {p.id!r}: a camera-frame map needs its image's camera tilt "
                           "(give --data DIR, or camera_tilt_deg in the entry)")
