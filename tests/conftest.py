"""Shared pytest setup: the --slow flag holds long tests out of the default suite, and the
property tests draw the same examples on every run unless asked to explore."""

import os

import pytest
from hypothesis import settings

# CI and the README's test command: the same examples every run, so a fuzz find cannot make one
# CI run fail and the next pass. HYPOTHESIS_PROFILE=explore draws new ones (what a person runs
# to look for bugs; every find becomes a named regression test).
settings.register_profile("default", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--slow", action="store_true", default=False, help="run slow tests too")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--slow"):
        return
    skip_slow = pytest.mark.skip(reason="slow test: run with --slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip_slow)
