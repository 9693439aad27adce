"""Shared fixtures: a ROS 2 domain of our own per test run, and children that always end."""

from __future__ import annotations

import os

import pytest

from stream_viz.testing import Children, claim_domain, ros_env, shm_clean


@pytest.fixture(scope="session")
def ros_domain() -> int:
    """This run's own ROS_DOMAIN_ID, also set in os.environ (with LOCALHOST discovery)."""
    domain = claim_domain()
    os.environ.update(ros_env(domain))
    yield domain
    shm_clean()


@pytest.fixture
def children(ros_domain, tmp_path):
    """Start real Python/ROS children; all are ended (SIGINT, then SIGKILL) after the test."""
    kids = Children(ros_env(ros_domain), tmp_path)
    yield kids
    kids.end_all()
