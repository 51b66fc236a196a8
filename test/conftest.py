"""
Shared pytest setup: process environment, collection, markers, fixtures.

Plain helpers (paths, the ROS harness, synthetic maps and scans) are in ``helpers.py``.

- The test process gets what the console scripts set (one BLAS thread, before numpy loads) and
  its own ROS isolation: every run gets its own ``ROS_DOMAIN_ID`` (random) and localhost-only
  discovery, set here before any test calls ``rclpy.init``, so parallel runs (and a robot on the
  network) never see each other. Set ``SSM_TEST_ROS_DOMAIN_ID`` to force a domain.
- ``unit/``: fast tests of one module or function; ``integration/``: end-to-end runs (console
  scripts in subprocesses, whole bags, both nodes over DDS, ``colcon build``). Tests in
  ``integration/`` are marked ``integration``, tests that use a ROS domain (DDS) ``dds``;
  ``make test-fast`` runs ``unit/`` without ``slow`` and ``dds``.
- Without rclpy the ``test_ros_*`` modules are left out (said in the report header); under CI
  (``CI=true``) they are collected anyway and fail on import, as a missing install must.
"""
from __future__ import annotations

import os
from pathlib import Path
import random
import signal
import time

from ssm_localization.threads import limit_blas_threads

limit_blas_threads()      # first: before numpy loads (rclpy and the helpers import it)
os.environ['ROS_DOMAIN_ID'] = os.environ.get(
    'SSM_TEST_ROS_DOMAIN_ID', str(random.Random(os.getpid() ^ time.time_ns()).randint(1, 101)))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('MPLBACKEND', 'Agg')

from helpers import (_RNG, CI, fresh_domain, HAVE_RCLPY,  # noqa: E402,I100 - after the env
                     RCLPY_SKIP_REASON, RosHarness)
import pytest  # noqa: E402

if HAVE_RCLPY:
    import rclpy

HERE = Path(__file__).resolve().parent
collect_ignore_glob = [] if HAVE_RCLPY or CI else ['unit/test_ros_*.py',
                                                   'integration/test_ros_*.py']


def pytest_report_header(config) -> str | None:
    """Say when the ROS test modules are left out."""
    return None if HAVE_RCLPY else f'{RCLPY_SKIP_REASON}: test_ros_*.py not collected'


def pytest_collection_modifyitems(config, items) -> None:
    """Mark the tests of ``integration/`` ``integration`` and those that use DDS ``dds``."""
    integration = HERE / 'integration'
    for item in items:
        if integration in item.path.parents:
            item.add_marker(pytest.mark.integration)
        if 'ros_domain' in item.fixturenames:
            item.add_marker(pytest.mark.dds)


def _domain_is_quiet(domain: int, wait: float = 0.7) -> bool:
    """Return True when no other ROS node or topic shows up on ``domain`` within ``wait`` s."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node('ssm_domain_probe', context=ctx)
    try:
        end = time.monotonic() + wait
        while time.monotonic() < end:
            others = [n for n, _ in node.get_node_names_and_namespaces() if n != node.get_name()]
            topics = [t for t, _ in node.get_topic_names_and_types()
                      if t not in ('/rosout', '/parameter_events')]
            if others or topics:
                return False
            time.sleep(0.1)
        return True
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


@pytest.fixture
def within_seconds():
    """
    Fail a test still running after ten seconds (a loop that never ends) instead of hanging.

    With SIGALRM (POSIX); elsewhere the test runs unguarded.
    """
    if not hasattr(signal, 'SIGALRM'):
        yield
        return

    def expired(signum, frame):
        raise TimeoutError('still running after 10 s')
    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(10)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


@pytest.fixture(scope='session')
def ros_domain() -> int:
    """Return a ROS domain nobody else on this host uses right now (exported in ROS_DOMAIN_ID)."""
    pytest.importorskip('rclpy', reason=RCLPY_SKIP_REASON)
    if 'SSM_TEST_ROS_DOMAIN_ID' in os.environ:
        return int(os.environ['SSM_TEST_ROS_DOMAIN_ID'])
    domain = int(os.environ['ROS_DOMAIN_ID'])
    for _ in range(8):
        if _domain_is_quiet(domain):
            break
        domain = _RNG.randint(1, 101)
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    return domain


def _harness(num_threads: int | None = None):
    fresh_domain()
    harness = RosHarness() if num_threads is None else RosHarness(num_threads=num_threads)
    try:
        yield harness
    finally:
        harness.close()


@pytest.fixture
def ros(ros_domain):
    yield from _harness()


@pytest.fixture
def ros_node_threads(ros_domain):
    """Return the harness with as many executor threads as the nodes' own main() uses."""
    from ssm_localization.ros.global_localizer import EXECUTOR_THREADS
    yield from _harness(EXECUTOR_THREADS)
