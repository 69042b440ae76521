"""Argument types shared by the subcommands: each rejects bad text with one line.

Every numeric option of every verb uses one of these (the engine's ``--workers`` and
``--scheduler`` live with the engine: :func:`relight.engine.add_arguments`), so zero,
negative, NaN, inf and absurdly large values are refused by argparse (one line, exit 2)
before any work.
"""
from __future__ import annotations

__all__ = [
    "positive_int", "finite_float", "positive_float", "camera_tilt", "rgb", "int_in", "float_in",
    "int_range_in", "MAX_RES", "MAX_SPP", "SEED_LIMIT", "MAX_COUNT", "MAX_RGB", "resolution", "net_resolution",
    "spp", "max_depth", "seed", "threads", "loader_workers", "count", "limit", "columns", "epochs",
    "batch_size", "patience", "width", "iterations", "learning_rate", "seconds", "minutes", "relative_rmse",
    "light_pan", "light_tilt", "field_of_view", "object_parts",
    "add_mirror_option", "add_weights_options", "checked_weights_options", "add_model_option", "model_help", "bounded_rgb", "loss_weights",
    "circle", "OneLineParser", "run_script",
]

import argparse
import math
import os


def _number(text: str, kind=float):
    try:
        return kind(text)
    except (ValueError, OverflowError):
        raise argparse.ArgumentTypeError(
            f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None


def positive_int(text: str) -> int:
    """An integer >= 1."""
    v = _number(text, int)
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def finite_float(text: str) -> float:
    """Any finite number (no NaN, no inf)."""
    v = _number(text)
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def positive_float(text: str) -> float:
    """A finite number > 0."""
    v = finite_float(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive finite number, got {text!r}")
    return v


def camera_tilt(text: str) -> float:
    """A camera tilt in degrees, strictly between -90 and 90."""
    v = finite_float(text)
    if not -90.0 < v < 90.0:
        raise argparse.ArgumentTypeError(f"camera tilt must be in (-90, 90) degrees, got {text!r}")
    return v


def rgb(text: str) -> tuple[float, float, float]:
    """``R,G,B``: three finite non-negative numbers, not all zero."""
    parts = text.split(",")
    values = tuple(_number(p) for p in parts)
    if len(values) != 3 or not all(math.isfinite(v) for v in values) or min(values) < 0 or max(values) <= 0:
        raise argparse.ArgumentTypeError(
            f"expected three finite non-negative numbers, not all zero, got {text!r}")
    return values


def int_in(lo: int, hi: int, what: str = "an integer"):
    """A type accepting integers in ``[lo, hi]``."""
    def parse(text: str) -> int:
        v = _number(text, int)
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"expected {what} in [{lo}, {hi}], got {text!r}")
        return v
    parse.__name__ = what.replace(" ", "_")
    return parse


def float_in(lo: float, hi: float, what: str = "a number", open_lo: bool = False, open_hi: bool = False):
    """A type accepting finite numbers in ``[lo, hi]`` (an open end with ``open_lo`` / ``open_hi``)."""
    def parse(text: str) -> float:
        v = finite_float(text)
        if not (lo < v if open_lo else lo <= v) or not (v < hi if open_hi else v <= hi):
            left, right = "(" if open_lo else "[", ")" if open_hi else "]"
            raise argparse.ArgumentTypeError(f"expected {what} in {left}{lo:g}, {hi:g}{right}, got {text!r}")
        return v
    parse.__name__ = what.replace(" ", "_")
    return parse


def int_range_in(lo: int, hi: int, what: str = "a count"):
    """A type accepting ``N`` or ``LO-HI`` (integers in ``[lo, hi]``, LO <= HI) as ``(lo, hi)``."""
    def parse(text: str) -> tuple[int, int]:
        parts = text.split("-")
        try:
            if len(parts) not in (1, 2):
                raise ValueError(text)
            values = [int(p) for p in parts]
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what} N or LO-HI (integers), got {text!r}") from None
        a, b = values[0], values[-1]
        if not lo <= a <= b <= hi:
            raise argparse.ArgumentTypeError(f"expected {what} N or LO-HI with {lo} <= LO <= HI <= {hi}, "
                                             f"got {text!r}")
        return a, b
    parse.__name__ = what.replace(" ", "_")
    return parse


