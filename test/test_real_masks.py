"""tools/real_masks.py: where a mask and the estimate's silhouette disagree (docs/real_cameras.md section 5)."""
import importlib.util
from pathlib import Path

import numpy as np

_SPEC = importlib.util.spec_from_file_location("real_masks", Path(__file__).resolve().parents[1] / "tools" / "real_masks.py")
real_masks = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(real_masks)


def test_parts_of_the_capsules():
    assert [real_masks._part(n) for n in ("chest", "shoulders", "head", "neck", "left_forearm", "right_hand",
                                          "left_thigh", "right_foot")] == \
        ["trunk", "trunk", "head", "head", "left_arm", "right_arm", "left_leg", "right_leg"]


def test_floor_far_and_missing_pixels_are_told_apart():
    H, W = 200, 120
    labels = np.full((H, W), -1, np.int32)
    labels[20:100, 40:80] = 0                    # trunk
    labels[100:160, 45:60] = 1                   # a leg, ankle at row 160
    parts = ["trunk", "left_leg"]
    mask = (labels >= 0).astype(np.uint8) * 255
    mask[170:180, 40:70] = 255                   # below the ankle: the floor's reflection, 300 px
    mask[10:20, 0:10] = 255                      # far from the silhouette: 100 px
    mask[40:60, 50:70] = 0                       # a dark hole in the trunk: 400 px
    image = np.full((H, W, 3), 200, np.uint8)
    image[40:60, 50:70] = 20
    r = real_masks.frame_figures(None, image, mask, labels, parts, np.array([[50.0, 160.0], [55.0, 158.0]]),
                                 np.array([[60.0, 50.0], [1.0, 1.0], [np.nan, np.nan]]))
    assert r["floor"] == 300 and r["far"] == 100
    assert r["missing"] == r["dark_missing"] == 400 and r["miss_trunk"] == 400 and r["miss_left_leg"] == 0
    assert r["peer_n"] == 2 and r["peer_on_mask"] == 0 and r["peer_in_sil"] == 1    # (60, 50) falls in the hole
