"""`isa-mocap warmup` (make venv runs it): the nodes' and the library's kernels compiled into numba's cache, the
nodes stopped."""
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.timeout(900)]


def test_warmup_starts_both_nodes_without_discovery_and_stops_them():
    res = subprocess.run([sys.executable, "-m", "isa_mocap_ros.cli.main", "warmup"], capture_output=True, text=True,
                         timeout=880)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "warmup: kernels compiled and cached" in res.stdout, res.stdout
    assert "Traceback" not in res.stderr and "warm-up failed" not in res.stderr, res.stderr
    from isa_mocap_ros.cli.warmup_library import GROUPS
    for group in GROUPS:                           # each library group ran to its end
        assert f"warmup_library: {group} done" in res.stdout, res.stdout


def test_library_groups_must_be_named():
    from isa_mocap_ros.cli.warmup_library import main
    assert main(["nope"]) == 2
    assert main([]) == 2
