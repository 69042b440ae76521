"""Make the README's QA overlay of `relight probe` (docs/probe_qa.png): a Mitsuba
validation scene with clutter (relight.verify.probe_scenes, seed 3, 480 x 360, 64 spp),
saved as 8-bit sRGB, then the sphere procedure with automatic sphere detection.

    .venv/bin/python scripts/probe_qa_example.py [--out docs/probe_qa.png]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

from relight import backend


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join("docs", "probe_qa.png"))
    args = ap.parse_args()
    backend.init()
    from relight.imageio import write_png
    from relight.verify.probe_scenes import render_probe_scene, sample_probe_scene
    scene = sample_probe_scene(3, 480, 360, clutter=True)
    with tempfile.TemporaryDirectory() as tmp:
        photo = os.path.join(tmp, "scene.png")
        write_png(photo, render_probe_scene(scene, spp=64, seed=0))
        qa = os.path.join(tmp, "qa.png")
        subprocess.run([sys.executable, "-m", "relight", "probe", "--chrome", photo, "--diffuse", photo,
                        "--fov", repr(scene.fov_deg), "--out", os.path.join(tmp, "pred.json"),
                        "--qa", qa], check=True)
        from PIL import Image
        with Image.open(qa) as im:   # 256 colours: a small file for the README
            im.convert("RGB").quantize(256).save(args.out, optimize=True)
    print(f"{args.out}; truth to_light_camera {[round(v, 3) for v in scene.to_light]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
