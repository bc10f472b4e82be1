"""config/pipeline.yaml agrees with the nodes' declared parameters and with the tracker's defaults,
so the network and `isa-mocap track` use the same settings unless a user changes them."""
from __future__ import annotations

from pathlib import Path

import yaml

from isa_mocap_ros.tracking.config import LEAVES, TrackerConfig

REPO = Path(__file__).resolve().parents[1]


def test_estimator_section_matches_tracker_defaults():
    """The estimator's parameters named as TrackerConfig fields hold the fields' defaults (the names are
    the fields' own: the node declares them from the dataclass)."""
    est = yaml.safe_load((REPO / "config" / "pipeline.yaml").read_text())["/mocap/estimator"]["ros__parameters"]
    tc = TrackerConfig().flat()
    shown = {k: v for k, v in est.items() if k in LEAVES}
    assert len(shown) >= 30                          # the settings a user tunes are listed there
    want = {k: (list(tc[k]) if isinstance(tc[k], tuple) else tc[k]) for k in shown}
    want["optimizer_params"] = yaml.safe_dump(dict(tc["optimizer_params"]), default_flow_style=True).strip()
    assert shown == want


def test_prediction_node_and_estimator_use_the_same_predictor():
    cfg = yaml.safe_load((REPO / "config" / "pipeline.yaml").read_text())
    pred, est = cfg["/mocap/prediction"]["ros__parameters"], cfg["/mocap/estimator"]["ros__parameters"]
    assert pred["predictor"] == est["predictor"] and pred["order"] == est["predictor_order"]
    assert abs(pred["frame_period_s"] - est["frame_period_s"]) < 1e-12


def test_every_section_is_a_node_with_parameters():
    cfg = yaml.safe_load((REPO / "config" / "pipeline.yaml").read_text())
    assert set(cfg) >= {"/mocap/camera", "/mocap/segmentation", "/mocap/prediction", "/mocap/estimator"}
    assert all(isinstance(v.get("ros__parameters"), dict) for v in cfg.values())


def test_deleted_settings_are_gone_everywhere():
    """Settings that only selected variants measured worse were deleted with their code (issue #31)."""
    est = yaml.safe_load((REPO / "config" / "pipeline.yaml").read_text())["/mocap/estimator"]["ros__parameters"]
    names = set(LEAVES)
    for gone in ("pelvis_move", "refine_fraction", "refine_partitions", "hull_misses", "init_confirm_share"):
        assert gone not in est and gone not in names
