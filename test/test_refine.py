"""Model-guided mask refinement (vision/refine.py): a graph cut seeded by the model's silhouette."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from isa_mocap_ros.vision.refine import RefineError, refine_mask


def iou(a, b) -> float:
    a, b = a > 0, b > 0
    return float((a & b).sum() / max(1, (a | b).sum()))


def scene(rng):
    """A textured floor, a person (skin-coloured torso, dark shorts close to the floor's colour), the
    exact silhouette, and a background-subtraction mask with the shorts missed and a ghost elsewhere."""
    H, W = 240, 160
    img = np.clip(rng.normal(60, 6, size=(H, W, 3)), 0, 255).astype(np.uint8)       # dark floor
    img[:60] = np.clip(rng.normal(200, 6, size=(60, W, 3)), 0, 255).astype(np.uint8)  # bright wall
    truth = np.zeros((H, W), np.uint8)
    cv2.ellipse(truth, (80, 40), (14, 18), 0, 0, 360, 255, -1)                       # head
    cv2.rectangle(truth, (60, 58), (100, 130), 255, -1)                              # torso
    cv2.rectangle(truth, (62, 130), (98, 160), 255, -1)                              # shorts
    cv2.rectangle(truth, (64, 160), (78, 220), 255, -1)                              # legs
    cv2.rectangle(truth, (84, 160), (98, 220), 255, -1)
    skin = np.array([220, 170, 140], np.uint8)
    img[truth > 0] = np.clip(skin + rng.normal(0, 5, size=((truth > 0).sum(), 3)), 0, 255).astype(np.uint8)
    shorts = np.zeros_like(truth)
    shorts[130:161, 62:99] = 255
    img[shorts > 0] = np.clip(np.array([25, 25, 30]) + rng.normal(0, 4, size=((shorts > 0).sum(), 3)), 0,
                              255).astype(np.uint8)
    mask = truth.copy()
    mask[shorts > 0] = 0                       # the shorts over the floor: missed
    cv2.circle(mask, (20, 200), 12, 255, -1)   # a ghost far from the person
    prior = np.zeros_like(truth)               # the model: the silhouette a few pixels off
    prior[3:, 2:] = truth[:-3, :-2]
    return img, truth, mask, prior


def test_refinement_restores_missed_parts_and_drops_far_foreground():
    img, truth, mask, prior = scene(np.random.default_rng(0))
    out = refine_mask(img, mask, prior)
    assert out.dtype == np.uint8 and set(np.unique(out)) <= {0, 255}
    assert iou(out, truth) > iou(mask, truth) + 0.1 and iou(out, truth) > 0.85, (iou(out, truth), iou(mask, truth))
    assert out[145, 80] == 255                 # the shorts are back
    assert out[200, 20] == 255                 # far foreground: left to the tracker's gate and hull filter
    far = refine_mask(img, mask, prior, drop_far=True)
    assert far[200, 20] == 0 and np.array_equal(far[:, 40:], out[:, 40:])
    # deterministic, and the same at full resolution within a few per cent
    assert np.array_equal(out, refine_mask(img, mask, prior))
    assert iou(refine_mask(img, mask, prior, max_side=1000), out) > 0.95


def test_refinement_keeps_the_mask_when_the_model_is_not_in_view():
    img, truth, mask, _ = scene(np.random.default_rng(1))
    out = refine_mask(img, mask, np.zeros_like(mask))
    assert np.array_equal(out > 0, mask > 0)


@pytest.mark.parametrize("kw, match", [
    (dict(image=np.zeros((10, 10), np.uint8)), "image: expected an \\(H, W, 3\\) uint8"),
    (dict(mask=np.zeros((5, 5), np.uint8)), "mask, prior: expected the image's size"),
    (dict(margin=0.0), "margin, core, iterations"),
])
def test_refinement_bad_input(kw, match):
    args = dict(image=np.zeros((10, 10, 3), np.uint8), mask=np.zeros((10, 10), np.uint8),
                prior=np.zeros((10, 10), np.uint8))
    opts = {k: v for k, v in kw.items() if k not in args}
    args.update({k: v for k, v in kw.items() if k in args})
    with pytest.raises(RefineError, match=match):
        refine_mask(args["image"], args["mask"], args["prior"], **opts)
