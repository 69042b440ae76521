"""Tests for relight.scene.shapes: fixed topology, normalisation, winding, closed forms."""
import json
import math

import numpy as np
import pytest

from relight.scene import shapes as S

SEEDS = range(6)
NU, NV = S.DEFAULT_NU, S.DEFAULT_NV


def _mesh(family, seed, **kw):
    return S.make_mesh(family, S.sample_shape_params(family, np.random.default_rng(seed)), **kw)


def _volume(m):
    v = m.vertices.astype(np.float64)
    f = m.faces.astype(np.int64)
    return np.linalg.det(np.stack([v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]], 1)).sum() / 6.0


def _rows(a, n_u=NU):
    return a.reshape(-1, n_u, a.shape[-1])


@pytest.fixture(scope="module")
def meshes():
    return {(fam, s): _mesh(fam, s) for fam in S.FAMILIES for s in SEEDS}


def test_scene_sampler_draws_every_family_and_only_those_asked():
    # the generator's own draw (not the list itself): 40 scenes of 1-3 objects reach all
    # six families; a config restricted to one family draws only that one
    from relight.generator.sampling import GeneratorConfig, sample_scene
    drawn = {o.family for i in range(40) for o in sample_scene(GeneratorConfig(), 5, i).objects}
    assert drawn == {"superquadric", "torus", "revolved", "extrusion", "blob", "primitive"}
    only = {o.family for i in range(10)
            for o in sample_scene(GeneratorConfig(families=("torus",)), 5, i).objects}
    assert only == {"torus"}


def test_grid_faces_layout():
    f = S.grid_faces(5, 4)
    assert f.dtype == np.uint32 and f.shape == (2 * 5 * 3, 3)
    assert f.min() == 0 and f.max() == 5 * 4 - 1
    # first cell (i=0, j=0) and the wrapping cell (i=4, j=0)
    assert f[0].tolist() == [0, 1, 6] and f[1].tolist() == [0, 6, 5]
    assert f[8].tolist() == [4, 0, 5] and f[9].tolist() == [4, 5, 9]
    with pytest.raises(ValueError):
        S.grid_faces(2, 4)


def test_same_topology_for_all_families(meshes):
    faces = S.grid_faces(NU, NV)
    for m in meshes.values():
        assert m.vertices.shape == (NU * NV, 3) and m.vertices.dtype == np.float32
        assert m.normals.shape == (NU * NV, 3) and m.normals.dtype == np.float32
        assert m.uv.shape == (NU * NV, 2) and m.uv.dtype == np.float32
        assert m.faces.dtype == np.uint32 and np.array_equal(m.faces, faces)


def test_custom_resolution_all_families():
    for fam in S.FAMILIES:
        m = _mesh(fam, 1, n_u=16, n_v=8)
        assert m.vertices.shape == (128, 3) and np.array_equal(m.faces, S.grid_faces(16, 8))


def test_normalisation(meshes):
    for (fam, s), m in meshes.items():
        v = m.vertices
        assert v[:, 2].min() == 0.0, (fam, s)
        assert abs(np.hypot(v[:, 0], v[:, 1]).max() - 1.0) < 1e-6, (fam, s)
        centre = 0.5 * (v[:, :2].min(0) + v[:, :2].max(0))
        assert np.abs(centre).max() < 1e-6, (fam, s)
        assert S.MIN_HEIGHT - 1e-6 <= v[:, 2].max() <= S.MAX_HEIGHT + 1e-6, (fam, s)


def test_outward_winding_positive_volume():
    for fam in S.FAMILIES:
        for s in range(25):
            assert _volume(_mesh(fam, s)) > 0.0, (fam, s)


def test_normals_unit_finite(meshes):
    for (fam, s), m in meshes.items():
        assert np.all(np.isfinite(m.normals)), (fam, s)
        assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-5), (fam, s)


def test_normals_point_outward_for_convex_families():
    for fam, params in [("superquadric", None), ("primitive", None),
                        ("extrusion", {"outline": "polygon", "radii": [1, 1, 1, 1, 1], "height": 1.0,
                                       "aspect": 0.8, "rotation": 0.3})]:
        for s in SEEDS:
            m = S.make_mesh(fam, params) if params else _mesh(fam, s)
            v = m.vertices
            c = 0.5 * (v.min(0) + v.max(0))
            frac = np.mean(np.einsum("ij,ij->i", m.normals, v - c) > 0)
            assert frac > 0.99, (fam, s, frac)


