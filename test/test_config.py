"""config/pipeline.yaml agrees with the nodes' declared parameters and with the tracker's defaults,
so the network and `isa-mocap track` use the same settings unless a user changes them."""
from __future__ import annotations

from pathlib import Path

import yaml

from isa_mocap_ros.tracking.tracker import TrackerConfig

REPO = Path(__file__).resolve().parents[1]


def test_estimator_section_matches_tracker_defaults():
    est = yaml.safe_load((REPO / "config" / "pipeline.yaml").read_text())["/mocap/estimator"]["ros__parameters"]
    tc = TrackerConfig()
    pairs = {"optimizer": tc.optimizer, "evals": tc.evals_per_frame, "energy": tc.energy_method,
             "downsample": tc.downsample, "search_radius_rad": tc.search_radius_rad, "predictor": tc.predictor,
             "predictor_order": tc.predictor_order, "prior_eta": tc.prior_eta, "seed": tc.seed,
             "pelvis_fraction": tc.pelvis_fraction,
             "torso_fraction": tc.torso_fraction, "limb_fold_deg": tc.limb_fold_deg,
             "limb_hinge_window_deg": tc.limb_hinge_window_deg,
             "limb_proposals": tc.limb_proposals,
             "limb_proposal_limbs": list(tc.limb_proposal_limbs), "limb_hinge_limbs": list(tc.limb_hinge_limbs),
             "limb_extrapolations": list(tc.limb_extrapolations),
             "init_confirm_frames": tc.init_confirm_frames,
             "heading_travel_cue": tc.heading_travel_cue,
             "partition_order": list(tc.partition_order), "gate_margin_px": tc.gate_margin_px,
             "hull_filter": tc.hull_filter, "hull_dilate_px": tc.hull_dilate_px,
             "hull_keep_px": tc.hull_keep_px,
             "hull_pad_m": tc.hull_pad_m, "view_weights": tc.view_weights}
    assert {k: est[k] for k in pairs} == pairs


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
    names = {f for f in TrackerConfig.__dataclass_fields__}
    for gone in ("pelvis_move", "refine_fraction", "refine_partitions", "hull_misses", "init_confirm_share"):
        assert gone not in est and gone not in names
