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


# ---------------------------------------------------------------------------------------------- scheduling
# `make test` runs `pytest -n 2 --dist loadgroup --no-loadscope-reorder`: each group below runs whole on one
# worker, in the order of this list (the longest first, so no long file starts last on one worker while the other
# idles), then the other files, one group each, in collection order. Groups keep a module's (or, for the network
# files, a session's) fixtures from being built on both workers. The order is a schedule, from an idle 2-core run's
# `--durations` (docs/history/ci_test_time_s33.md): a stale entry costs balance, never a result.
TEST_GROUPS = (
    ("network_fixture", ("test_network.py", "test_network_keypoints.py", "test_network_fuzz.py")),
    ("energy_silhouette", ("test_energy_silhouette.py",)),
    ("shape_calibration", ("test_shape_calibration.py",)),
    ("player_recorder", ("test_player_recorder.py",)),
    ("bench_results", ("test_bench_results.py",)),
    ("node_segmentation", ("test_node_segmentation.py",)),
    ("network_realtime", ("test_network_realtime.py",)),
    ("real_recording", ("test_real_recording.py",)),
    ("network_live", ("test_network_live.py",)),
    ("network_degrade", ("test_network_degrade.py",)),
    ("node_estimator", ("test_node_estimator.py",)),
    ("optim_compiled", ("test_optim_compiled.py",)),
    ("optim_bench", ("test_optim_bench.py",)),
    ("launcher", ("test_launcher.py",)),
    ("node_estimator_keypoints", ("test_node_estimator_keypoints.py",)),
    ("node_estimator_startup", ("test_node_estimator_startup.py",)),
    ("bench_robustness", ("test_bench_robustness.py",)),
    ("node_prediction", ("test_node_prediction.py",)),
    ("bench_compare", ("test_bench_compare.py",)),
    ("bench_mesh", ("test_bench_mesh.py",)),
)


def schedule(files: list[str]) -> tuple[list[int], list[str]]:
    """The run order of test items from their ``files`` (one name per item, in collection order) and each item's
    group: :data:`TEST_GROUPS`' files first, in that order, the others after in collection order, each its own
    group (its file's name). Stable: a file's items keep their order and stay together."""
    group_of = {f: (rank, name) for rank, (name, fs) in enumerate(TEST_GROUPS) for f in fs}
    rest = len(TEST_GROUPS)
    keys = [group_of.get(f, (rest, f)) for f in files]
    order = sorted(range(len(files)), key=lambda i: keys[i][0])
    return order, [k[1] for k in keys]


def pytest_configure(config):
    # xdist registers the mark; so does this, for runs without xdist (-p no:xdist) under --strict-markers
    config.addinivalue_line("markers", "xdist_group(name): run with the other tests of the group on one xdist worker")


@pytest.hookimpl(tryfirst=True)          # before xdist's own hook, which reads the groups into the test ids
def pytest_collection_modifyitems(config, items):
    order, groups = schedule([item.path.name for item in items])
    for item, group in zip(items, groups):
        item.add_marker(pytest.mark.xdist_group(group))
    items[:] = [items[i] for i in order]


# ---------------------------------------------------------------------------------------------- shared runs
FIXTURE_BAG = REPO / "bags" / "fixture"
#: the offline tracker's settings the network tests on bags/fixture compare their lockstep runs with
FIXTURE_TRACK_SETTINGS = ("--optimizer", "isa", "--evals", "300", "--seed", "3", "--shape", "default")


@pytest.fixture(scope="session")
def fixture_track(tmp_path_factory):
    """``fixture_track(weight)``: the directory of ``isa-mocap track bags/fixture --keypoint-weight weight``
    with :data:`FIXTURE_TRACK_SETTINGS`, run once per weight in a session and shared by the network tests that
    compare a lockstep run with it (test_network, test_network_keypoints, test_network_fuzz: one xdist group,
    so one worker runs them all). ``weight=None``: ``track``'s default, resolved as ``track`` resolves it
    (``default_keypoint_weight``: 1 with the landmark model, 0 without), so it is the same run as that weight's."""
    from isa_mocap_ros.cli.keypoint_options import default_keypoint_weight

    done: dict[str, Path] = {}

    def _track(weight: str | None) -> Path:
        if weight is None:
            weight = f"{default_keypoint_weight()[0]:g}"
        if weight not in done:
            out = tmp_path_factory.mktemp(f"fixture_track_kw{weight}")
            res = subprocess.run([sys.executable, "-m", "isa_mocap_ros.cli.main", "track", str(FIXTURE_BAG), "--out",
                                  str(out), "--keypoint-weight", weight, *FIXTURE_TRACK_SETTINGS],
                                 capture_output=True, text=True, timeout=400)
            assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
            done[weight] = out
        return done[weight]

    return _track