def test_pole_rings_share_axis_normal():
    for fam in ("superquadric", "blob", "revolved", "extrusion", "primitive"):
        for s in SEEDS:
            m = _mesh(fam, s)
            v, n = _rows(m.vertices), _rows(m.normals)
            for row in (0, -1):
                assert np.all(v[row] == v[row][0]), (fam, s)  # collapsed pole
                assert np.all(n[row] == n[row][0]), (fam, s)  # one shared normal
            assert n[0][0][2] < -0.5 and n[-1][0][2] > 0.5 or fam == "blob", (fam, s)
    sq = _rows(S.make_mesh("superquadric", {"e1": 0.6, "e2": 1.4, "axes": [1, 0.6, 0.8]}).normals)
    assert np.allclose(sq[0], [0, 0, -1], atol=1e-6) and np.allclose(sq[-1], [0, 0, 1], atol=1e-6)


def test_flat_caps_have_axis_normals():
    """Bottom/top centre and inset rings lie on flat caps, so their normals are -z / +z."""
    for params in ({"kind": "cylinder", "radius": 1.0, "height": 1.2},
                   {"kind": "box", "size": [1, 0.5, 0.7]}):
        n = _rows(S.make_mesh("primitive", params).normals)
        assert np.allclose(n[:2], [0, 0, -1], atol=1e-6) and np.allclose(n[-2:], [0, 0, 1], atol=1e-6)
        side = n[3:-3, :, 2]
        assert np.abs(side).max() < 1e-6  # vertical walls
    n = _rows(_mesh("extrusion", 3).normals)
    assert np.allclose(n[:2], [0, 0, -1], atol=1e-6) and np.allclose(n[-2:], [0, 0, 1], atol=1e-6)


def test_sphere_closed_form():
    sphere = {"e1": 1.0, "e2": 1.0, "axes": [1.0, 1.0, 1.0]}
    # odd n_v has an equator row, so the normalised sphere has radius exactly 1
    for n_v, radius in ((25, 1.0), (NV, 1.0 / math.cos(math.pi / (2 * (NV - 1))))):
        m = S.make_mesh("superquadric", sphere, n_v=n_v)
        d = np.linalg.norm(m.vertices.astype(np.float64) - [0.0, 0.0, radius], axis=1)
        assert np.abs(d - radius).max() < 2e-6
        assert np.einsum("ij,ij->i", m.normals, m.vertices - [0, 0, radius]).min() > 0.99 * radius
    # Inscribed polyhedron: V <= 4/3 pi r^3, and it contains the ball of radius
    # r cos(delta), delta = half the angular diagonal of a grid cell.
    n_v = 25
    m = S.make_mesh("superquadric", sphere, n_v=n_v)
    delta = 0.5 * math.hypot(2 * math.pi / NU, math.pi / (n_v - 1))
    ball = 4.0 / 3.0 * math.pi
    assert ball * math.cos(delta) ** 3 < _volume(m) < ball


def test_cylinder_cone_box_volumes():
    n, h = NU, 1.5
    polygon_area = 0.5 * n * math.sin(2 * math.pi / n)  # inscribed n-gon, radius 1
    cyl = S.make_mesh("primitive", {"kind": "cylinder", "radius": 2.0, "height": 2 * h})
    assert cyl.vertices[:, 2].max() == pytest.approx(h, abs=1e-6)
    assert _volume(cyl) == pytest.approx(polygon_area * h, rel=1e-5)
    tess = 1.0 - polygon_area / math.pi  # tessellation deficit of the circle
    assert abs(_volume(cyl) - math.pi * h) / (math.pi * h) <= tess + 1e-5
    cone = S.make_mesh("primitive", {"kind": "cone", "radius": 1.0, "height": h})
    assert _volume(cone) == pytest.approx(polygon_area * h / 3.0, rel=1e-5)
    box = S.make_mesh("primitive", {"kind": "box", "size": [2.0, 1.0, 0.5]})
    s = 1.0 / math.hypot(1.0, 0.5)  # half-diagonal normalised to 1
    assert _volume(box) == pytest.approx(2.0 * 1.0 * 0.5 * s**3, rel=1e-5)
    assert np.allclose(box.vertices.max(0), [s, 0.5 * s, 0.5 * s], atol=1e-6)


