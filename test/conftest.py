"""Shared fixtures: the real data folder, an isolated ROS 2 domain per test session."""
from __future__ import annotations

import os
import random
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED_DATA = Path(os.environ.get("ADT_SHARED_DATA", REPO.parent / "shared" / "data"))


def _test_domain() -> str:
    """One ROS domain per pytest run, chosen at random (or the caller's ROS_DOMAIN_ID), so that parallel runs on one
    machine (developers, CI) never see each other's topics; each pytest-xdist worker of the run takes the next
    domain after it (a worker inherits the run's environment), so the workers never see each other's either."""
    base = os.environ.get("ADT_TEST_BASE_DOMAIN") or os.environ.get("ROS_DOMAIN_ID") \
        or str(random.Random(os.getpid()).randint(1, 100))
    os.environ["ADT_TEST_BASE_DOMAIN"] = base
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    return str((int(base) + int(worker[2:])) % 100 + 1) if worker.startswith("gw") else base


os.environ["ROS_DOMAIN_ID"] = _test_domain()
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``; skips the test with a clear reason where it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA} (set ADT_SHARED_DATA)")
    return SHARED_DATA


def require_data(relative: str) -> Path:
    path = SHARED_DATA / relative
    if not path.exists():
        pytest.skip(f"real data {relative} not found under {SHARED_DATA}")
    return path
