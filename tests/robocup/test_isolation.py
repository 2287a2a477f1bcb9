"""rcssserver kept off the network: `elevens robocup play|train|bench` go on in a private
network namespace that holds only a loopback interface, and run as before, with a warning,
where the platform allows none."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from elevens.robocup.isolation import IsolationUnavailableError, isolated_command

ROOT = Path(__file__).resolve().parents[2]

# Records the interfaces of the network it runs in (/proc/net/dev is per namespace), then
# fails like a server that cannot start.
SPY_SERVER = """#!{python}
import os, sys
lines = open("/proc/net/dev").read().splitlines()[2:]
names = sorted(line.split(":")[0].strip() for line in lines)
with open(os.environ["SPY_OUT"], "w") as out:
    out.write(" ".join(names) + "\\n" + str(os.getuid()))
print("spy server: stopping on purpose", file=sys.stderr)
sys.exit(3)
"""


def namespaces_allowed() -> bool:
    try:
        isolated_command(["true"])
    except IsolationUnavailableError:
        return False
    return True


def run_bench(tmp_path: Path, **environment: str) -> tuple[subprocess.CompletedProcess[str], str]:
    spy = tmp_path / "rcssserver"
    spy.write_text(SPY_SERVER.replace("{python}", sys.executable))
    spy.chmod(spy.stat().st_mode | stat.S_IXUSR)
    out = tmp_path / "interfaces.txt"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "SPY_OUT": str(out), **environment}
    result = subprocess.run(
        [sys.executable, "-m", "elevens", "robocup", "bench", "--cycles", "5",
         "--rcssserver", str(spy)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )
    return result, out.read_text() if out.exists() else ""


@pytest.mark.skipif(
    not namespaces_allowed(), reason="unprivileged user and network namespaces are not allowed "
    "here (unshare --user --map-root-user --net fails)",
)
def test_the_server_runs_in_a_network_of_loopback_alone(tmp_path: Path) -> None:
    result, seen = run_bench(tmp_path)
    assert result.returncode != 0  # the spy server stops on purpose
    interfaces, uid = seen.split("\n")
    assert interfaces == "lo", (interfaces, result.stderr[-2000:])
    # The host's own network has more than loopback (else this test proves nothing).
    host = Path("/proc/net/dev").read_text().splitlines()[2:]
    assert len(host) > 1
    assert "private network namespace" not in result.stderr  # no fallback warning


def test_without_namespaces_it_warns_and_runs_as_before(tmp_path: Path) -> None:
    empty = tmp_path / "no-unshare"
    empty.mkdir()
    # No unshare on PATH (the spy server is found by its path, python by sys.executable).
    result, seen = run_bench(tmp_path, PATH=str(empty))
    assert "rcssserver runs without a private network namespace" in result.stderr
    assert "the unshare program (util-linux) is not installed" in result.stderr
    host = sorted(line.split(":")[0].strip() for line in
                  Path("/proc/net/dev").read_text().splitlines()[2:])
    assert seen.split("\n")[0] == " ".join(host)


def test_the_switch_turns_it_off(tmp_path: Path) -> None:
    result, seen = run_bench(tmp_path, ELEVENS_NETWORK_ISOLATION="0")
    host = sorted(line.split(":")[0].strip() for line in
                  Path("/proc/net/dev").read_text().splitlines()[2:])
    assert seen.split("\n")[0] == " ".join(host)
    assert "private network namespace" not in result.stderr
