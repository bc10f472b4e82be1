"""The estimator declares the tracker's settings from TrackerConfig (nodes/common.py declare_config): one
ROS parameter per field, named as the field, with its default and its one-line doc; config/pipeline.yaml
passes through them to the same TrackerConfig the offline tracker builds."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from isa_mocap_ros.tracking.config import LEAVES, TrackerConfig, TrackerError, field_docs

pytestmark = pytest.mark.ros
CONFIG = Path(__file__).resolve().parents[1] / "config" / "pipeline.yaml"


@pytest.fixture
def make_node(ros_domain):
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    nodes = []

    def _make(**overrides):
        node = rclpy.create_node("params_test", context=ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        nodes.append(node)
        return node

    yield _make
    for node in nodes:
        node.destroy_node()
    rclpy.shutdown(context=ctx)


def test_every_field_has_a_one_line_doc():
    docs = field_docs()
    assert list(docs) == list(LEAVES) == list(TrackerConfig().flat())
    assert all(d and "\n" not in d for d in docs.values())

    @dataclasses.dataclass(frozen=True)
    class Undocumented:
        """Attributes
        ----------
        a : int
            The a.
        """
        a: int = 1
        b: int = 2

    with pytest.raises(TrackerError, match=r"Undocumented: no one-line description .*\['b'\]"):
        field_docs(Undocumented)


def test_estimator_declares_one_parameter_per_field_with_its_doc_and_default(make_node):
    from isa_mocap_ros.nodes.common import declare_config
    from isa_mocap_ros.nodes.estimator import NOT_PARAMETERS

    node = make_node()
    values = declare_config(node, TrackerConfig, field_docs(), skip=NOT_PARAMETERS)
    docs = field_docs()
    names = [name for name in LEAVES if name not in NOT_PARAMETERS]
    assert list(values) == names and len(names) == len(docs) - len(NOT_PARAMETERS)
    for name in names:
        assert docs[name] in node.describe_parameter(name).description
    assert TrackerConfig.from_flat(**values) == TrackerConfig()


def test_overrides_reach_the_config_converted(make_node):
    from isa_mocap_ros.nodes.common import declare_config

    node = make_node(evals=200, optimizer_params="{n_particles: 50, kernel: s2}", limb_extrapolations=[0.0],
                     partition_order=["root", "torso", "left_arm", "right_arm", "left_leg", "right_leg"])
    cfg = TrackerConfig.from_flat(**declare_config(node, TrackerConfig, field_docs()))
    assert cfg.search.evals == 200 and dict(cfg.search.optimizer_params) == {"n_particles": 50, "kernel": "s2"}
    assert cfg.stages.limb_extrapolations == () and cfg.search.partition_order[:2] == ("root", "torso")
    bad = make_node(optimizer_params="[1, 2]")
    with pytest.raises(ValueError, match=r"parameter optimizer_params: expected a YAML/JSON mapping"):
        declare_config(bad, TrackerConfig, field_docs())


def test_pipeline_yaml_estimator_section_gives_the_default_tracker(make_node):
    """config/pipeline.yaml sets the tracker's defaults: the network and `isa-mocap track` track alike."""
    from isa_mocap_ros.nodes.common import declare_config

    est = yaml.safe_load(CONFIG.read_text())["/mocap/estimator"]["ros__parameters"]
    node = make_node(**{k: v for k, v in est.items() if k in LEAVES})
    assert TrackerConfig.from_flat(**declare_config(node, TrackerConfig, field_docs())) == TrackerConfig()
