"""The triangle rasterizer (vision/raster.py): coverage against point-in-polygon, z-buffer order, no
seams between triangles sharing an edge."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from isa_mocap_ros.vision import VisionError, look_at
from isa_mocap_ros.vision.raster import mesh_mask, render_mesh

CAM = look_at((0.0, -3.0, 1.0), (0.0, 0.0, 1.0), fov_deg=50.0, width=160, height=120)


def _quad(x0, x1, z0, z1, y=0.0):
    V = np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]], float)
    return V, np.array([[0, 1, 2], [0, 2, 3]])


def test_coverage_matches_point_in_polygon_without_seams():
    V, T = _quad(-0.4, 0.3, 0.7, 1.35)
    m = mesh_mask(CAM, V, T)
    poly = CAM.project(V).astype(np.float32)
    inside = np.zeros_like(m, dtype=bool)
    near = np.zeros_like(m, dtype=bool)
    for v in range(m.shape[0]):
        for u in range(m.shape[1]):
            d = cv2.pointPolygonTest(poly.reshape(-1, 1, 2), (float(u), float(v)), True)
            inside[v, u] = d > 0
            near[v, u] = abs(d) < 0.51
    assert inside.sum() > 500
    assert np.array_equal((m > 0)[~near], inside[~near])       # exact away from the outline
    # the diagonal shared by the two triangles leaves no hole inside the quad
    assert (m > 0)[inside & ~near].all()


@pytest.mark.parametrize("order", [(0, 1), (1, 0)])
def test_nearest_triangle_wins_whatever_the_order(order):
    Va, Ta = _quad(-0.5, 0.5, 0.5, 1.5, y=0.0)        # far, red
    Vb, Tb = _quad(-0.2, 0.2, 0.8, 1.2, y=-0.5)       # near, green
    parts = [(Va, Ta, (255, 0, 0)), (Vb, Tb, (0, 255, 0))]
    V, T, C = [], [], []
    for i in order:
        v, t, c = parts[i]
        T.append(t + sum(len(x) for x in V))
        V.append(v)
        C += [c, c]
    rgb, mask = render_mesh(CAM, np.concatenate(V), np.concatenate(T), np.array(C, np.uint8),
                            light_dir=(0.0, -1.0, 0.0))
    u, v = CAM.project([0.0, -0.5, 1.0]).round().astype(int)
    assert rgb[v, u, 1] > 150 and rgb[v, u, 0] == 0
    u, v = CAM.project([0.4, 0.0, 0.6]).round().astype(int)
    assert rgb[v, u, 0] > 150 and rgb[v, u, 1] == 0
    assert mask[v, u] == 255


def test_bad_input_names_the_argument():
    V, T = _quad(0, 1, 0, 1)
    with pytest.raises(VisionError, match="tris"):
        mesh_mask(CAM, V, T + 10)
    with pytest.raises(VisionError, match="colors"):
        render_mesh(CAM, V, T, np.zeros((3, 3), np.uint8))