MAX_RES = 4096            # pixels per side of any rendered or network image
MAX_SPP = 1 << 16
SEED_LIMIT = 2 ** 32
MAX_COUNT = 1_000_000     # dataset ids have six digits
MAX_RGB = 1e6

resolution = int_in(1, MAX_RES, "an image size in pixels")
net_resolution = int_in(16, MAX_RES, "a network input size in pixels")
spp = int_in(1, MAX_SPP, "a sample count per pixel")
max_depth = int_in(1, 64, "a path depth")
seed = int_in(0, SEED_LIMIT - 1, "a seed")
threads = int_in(1, 1024, "a thread count")
loader_workers = int_in(0, 256, "a worker count")
count = int_in(1, MAX_COUNT, "an image count")   # 0 would make an empty dataset: refused
limit = int_in(1, 10_000_000, "a count")
columns = int_in(1, 64, "a column count")
epochs = int_in(1, 100_000, "an epoch count")
batch_size = int_in(1, 65_536, "a batch size")
patience = int_in(0, 100_000, "a patience in epochs")
width = int_in(1, 1024, "a network width")
iterations = int_in(1, 1_000_000, "an iteration count")
learning_rate = float_in(0.0, 1.0, "a learning rate", open_lo=True)
seconds = float_in(0.0, 1e7, "a time in seconds", open_lo=True)
minutes = float_in(0.0, 1e6, "a time in minutes")
relative_rmse = float_in(0.0, 1.0, "a relative RMSE", open_lo=True)
light_pan = float_in(-360.0, 360.0, "a light pan in degrees")
light_tilt = float_in(-90.0, 90.0, "a light tilt in degrees")
field_of_view = float_in(0.0, 180.0, "a field of view in degrees", open_lo=True, open_hi=True)


def object_parts(text: str) -> tuple[int, int]:
    from relight.scene.shapes import MAX_PARTS
    return int_range_in(1, MAX_PARTS, "a part count")(text)


def add_mirror_option(parser) -> None:
    """``--mirror-average`` of a network verb (:class:`relight.net.model.MirrorAveraged`)."""
    parser.add_argument("--mirror-average", action="store_true",
                        help="also run each image's left-right mirror image and average the two "
                             "predictions (lower errors, about 1.8x the time)")


def add_weights_options(parser) -> None:
    """``--save`` / ``--force`` / ``--load`` of a script that trains a small network or judges
    trained weights (the probe's learned networks); :func:`checked_weights_options` checks them."""
    parser.add_argument("--save", help="write the trained weights here (safetensors; refuses to overwrite "
                                       "without --force)")
    parser.add_argument("--force", action="store_true", help="overwrite --save")
    parser.add_argument("--load", help="judge these weights instead of training")


def checked_weights_options(parser, args, train) -> None:
    """The options of :func:`add_weights_options` checked: a one-line error and exit 2
    (``parser.error``; :class:`OneLineParser`) unless exactly one of ``train`` (the training
    data given) and ``--load`` is, or when ``--save`` would overwrite a file without ``--force``."""
    if bool(train) == bool(args.load):
        parser.error("give --train FOLDER or --load WEIGHTS")
    if args.save and os.path.exists(args.save) and not args.force:
        parser.error(f"{args.save} exists (give --force to replace it)")


def model_help(default: bool = True) -> str:
    """The one help text of every option that names a network: the shipped names, a file or
    a run folder, and (``default``) what giving none means (:func:`relight.net.io.resolve_model`)."""
    from relight.net.io import DEFAULT_MODELS, SHIPPED_NAMES
    text = f"shipped model name ({', '.join(SHIPPED_NAMES)}) or a .safetensors file or run folder"
    return text + (f" (default: {', else '.join(DEFAULT_MODELS)})" if default else "")


