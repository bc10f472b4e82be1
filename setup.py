"""ament_python / pip package for isa_mocap_ros.

Installable with ``pip install -e '.[test]'`` (what ``make venv`` does: ROS 2 Jazzy from the
``ros-jazzy-*`` PyPI wheels) or with colcon in a full ROS 2 workspace.
"""
import os

from setuptools import find_packages, setup

package_name = "isa_mocap_ros"


def tree(folder: str) -> list[tuple[str, list[str]]]:
    """data_files entries installing every file under ``folder`` to share/<pkg>/<folder>/..."""
    out = []
    for root, _dirs, files in sorted(os.walk(folder)):
        paths = sorted(os.path.join(root, f) for f in files if not f.startswith("."))
        if paths:
            out.append((os.path.join("share", package_name, root), paths))
    return out


# One console script per node, plus the ``isa-mocap`` CLI.
NODES = ["player", "recorder", "camera", "segmentation", "prediction", "estimator", "keypoints"]

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ] + tree("config") + tree("bags") + tree("launch"),
    python_requires=">=3.10",
    install_requires=[
        "numpy>=1.26,<3",
        "opencv-python-headless>=4.8",
        "pyyaml>=6",
        "rosbags>=0.11,<0.12",
        "mcap>=1.2,<2",
        "mcap-ros2-support>=0.5,<1",
        "zstandard>=0.22",
        "lz4>=4",
        "numba>=0.60",
        "scipy>=1.11",
        "tqdm>=4.66",
        "matplotlib>=3.8",
        # ROS 2 Jazzy from PyPI wheels (a full ROS install provides these itself).
        "ros-jazzy-rclpy>=7.1,<8",
        "ros-jazzy-common-interfaces>=5.3,<6",
        "ros-jazzy-rmw-fastrtps-cpp>=8.4,<9",
    ],
    extras_require={
        # 2-D keypoints (vision/landmarks.py): the LiteRT interpreter for the BlazePose model file.
        "keypoints": ["ai-edge-litert>=1.2"],
        "test": ["pytest>=8", "pytest-timeout>=2.3", "pytest-xdist>=3.8", "hypothesis>=6.100", "cma>=4"],
    },
    zip_safe=True,
    maintainer="isa_mocap_ros developers",
    description="Markerless multi-view motion capture (ISA, APF, CMA-ES, DE, PSO) as ROS 2 nodes",
    license="Apache-2.0",
    entry_points={
        "console_scripts": ["isa-mocap = isa_mocap_ros.cli.main:main"]
        + [f"{n}_node = isa_mocap_ros.nodes.{n}:main" for n in NODES],
    },
)