def test_torus_closed_form():
    big, small = 1.0, 0.4
    m = S.make_mesh("torus", {"major_radius": big, "minor_radius": small, "standing": False})
    rc, rt = big / (big + small), small / (big + small)  # after normalisation
    ring_v = _rows(m.vertices)
    assert np.array_equal(ring_v[0], ring_v[-1])  # closed seam
    v = m.vertices.astype(np.float64)
    zc = 0.5 * v[:, 2].max()
    rad = np.hypot(v[:, 0], v[:, 1])
    c = np.stack([v[:, 0] * rc / rad, v[:, 1] * rc / rad, np.full(len(v), zc)], 1)
    d = v - c
    dist = np.linalg.norm(d, axis=1)
    assert np.abs(dist - rt).max() < 1e-3
    assert np.einsum("ij,ij->i", m.normals, d / dist[:, None]).min() > 0.99
    # Pappus with both circles replaced by inscribed polygons (n_u and n_v-1 sides)
    sinc = lambda k: math.sin(2 * math.pi / k) / (2 * math.pi / k)  # noqa: E731
    pappus = 2 * math.pi**2 * rc * rt**2
    assert _volume(m) == pytest.approx(pappus * sinc(NU) * sinc(NV - 1), rel=1e-3)
    standing = S.make_mesh("torus", {"major_radius": big, "minor_radius": small, "standing": True})
    assert standing.vertices[:, 2].min() == 0.0
    assert standing.vertices[:, 2].max() == pytest.approx(2.0, abs=1e-6)
    assert _volume(standing) == pytest.approx(_volume(m), rel=1e-4)


def test_uv():
    m = _mesh("blob", 0)
    uv = _rows(m.uv, NU)
    assert np.allclose(uv[0, :, 0], np.arange(NU) / NU)
    assert np.allclose(uv[:, 0, 1], np.linspace(0, 1, NV)) and np.all(uv[:, :, 1] == uv[:, :1, 1])
    assert m.uv.min() >= 0.0 and m.uv.max() <= 1.0


def test_determinism_and_json_roundtrip():
    for fam in S.FAMILIES:
        p1 = S.sample_shape_params(fam, np.random.default_rng(42))
        p2 = S.sample_shape_params(fam, np.random.default_rng(42))
        assert p1 == p2
        p3 = json.loads(json.dumps(p1))
        a, b = S.make_mesh(fam, p1), S.make_mesh(fam, p3)
        for field in ("vertices", "faces", "normals", "uv"):
            assert getattr(a, field).tobytes() == getattr(b, field).tobytes(), (fam, field)


def test_seeds_give_different_shapes(meshes):
    for fam in S.FAMILIES:
        verts = [meshes[(fam, s)].vertices for s in SEEDS]
        assert all(not np.array_equal(verts[0], v) for v in verts[1:]), fam


def test_primitive_and_outline_kinds_all_reachable():
    prims = {S.sample_shape_params("primitive", np.random.default_rng(s))["kind"] for s in range(40)}
    outlines = {S.sample_shape_params("extrusion", np.random.default_rng(s))["outline"] for s in range(40)}
    assert prims == set(S.PRIMITIVE_KINDS) and outlines == set(S.OUTLINE_KINDS)
    for outline in S.OUTLINE_KINDS:  # star and polygon corners are kept exactly
        for s in range(40):
            p = S.sample_shape_params("extrusion", np.random.default_rng(s))
            if p["outline"] == outline:
                assert _volume(S.make_mesh("extrusion", p)) > 0
                break


@pytest.mark.parametrize("family,params,match", [
    ("sphere", {}, "expected one of"),
    ("superquadric", {"e1": 1.0, "axes": [1, 1, 1]}, "e2"),
    ("superquadric", {"e1": 1.0, "e2": 9.0, "axes": [1, 1, 1]}, "e2"),
    ("torus", {"major_radius": 1.0, "minor_radius": 2.0}, "minor_radius"),
    ("primitive", {"kind": "pyramid"}, "kind"),
    ("extrusion", {"outline": "heart", "height": 1, "aspect": 1, "rotation": 0}, "outline"),
    ("revolved", {"radii": "wide", "height": 1.0}, "radii"),
    ("blob", {"family": "torus", "bumps": [], "axes": [1, 1, 1]}, "family"),
])
def test_bad_input_raises(family, params, match):
    with pytest.raises(ValueError, match=match):
        S.make_mesh(family, params)


def test_bad_sample_family_and_grid():
    with pytest.raises(ValueError, match="expected one of"):
        S.sample_shape_params("cube", np.random.default_rng(0))
    with pytest.raises(ValueError, match="n_v"):
        _mesh("blob", 0, n_v=4)
