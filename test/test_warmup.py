"""`isa-mocap warmup` (make venv runs it): the nodes' kernels compiled into numba's cache, the nodes stopped."""
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
