"""Argument types shared by the subcommands: each rejects bad text with one line."""
from __future__ import annotations

import argparse
import math


def _number(text: str, kind=float):
    try:
        return kind(text)
    except ValueError:
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
