"""Shared setup for the RoboCup tests: the marker for tests that need a real rcssserver,
and a fixture that runs one on free ports."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator

import pytest

from elevens.robocup.server import ServerProcess

#: Skips a test unless rcssserver is on PATH or named by $ELEVENS_RCSSSERVER.
needs_rcssserver = pytest.mark.skipif(
    shutil.which("rcssserver") is None and not os.environ.get("ELEVENS_RCSSSERVER"),
    reason=(
        "rcssserver not found on PATH (set ELEVENS_RCSSSERVER or install it from "
        "github.com/rcsoccersim/rcssserver)"
    ),
)


@pytest.fixture
def rcss_server() -> Iterator[ServerProcess]:
    """A running rcssserver with the training options on free loopback ports; stopped
    (and its temporary directory removed) after the test. Use with @needs_rcssserver."""
    server = ServerProcess()
    server.start()
    try:
        yield server
    finally:
        server.stop()
