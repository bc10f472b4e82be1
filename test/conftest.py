"""Shared fixtures: private ROS domains, child-process helpers, the shared motion data."""
from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from isa_mocap_ros.rosenv import ros_env

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("ISA_MOCAP_SHARED", REPO.parent / "shared"))
CMU_WALK = SHARED / "data" / "mocap" / "cmu_131_01_walk.bvh"

_domain_counter = itertools.count()


def _worker_index() -> int:
    wid = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return int(wid[2:]) if wid.startswith("gw") and wid[2:].isdigit() else 0


def _domain_range() -> tuple[int, int]:
    """The ROS_DOMAIN_IDs the suite may use: 10..99, or ``ISA_MOCAP_TEST_DOMAINS=LO-HI`` (inclusive),
    so two suites running at once on one machine (two checkouts) can be kept apart."""
    text = os.environ.get("ISA_MOCAP_TEST_DOMAINS", "10-99")
    try:
        lo, hi = (int(v) for v in text.split("-"))
    except ValueError:
        raise ValueError(f"ISA_MOCAP_TEST_DOMAINS={text!r}: expected LO-HI, e.g. 10-40") from None
    if not 0 <= lo <= hi <= 101:
        raise ValueError(f"ISA_MOCAP_TEST_DOMAINS={text!r}: ROS domain ids lie in 0..101")
    return lo, hi


def domain_for(worker: int, workers: int, run: int, k: int, lo: int = 10, hi: int = 99) -> int:
    """ROS_DOMAIN_ID (``lo..hi``) of a worker's ``k``-th test: worker ``w`` of ``W`` only ever uses ids
    ``≡ w (mod W)`` after ``lo``, so tests running at the same time on different workers never share a
    domain (a hash of pid and worker did, now and then: a recorder then got another test's masks);
    ``run`` shifts where the cycle starts, so consecutive runs do not reuse the same ids first."""
    workers = max(1, workers)
    slots = max(1, (hi - lo + 1) // workers)
    return lo + ((run + k) % slots) * workers + worker % workers


def next_domain() -> int:
    """The next ROS_DOMAIN_ID of this worker (see :func:`domain_for`); for fixtures of wider scope."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    run = os.getppid() if "PYTEST_XDIST_WORKER" in os.environ else os.getpid()   # the xdist controller's pid
    return domain_for(_worker_index(), workers, run, next(_domain_counter), *_domain_range())


@pytest.fixture
def ros_domain() -> int:
    """A ROS_DOMAIN_ID of its own for each test (see :func:`domain_for`)."""
    return next_domain()


@pytest.fixture
def rosenv(ros_domain):
    """Environment for child processes: localhost discovery on the test's own domain."""
    env = ros_env(ros_domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


class ChildProcess:
    """A child process with its output in files, stopped by a signal like a user would."""

    def __init__(self, args: list[str], env: dict[str, str], log_dir: Path, name: str):
        self.name = name
        self.out_path = log_dir / f"{name}.out"
        self._out = open(self.out_path, "wb")
        self.popen = subprocess.Popen(args, env=env, stdout=self._out, stderr=subprocess.STDOUT,
                                      start_new_session=True)

    def output(self) -> str:
        if not self._out.closed:
            self._out.flush()
        return self.out_path.read_text(errors="replace")

    def wait_for_output(self, text: str, timeout: float = 30.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if text in self.output():
                return True
            if self.popen.poll() is not None:
                return text in self.output()
            time.sleep(0.05)
        return False

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15.0) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(5)
        self._out.close()
        return self.popen.returncode


@pytest.fixture
def spawn(rosenv, tmp_path):
    """``spawn(name, *args)`` starts ``python args...`` in the test's ROS domain; all are stopped after."""
    procs: list[ChildProcess] = []

    def _spawn(name: str, *args: str, env: dict[str, str] | None = None) -> ChildProcess:
        p = ChildProcess([sys.executable, *args], env or rosenv, tmp_path, name)
        procs.append(p)
        return p

    yield _spawn
    for p in procs:
        p.stop(signal.SIGKILL if p.popen.poll() is None else signal.SIGINT, timeout=5)


@pytest.fixture(scope="session")
def landmark_model() -> Path:
    """The BlazePose landmark model file that `make models` caches (skips, naming what is missing, where it is
    absent)."""
    from isa_mocap_ros.vision.landmark_model import ModelUnavailable, landmark_model_path
    try:
        return landmark_model_path()
    except ModelUnavailable as exc:
        pytest.skip(f"landmark model not available (make models): {exc}")


@pytest.fixture
def cmu_walk() -> Path:
    """The CMU walk BVH from ../shared (skips where it is absent, as DESIGN §6 asks)."""
    if not CMU_WALK.exists():
        pytest.skip(f"CMU motion file not found at {CMU_WALK} (set ISA_MOCAP_SHARED to the shared/ folder)")
    return CMU_WALK


def joint_states_by_stamp(bag: Path) -> dict:
    """``/mocap/joint_states`` of a recorded bag: positions (an array) by header stamp (ns)."""
    import numpy as np

    import msg_adapters as ma
    from isa_mocap_ros.bag import BagReader

    out = {}
    with BagReader(bag) as r:
        for m in r.messages(["/mocap/joint_states"]):
            msg = ma.from_cdr(m.data, m.type)
            out[ma.stamp_to_ns(msg.header)] = np.array(msg.position)
    return out
