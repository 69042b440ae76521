"""Make relight/assets/meshes/ from a snapshot of the odedstein/meshes repository.

How the shipped meshes were made (run once; the results are committed, nothing is
downloaded at run time)::

    pip install fast_simplification==0.2.0
    python scripts/make_mesh_assets.py /path/to/odedstein-meshes.git

For each chosen object (public-domain or CC BY licences only; each object's README,
with its attribution and licence, is copied beside it as NAME.LICENSE.md):

1. read its OBJ (taken as y-up, turned to relight's z-up: (x, y, z) -> (x, -z, y));
2. simplify it (quadric decimation) to at most the face and vertex counts of relight's
   procedural shapes (``shapes.DEFAULT_NU x DEFAULT_NV`` grid: 1152 vertices, 2208 faces);
3. pad it to exactly those counts (unused vertices repeat vertex 0; extra faces are
   degenerate (0, 0, 0), which no ray hits), so every shipped mesh shares the procedural
   shapes' buffer sizes and a scene template (no new Mitsuba scene per mesh);
4. write it as a binary little-endian PLY (``NAME.ply``).
"""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
from relight.scene import shapes  # noqa: E402

OUT = os.path.join(os.path.dirname(HERE), "relight", "assets", "meshes")
# object -> the OBJ file in the snapshot (public domain or CC BY; see each LICENSE file)
OBJECTS = {
    "spot": ("objects/spot/spot_low_resolution.obj", "public domain"),
    "fish": ("objects/fish/fish_low_resolution.obj", "public domain"),
    "boat": ("objects/boat/boat.obj", "CC BY 4.0"),
    "boot": ("objects/boot/boot.obj", "CC BY 4.0"),
    "demosthenes": ("objects/demosthenes/demosthenes-low-res.obj", "CC BY 4.0"),
    "goathead": ("objects/goathead/goathead.obj", "CC BY 3.0"),
    "koala": ("objects/koala/koala_low_resolution.obj", "CC BY 3.0"),
    "penguin": ("objects/penguin/penguin.obj", "CC BY 4.0"),
    "skull": ("objects/skull/skull_low_resolution.obj", "CC BY 3.0"),
    "wingnut": ("objects/wingnut/wingnut.obj", "CC BY 4.0"),
    "hammer": ("objects/hammer/hammer.obj", "CC BY 4.0"),
    "scorpion": ("objects/scorpion/scorpion_low_resolution.obj", "CC BY 3.0"),
}
N_VERTICES = shapes.DEFAULT_NU * shapes.DEFAULT_NV
N_FACES = 2 * shapes.DEFAULT_NU * (shapes.DEFAULT_NV - 1)


def git_show(repo: str, path: str) -> str:
    return subprocess.run(["git", "--git-dir", repo, "show", f"HEAD:{path}"], check=True,
                          capture_output=True, text=True).stdout


def parse_obj(text: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and triangles (F, 3) of an OBJ (polygons fanned)."""
    v, f = [], []
    for line in text.splitlines():
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            idx = [int(tok.split("/")[0]) for tok in line.split()[1:]]
            idx = [i - 1 if i > 0 else len(v) + i for i in idx]
            f.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
    return np.asarray(v, np.float64), np.asarray(f, np.int64)


def simplify(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import fast_simplification
    reduction = 0.0
    while len(f) > N_FACES or len(v) > N_VERTICES:
        reduction = min(0.999, max(reduction + 0.01, 1.0 - 0.98 * N_FACES / len(f)))
        v2, f2 = fast_simplification.simplify(v.astype(np.float32), f.astype(np.int32), reduction)
        if len(f2) <= N_FACES and len(v2) <= N_VERTICES:
            return v2.astype(np.float64), f2.astype(np.int64)
    return v, f


def pad(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.unique(f)
    remap = np.full(len(v), -1)
    remap[used] = np.arange(len(used))
    v, f = v[used], remap[f]
    v = np.concatenate([v, np.repeat(v[:1], N_VERTICES - len(v), 0)])
    f = np.concatenate([f, np.zeros((N_FACES - len(f), 3), np.int64)])
    return v, f


def write_ply(path: str, v: np.ndarray, f: np.ndarray) -> None:
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    faces = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    faces["n"], faces["i"] = 3, f
    with open(path, "wb") as out:
        out.write(header.encode())
        out.write(v.astype("<f4").tobytes())
        out.write(faces.tobytes())


def main(repo: str) -> None:
    os.makedirs(OUT, exist_ok=True)
    for name, (path, licence) in OBJECTS.items():
        v, f = parse_obj(git_show(repo, path))
        v = np.stack([v[:, 0], -v[:, 2], v[:, 1]], 1)        # y-up -> z-up
        v, f = pad(*simplify(v, f))
        write_ply(os.path.join(OUT, f"{name}.ply"), v, f)
        readme = git_show(repo, os.path.dirname(path) + "/README.md")
        with open(os.path.join(OUT, f"{name}.LICENSE.md"), "w") as out:
            out.write(f"Licence: {licence}\n\nSource: github.com/odedstein/meshes, {path}; simplified to at "
                      f"most {N_FACES} faces and padded by relight's scripts/make_mesh_assets.py. The original's "
                      f"README (attribution and licence) follows.\n\n{readme}")
        print(f"{name}: {len(v)} vertices, {len(f)} faces")


if __name__ == "__main__":
    main(sys.argv[1])
