"""Shared setup for the RoboCup tests: the marker for tests that need a real rcssserver,
and a fixture that runs one on free ports."""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from collections.abc import Iterator
from pathlib import Path

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


def process_running(pid: int) -> bool:
    """Whether process ``pid`` runs; a zombie (exited, not yet reaped) counts as stopped."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with contextlib.suppress(OSError):
        return "Z" not in Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    return True


def wait_stopped(pid: int, timeout_s: float = 300.0) -> bool:
    """Whether process ``pid`` has stopped within ``timeout_s`` (polled; it returns as soon
    as it has, the bound only ends the wait for one that never stops)."""
    deadline = time.monotonic() + timeout_s
    while process_running(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not process_running(pid)