def add_model_option(parser, flag: str = "--model", *aliases: str, default_text: bool = True, **kwargs) -> None:
    """A ``--model`` option (or ``flag``) taking a shipped model's name or a file / run folder,
    with the shared help text; ``kwargs`` go to ``add_argument`` (e.g. ``required=True``,
    ``dest``), and a ``help`` there follows the shared text."""
    extra = kwargs.pop("help", None)
    text = model_help(default_text and not kwargs.get("required", False))
    kwargs.setdefault("default", None)
    kwargs.setdefault("metavar", "MODEL")
    parser.add_argument(flag, *aliases, help=f"{text}; {extra}" if extra else text, **kwargs)


def bounded_rgb(text: str) -> tuple[float, float, float]:
    """``R,G,B``: three finite numbers in [0, 1e6], the largest at least 1e-6."""
    values = rgb(text)
    if max(values) > MAX_RGB or max(values) < 1e-6:
        raise argparse.ArgumentTypeError(
            f"expected three numbers in [0, {MAX_RGB:g}] with the largest >= 1e-6, got {text!r}")
    return values


def loss_weights(text: str):
    """``PAN,TILT,COLOUR`` loss weights: three finite numbers in [0, 1e6], not all zero."""
    from relight.net.loss import LossWeights
    parts = text.split(",")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) and 0 <= v <= MAX_RGB for v in values) \
            or max(values) <= 0:
        raise argparse.ArgumentTypeError(
            f"expected three finite numbers in [0, 1e6], not all zero, like 1,1,1, got {text!r}")
    return LossWeights(pan=values[0], tilt=values[1], colour=values[2])


# The largest image side relight reads (relight.imageio.MAX_IMAGE_PIXELS is 8192^2): no
# circle of a readable image has a centre or radius beyond it.
MAX_CIRCLE_PX = 65536


def circle(text: str) -> tuple[float, float, float]:
    """``CX,CY,R`` in pixels: three finite numbers, 0 < R and |CX|, |CY|, R at most
    :data:`MAX_CIRCLE_PX` (the image itself: :func:`relight.commands.probe.check_circle_fits`)."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values) or values[2] <= 0 \
            or max(abs(v) for v in values) > MAX_CIRCLE_PX:
        raise argparse.ArgumentTypeError(f"expected CX,CY,R (pixels, 0 < R, each at most {MAX_CIRCLE_PX}), "
                                         f"got {text!r}")
    return values


class OneLineParser(argparse.ArgumentParser):
    """An argument parser with the command line's manners, for scripts and benchmarks: a bad
    argument is one line ``PROG: error: ...`` on stderr and exit 2 (no usage block), and
    ``--check-args`` checks a command's arguments (types and ranges) without running it."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.add_argument("--check-args", action="store_true",
                          help="check the arguments (types and ranges), say so and exit without running")

    def parse_args(self, args=None, namespace=None):
        import sys
        ns = super().parse_args(args, namespace)
        if ns.check_args:
            print(f"{self.prog}: arguments ok")
            sys.exit(0)
        return ns

    def error(self, message):
        import sys
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(2)


def run_script(main, prog: str | None = None) -> int:
    """Run a script's ``main()`` as the command line runs a verb: an error a user can fix
    (:class:`relight.errors.RelightError`, a missing or unreadable file) is one line on
    stderr and exit code 2, never a traceback."""
    import os
    import sys
    from relight.errors import user_errors
    prog = prog or os.path.basename(sys.argv[0])
    try:
        return int(main() or 0)
    except KeyboardInterrupt:
        sys.stderr.write(f"{prog}: interrupted (re-run the same command to resume)\n")
        return 130
    except user_errors() as exc:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if isinstance(exc, OSError) and exc.filename:
            text = f"{exc.strerror}: {exc.filename}"
        sys.stderr.write(f"{prog}: error: {text}\n")
        return 2
