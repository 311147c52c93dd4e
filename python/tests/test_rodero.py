"""The real human left ventricle of Rodero et al. (2021), fetched by palpate.data.

Skipped (saying why) only when the file is not cached and the download fails (no network).
Numbers measured on the file are asserted so that a change in the reader shows up here.
"""
import json

import numpy as np
import pytest

import palpate
from palpate import data


@pytest.fixture(scope="module")
def lv(lv_path):
    """As stored in the file (repair=False): the numbers below are the file's."""
    return palpate.read_tagged_surface(lv_path, unit="mm", repair=False)


def _areas(p, t):
    return 0.5 * np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)


def test_cached_file_and_part_definition(lv_path):
    assert lv_path.name == data.RODERO_VTP
    assert data._sha256(lv_path) == data.RODERO_SHA256[data.RODERO_VTP]
    jpath = palpate.surfaces.part_definition_path(lv_path)
    assert jpath is not None and jpath.endswith(data.RODERO_JSON)
    assert palpate.surfaces.read_part_definition(jpath) == {
        "left-ventricle-endocardium": 1, "left-ventricle-epicardium": 2,
        "interface_left-ventricle-myocardium_mitral-valve-plane": 3,
        "interface_left-ventricle-myocardium_aortic-valve-plane": 4}
    json.loads(open(jpath).read())


def test_raw_vtp(lv_path):
    d = palpate.read_vtp(lv_path)
    assert d.points.shape == (50162, 3) and d.triangles.shape == (100324, 3)
    tags, counts = np.unique(d.cell_data["surface-id"], return_counts=True)
    assert dict(zip(tags.tolist(), counts.tolist())) == {1: 35339, 2: 63265, 3: 839, 4: 881}
    lo, hi = d.points.min(axis=0), d.points.max(axis=0)                     # mm
    np.testing.assert_allclose(lo, [48.802, 12.741, 0.0556], atol=1e-3)
    np.testing.assert_allclose(hi, [134.494, 106.130, 94.784], atol=1e-3)
    assert len(np.unique(d.triangles)) == len(d.points)                       # every point used


def test_parts(lv):
    p, t, part = lv
    assert p.dtype == np.float64 and t.dtype == np.int64 and part.dtype == np.int8
    assert np.bincount(part).tolist() == [35339, 63265, 1720]                 # inner, outer, base (839 + 881)
    a = _areas(p * 1e3, t)                                                    # mm^2
    area_cm2 = [a[part == k].sum() / 100 for k in range(3)]
    np.testing.assert_allclose(area_cm2, [127.46, 228.19, 5.589], rtol=1e-3)
    print(f"\nRodero LV: areas inner {area_cm2[0]:.2f} cm^2, outer {area_cm2[1]:.2f} cm^2, base {area_cm2[2]:.3f} cm^2")


def test_closed_no_open_edges(lv):
    """Every edge is shared: no hole. (Two edges are shared by four triangles, see below.)"""
    _, t, _ = lv
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert (counts == 1).sum() == 0
    assert (counts == 2).sum() == 150482 and (counts == 4).sum() == 2


def test_enclosed_volume(lv):
    """The whole surface (endocardium + epicardium + valve rings) bounds the myocardial wall."""
    p, t, _ = lv
    fixed, n_flipped = palpate.orient_consistently(p, t)
    assert n_flipped == 7040                 # the file's triangles are not consistently oriented
    q = p * 1e3
    vol_ml = np.einsum("ij,ij->i", q[fixed[:, 0]], np.cross(q[fixed[:, 1]], q[fixed[:, 2]])).sum() / 6 / 1e3
    assert vol_ml == pytest.approx(163.31, rel=1e-3)
    print(f"\nRodero LV: wall volume {vol_ml:.2f} mL, {n_flipped} triangles re-oriented")


def test_trisurface_accepts_whole_surface(lv):
    """The Rust core rejects the closed surface as stored (inconsistent orientation) and after
    orient_consistently alone (two edges shared by four triangles); palpate.repair_surface (the
    default of read_tagged_surface) makes it acceptable, see test_repair.py."""
    p, t, part = lv
    with pytest.raises(palpate.SurfaceError):
        palpate.TriSurface(p, t, source="rodero_01_leftventricle_surface.vtp")
    with pytest.raises(palpate.SurfaceError, match=r"non-manifold: edge \((157, 1366|1116, 1118)\) is shared by 4"):
        palpate.TriSurface(p, palpate.orient_consistently(p, t)[0])
    q, u, _, _ = palpate.repair_surface(p, t, part)
    s = palpate.TriSurface(q, u, source="rodero_01_leftventricle_surface.vtp")
    assert s.volume * 1e6 == pytest.approx(163.31, rel=1e-3)
