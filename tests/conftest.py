"""Shared pytest setup: the --slow flag holds long tests out of the default suite, and the
property tests draw the same examples on every run unless asked to explore."""

import os
import shutil
import tempfile

# The suite runs in two worker processes (pyproject: pytest -n 2). Where a GPU is visible, each
# would otherwise take 75% of its memory when JAX starts.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

# Much of the suite's time is XLA compiling small programs that then run for milliseconds.
# The suite checks what programs compute, not how fast: LLVM at -O1 without its expensive
# passes compiles faster and still runs the long games well (-O0 compiles faster still but
# runs the panel's games at half speed). Runs, benches and the CLI keep XLA's defaults;
# ELEVENS_TEST_XLA_DEFAULTS=1 runs the suite with them too. Set before jax starts its
# backend; subprocesses a test starts inherit it.
_FAST_COMPILE = ("--xla_backend_optimization_level=1", "--xla_llvm_disable_expensive_passes=true")
if not os.environ.get("ELEVENS_TEST_XLA_DEFAULTS"):
    _flags = os.environ.get("XLA_FLAGS", "").split()
    _names = {flag.split("=")[0] for flag in _flags}
    _flags += [flag for flag in _FAST_COMPILE if flag.split("=")[0] not in _names]
    os.environ["XLA_FLAGS"] = " ".join(_flags)

import jax  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

# CI and the README's test command: the same examples every run, so a fuzz find cannot make one
# CI run fail and the next pass. HYPOTHESIS_PROFILE=explore draws new ones (what a person runs
# to look for bugs; every find becomes a named regression test).
settings.register_profile("default", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


# One compile per computation in a test session: many tests build the same jitted function
# (a fresh closure each time, e.g. the update step of every training run), which jax's
# in-memory cache cannot share. jax's persistent cache keys on the lowered program, so a second
# build with the same shapes loads the executable instead of compiling it again. The directory
# is new for each session and removed at its end: no run reuses another's compiles.
# Only compiles over 0.1 s are stored (the op-by-op kernels of eager code are not worth a file).
# With pytest -n, the controlling process makes the directory and its workers share it (they
# inherit the variable); only the process that made it removes it.
_CACHE_VARIABLE = "ELEVENS_TEST_COMPILE_CACHE"
_OWNS_CACHE = _CACHE_VARIABLE not in os.environ
if _OWNS_CACHE:
    os.environ[_CACHE_VARIABLE] = tempfile.mkdtemp(prefix="elevens-test-compiles-")
_COMPILE_CACHE = os.environ[_CACHE_VARIABLE]
_CACHE_SETTINGS = {
    "jax_compilation_cache_dir": _COMPILE_CACHE,
    "jax_persistent_cache_min_compile_time_secs": 0.1,
    "jax_persistent_cache_min_entry_size_bytes": 0,
}
for _name, _value in _CACHE_SETTINGS.items():
    jax.config.update(_name, _value)
    # The same settings for the Python subprocesses a test starts (`python -m elevens ...`,
    # the parallel worker): jax reads them from the environment, so a subprocess loads what the
    # session already compiled (and its repeats load its own) instead of compiling again.
    os.environ[_name.upper()] = str(_value)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if _OWNS_CACHE:
        shutil.rmtree(_COMPILE_CACHE, ignore_errors=True)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--slow", action="store_true", default=False, help="run slow tests too")
    parser.addoption(
        "--compile-log", metavar="FILE", default=None,
        help="append a line per test: its seconds, XLA compiles and seconds compiling, and "
             "its id (each worker of pytest -n to FILE.<worker>); many compiles in a test "
             "not about eager JAX mean code running op by op")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--slow"):
        return
    skip_slow = pytest.mark.skip(reason="slow test: run with --slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip_slow)


# --compile-log: XLA compiles counted per test through jax.monitoring, written where the tests
# run (a worker of pytest -n, or the one process of -n 0; not xdist's controlling process).
_COMPILES = {"count": 0, "seconds": 0.0}
_TEST_SECONDS: dict[str, float] = {}
_COMPILE_LOG: list[str] = []


def _count_compile(event: str, duration_secs: float, **_: str | int) -> None:
    if event == "/jax/core/compile/backend_compile_duration":
        _COMPILES["count"] += 1
        _COMPILES["seconds"] += duration_secs


def pytest_configure(config: pytest.Config) -> None:
    path = config.getoption("--compile-log")
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    controller = worker is None and bool(config.getoption("numprocesses", None))
    if path and not controller:
        _COMPILE_LOG.append(f"{path}.{worker}" if worker else str(path))
        jax.monitoring.register_event_duration_secs_listener(_count_compile)


def pytest_runtest_setup(item: pytest.Item) -> None:
    _COMPILES["count"], _COMPILES["seconds"] = 0, 0.0


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if not _COMPILE_LOG:
        return
    _TEST_SECONDS[report.nodeid] = _TEST_SECONDS.get(report.nodeid, 0.0) + report.duration
    if report.when == "teardown":
        seconds = _TEST_SECONDS.pop(report.nodeid)
        with open(_COMPILE_LOG[0], "a", encoding="utf-8") as f:
            f.write(f"{seconds:.2f} {_COMPILES['count']} {_COMPILES['seconds']:.2f} "
                    f"{report.nodeid}\n")
