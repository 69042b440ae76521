"""Draw docs/envmap_frame.png: the two frames of an environment-map prediction.

    .venv/bin/python scripts/envmap_frame_figure.py [--out docs/envmap_frame.png]

Top: a camera-frame map (``envmap_frame: camera``) of a scene whose camera is tilted
30 deg down, holding the disc that ``relight envmap from-light`` makes for a light at
pan_rel 60 (front right), tilt 45; the axes are the camera's. Bottom: the same light in
a world-frame map (``envmap_frame: world``), axes in pan and tilt. Both maps are drawn
by :mod:`relight.verify.envmap` and placed with :mod:`relight.frames`, so the figure is
the convention as the code implements it.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight import frames  # noqa: E402
from relight.verify import envmap as E  # noqa: E402

CAMERA_TILT_DEG, PAN_REL_DEG, TILT_DEG = 30.0, 60.0, 45.0
WIDTH = 256


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                                 "docs", "envmap_frame.png"))
    args = p.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    to_light = frames.direction(PAN_REL_DEG, TILT_DEG)
    fig, axes = plt.subplots(2, 1, figsize=(8.0, 8.4), constrained_layout=True)
    for ax, frame in zip(axes, ("camera", "world")):
        d_map = frames.world_to_envmap(to_light, frame, CAMERA_TILT_DEG)
        m = E.disc_envmap(d_map, [1.0, 0.85, 0.6], WIDTH, radius_deg=4.0)
        ax.imshow(np.clip(m / m.max(), 0, 1) * 0.9 + 0.05, extent=(0, 1, 1, 0), aspect=0.5 * 1.0)
        ax.set_xlim(0, 1)
        ax.set_ylim(1, 0)
        ax.set_xlabel("u = (column + 0.5) / W")
        ax.set_ylabel("v = (row + 0.5) / H")
        for u in (0.25, 0.5, 0.75):
            ax.axvline(u, color="0.6", lw=0.6)
        ax.axhline(0.5, color="0.6", lw=0.6)
        u, v = frames.direction_to_equirect(d_map)
        ax.annotate(f"light: pan_rel {PAN_REL_DEG:.0f}, tilt {TILT_DEG:.0f}", (float(u), float(v)),
                    xytext=(float(u) - 0.33, float(v) - 0.1), color="w", fontsize=8,
                    arrowprops={"arrowstyle": "->", "color": "w"})
        if frame == "camera":
            labels = {0.0: "behind\n(+z)", 0.25: "left\n(-x)", 0.5: "forward: view\ndirection (-z)",
                      0.75: "right\n(+x)", 1.0: "behind\n(+z)"}
            ax.set_title(f"envmap_frame: camera (camera tilted {CAMERA_TILT_DEG:.0f} deg down); "
                         "v = 0: image up (+y), v = 0.5: the camera's x-z plane", fontsize=9)
        else:
            labels = {0.0: "pan 0\n(+X)", 0.25: "pan 270\n(-Y)", 0.5: "pan 180\n(-X)", 0.75: "pan 90\n(+Y)",
                      1.0: "pan 0\n(+X)"}
            ax.set_title("envmap_frame: world; pan = wrap360(-360 u), tilt = 90 - 180 v "
                         "(v = 0: zenith, 0.5: horizon)", fontsize=9)
        for u0, text in labels.items():
            ax.text(min(max(u0, 0.045), 0.955), 0.6, text, ha="center", va="center", fontsize=8, color="w")
        ax.set_xticks([0, 0.25, 0.5, 0.75, 1])
        ax.set_yticks([0, 0.25, 0.5, 0.75, 1])
    fig.savefig(args.out, dpi=110)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
