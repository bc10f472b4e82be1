"""TrackerConfig as nested frozen groups (tracking/config.py): unique leaf names (they are the estimator's ROS
parameter names and config/pipeline.yaml's keys), building from and listing flat leaves, each group checking
its own settings; and the shared setting checks (config_checks.py) both TrackerConfig and SegmentationConfig use."""
from __future__ import annotations

import dataclasses

import pytest

from isa_mocap_ros.config_checks import check_bool, check_choice, check_number
from isa_mocap_ros.tracking import config as tc
from isa_mocap_ros.tracking.config import LEAVES, TrackerConfig, TrackerError, field_docs
from isa_mocap_ros.vision.segmentation_config import SegmentationConfig, SegmentationError

#: the tracker's settings before they were grouped (issue #31): the names must not change, since they are the
#: estimator's ROS parameters, config/pipeline.yaml's keys and the names the CLI and benches build configs with
FLAT_NAMES = {
    "optimizer", "evals", "optimizer_params", "search_radius_rad", "spread_velocity_gain", "root_translation_radius_m",
    "predictor", "predictor_order", "joint_velocity_gain", "prior_eta", "prior_file", "energy", "downsample",
    "n_model_points", "n_mask_points", "seed", "init_yaw_steps", "init_refine_evals", "init_keep", "init_polish",
    "init_confirm_frames", "init_confirm_ratio", "init_confirm_margin", "heading_travel_cue", "pelvis_fraction",
    "torso_fraction", "leg_untwist", "leg_untwist_tolerance", "leg_untwist_margin", "limb_proposals",
    "limb_proposal_limbs", "limb_hinge_limbs", "limb_extrapolations",
    "limb_fold_deg", "limb_hinge_window_deg", "partition_order", "contour_iterations", "contour_extra_iterations",
    "contour_extra_partitions", "contour_points", "contour_max_px", "gate_margin_px", "hull_filter",
    "hull_dilate_px", "hull_keep_px", "hull_pad_m", "view_weights", "keypoint_weight", "keypoint_sigma_m", "temporal_weight", "temporal_joints",
    "max_frames_ahead", "silhouette_core_px", "first_frame_hull", "coarse_fraction"}


def test_leaf_names_are_unique_and_unchanged():
    names = [f.name for g in dataclasses.fields(TrackerConfig) for f in dataclasses.fields(g.default_factory)]
    assert len(names) == len(set(names)) == len(LEAVES) == 55
    assert set(names) == FLAT_NAMES
    assert all(getattr(getattr(TrackerConfig(), LEAVES[n]), n) is not None for n in names)


def test_a_setting_in_two_groups_is_refused():
    @dataclasses.dataclass(frozen=True)
    class Other:
        evals: int = 3

    with pytest.raises(TrackerError, match=r"setting 'evals' in both search and other"):
        tc._leaves({"search": tc.SearchConfig, "other": Other})


def test_flat_round_trip_and_replace():
    cfg = TrackerConfig.from_flat(evals=600, seed=3, hull_filter=False, keypoint_weight=0.5)
    assert (cfg.search.evals, cfg.search.seed, cfg.masks.hull_filter, cfg.keypoints.keypoint_weight) == \
        (600, 3, False, 0.5)
    assert cfg.stages == tc.StageConfig() and cfg.objective == tc.ObjectiveConfig()
    flat = cfg.flat()
    assert list(flat) == list(LEAVES) and TrackerConfig.from_flat(**flat) == cfg
    again = cfg.replace(evals=900, init_polish=False)
    assert (again.search.evals, again.search.seed, again.first_frame.init_polish) == (900, 3, False)
    assert cfg.search.evals == 600                                # a copy: the original is unchanged
    assert TrackerConfig.from_flat() == TrackerConfig()


def test_groups_are_frozen_and_check_their_settings():
    cfg = TrackerConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.search.evals = 3
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.search = tc.SearchConfig()
    with pytest.raises(TrackerError, match=r"evals: expected an integer >= 1, received 0"):
        TrackerConfig.from_flat(evals=0)
    with pytest.raises(TrackerError, match=r"evals: expected an integer >= 1, received 0"):
        cfg.replace(evals=0)
    with pytest.raises(TrackerError, match=r"hull_filter: expected true or false, received 'yes'"):
        tc.MaskConfig(hull_filter="yes")
    with pytest.raises(TrackerError, match=r"pelvis_fraction \+ torso_fraction: expected below 1"):
        TrackerConfig.from_flat(pelvis_fraction=0.6, torso_fraction=0.5)
    with pytest.raises(TrackerError, match=r"evalz: not a tracker setting \(expected one of optimizer, evals"):
        TrackerConfig.from_flat(evalz=3)
    with pytest.raises(TrackerError, match=r"search: expected a SearchConfig, received dict"):
        TrackerConfig(search={"evals": 3})


def test_each_group_documents_each_setting_on_one_line():
    for g in dataclasses.fields(TrackerConfig):
        docs = field_docs(g.default_factory)
        assert list(docs) == [f.name for f in dataclasses.fields(g.default_factory)]
        assert all(d and "\n" not in d for d in docs.values())
    assert list(field_docs(TrackerConfig)) == list(LEAVES)


def test_shared_checks_name_the_setting():
    check_number("a", 3, lo=1, integer=True)
    check_number("b", 0.5, lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    for value, match in [(0, r"a: expected an integer >= 1, received 0"), (True, r"received True"),
                         (2.0, r"a: expected an integer >= 1, received 2.0")]:
        with pytest.raises(KeyError, match=match):
            check_number("a", value, lo=1, integer=True, error=KeyError)
    with pytest.raises(ValueError, match=r"b: expected a finite number in \(0.0, 1.0\), received 1.0"):
        check_number("b", 1.0, lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    with pytest.raises(ValueError, match=r"c: expected a finite number > 0, received nan"):
        check_number("c", float("nan"), lo=0, lo_open=True)
    with pytest.raises(ValueError, match=r"d: expected a finite number <= 2, received 'x'"):
        check_number("d", "x", hi=2)
    check_bool("e", False)
    with pytest.raises(ValueError, match=r"e: expected true or false, received 1"):
        check_bool("e", 1)
    check_choice("f", "x", ("x", "y"))
    with pytest.raises(ValueError, match=r"f: expected one of x, y, received 'z'"):
        check_choice("f", "z", ("x", "y"))


def test_segmentation_config_uses_the_shared_checks():
    with pytest.raises(SegmentationError, match=r"update_rate: expected a finite number in \[0.0, 1.0\], received 1.5"):
        SegmentationConfig(update_rate=1.5)
    with pytest.raises(SegmentationError, match=r"history: expected an integer >= 1, received 0"):
        SegmentationConfig(history=0)
    with pytest.raises(SegmentationError, match=r"method: expected one of colour, mog2, knn, received 'gmm'"):
        SegmentationConfig(method="gmm")
