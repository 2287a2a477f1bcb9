"""ServerProcess, find_rcssserver and the port/option helpers: with a stand-in binary
(a small Python script) everywhere, then with a real rcssserver when one is installed."""

from __future__ import annotations

import os
import signal
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from elevens.robocup.server import (
    ENV_VAR,
    INSTALL_HINT,
    TRAINING_OPTIONS,
    RcssserverNotFound,
    ServerAddress,
    ServerProcess,
    find_rcssserver,
    free_port_triple,
)
from tests.robocup.conftest import needs_rcssserver, process_running, wait_stopped

# A stand-in rcssserver: binds the player port it is given, reports its arguments and
# environment in its log, then waits to be killed.
FAKE_SERVER = f"""#!{sys.executable}
import os, socket, sys, time
args = dict(a.split("=", 1) for a in sys.argv[1:])
if "server::fail" in args:
    print("cmd line args: 1: error: 'server' has no parameter called 'fail'", flush=True)
    sys.exit(1)
print("CONF", os.environ.get("RCSS_CONF_DIR"), flush=True)
print("CWD", os.getcwd(), flush=True)
print("ARGS", " ".join(sys.argv[1:]), flush=True)
print("PID", os.getpid(), flush=True)
if "server::nobind" not in args:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("0.0.0.0", int(args["server::port"])))
time.sleep(60)
"""


@pytest.fixture
def fake_binary(tmp_path: Path) -> str:
    path = tmp_path / "bin" / "rcssserver"
    path.parent.mkdir()
    path.write_text(FAKE_SERVER)
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return str(path)


# -- finding the binary -----------------------------------------------------------------


def test_missing_rcssserver_says_so_where_it_looked_and_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv(ENV_VAR, raising=False)
    with pytest.raises(RcssserverNotFound) as info:
        find_rcssserver()
    text = str(info.value)
    assert isinstance(info.value, FileNotFoundError)
    assert text.startswith("rcssserver was not found")
    assert str(tmp_path) in text and ENV_VAR in text
    assert "github.com/rcsoccersim/rcssserver" in text and "cmake" in text
    assert "libboost-system-dev" in text and INSTALL_HINT in text


def test_explicit_path_and_environment_must_point_at_an_executable(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fake_binary: str
) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    with pytest.raises(RcssserverNotFound, match="the given path .*nope.*not an executable"):
        find_rcssserver(tmp_path / "nope")
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "missing"))
    with pytest.raises(RcssserverNotFound, match=f"\\${ENV_VAR}=.*missing"):
        find_rcssserver()
    not_exec = tmp_path / "plain"
    not_exec.write_text("")
    with pytest.raises(RcssserverNotFound, match="not an executable"):
        find_rcssserver(not_exec)


def test_lookup_order_is_explicit_then_environment_then_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fake_binary: str
) -> None:
    other = tmp_path / "other" / "rcssserver"
    other.parent.mkdir()
    other.write_text(FAKE_SERVER)
    other.chmod(0o755)
    monkeypatch.setenv("PATH", str(Path(fake_binary).parent))
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert find_rcssserver() == fake_binary
    monkeypatch.setenv(ENV_VAR, str(other))
    assert find_rcssserver() == str(other)
    assert find_rcssserver(fake_binary) == fake_binary
    assert find_rcssserver("rcssserver") == fake_binary  # a command name is looked up on PATH


# -- ports and options -------------------------------------------------------------------


def test_free_port_triples_are_consecutive_free_and_distinct() -> None:
    seen: set[int] = set()
    for _ in range(5):
        address = free_port_triple()
        ports = (address.port, address.coach_port, address.olcoach_port)
        assert ports == (address.port, address.port + 1, address.port + 2)
        assert address.host == "127.0.0.1" and not seen & set(ports)
        seen.update(ports)
        for port in ports:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.bind(("0.0.0.0", port))


def test_server_address_checks_ports() -> None:
    assert ServerAddress.from_port(6000) == ServerAddress(6000, 6001, 6002, "127.0.0.1")
    with pytest.raises(ValueError, match="port 0 must be an int in"):
        ServerAddress(0, 1, 2)
    with pytest.raises(ValueError, match="coach_port 70000"):
        ServerAddress(6000, 70000, 6002)


def test_training_options_are_the_ones_training_needs() -> None:
    opts = TRAINING_OPTIONS
    assert opts["server::synch_mode"] == "true"
    assert opts["server::coach_w_referee"] == "true" and opts["server::coach"] == "false"
    assert opts["server::auto_mode"] == "false"
    assert opts["server::half_time"] == "-1" and opts["server::drop_ball_time"] == "0"
    assert opts["server::foul_detect_probability"] == "0"
    for log in ("game_logging", "text_logging", "keepaway_logging"):
        assert opts[f"server::{log}"] == "false"
    assert all("::" in name for name in opts)


def test_option_names_and_ports_are_checked(fake_binary: str) -> None:
    with pytest.raises(ValueError, match="'bad name'"):
        ServerProcess(fake_binary, options={"bad name": 1})
    with pytest.raises(ValueError, match="not server::port"):
        ServerProcess(fake_binary, options={"port": 7000})
    with pytest.raises(ValueError, match="whitespace"):
        ServerProcess(fake_binary, options={"half_time": "1 2"})


# -- the process (stand-in binary) -------------------------------------------------------


def _log(server: ServerProcess) -> str:
    path = server.log_path
    assert path is not None
    for _ in range(100):  # the stand-in prints right after starting
        if path.exists() and "ARGS" in path.read_text():
            break
        time.sleep(0.01)
    return path.read_text()


def test_process_runs_in_a_private_directory_with_the_options(fake_binary: str) -> None:
    server = ServerProcess(fake_binary, options={"half_time": 300, "use_offside": False})
    with server:
        assert server.alive and server.pid is not None
        address = server.address
        workdir = server.workdir
        assert workdir is not None and workdir.is_dir()
        log = _log(server)
        assert f"CONF {workdir / 'conf'}" in log and f"CWD {workdir}" in log
        assert f"server::port={address.port}" in log
        assert f"server::coach_port={address.coach_port}" in log
        assert "server::half_time=300" in log and "server::use_offside=false" in log
        assert "server::synch_mode=true" in log and "server::coach_w_referee=true" in log
        assert server.options["server::half_time"] == "300"
    assert not server.alive and not workdir.exists()
    server.stop()  # idempotent


def test_restart_keeps_the_address(fake_binary: str, tmp_path: Path) -> None:
    log_path = tmp_path / "logs" / "server.log"
    with ServerProcess(fake_binary, log_path=log_path) as server:
        address, pid, workdir = server.address, server.pid, server.workdir
        server.restart()
        assert server.alive and server.address == address and server.pid != pid
        assert server.workdir != workdir and workdir is not None and not workdir.exists()
        assert server.starts == 2
    assert not server.alive
    assert log_path.read_text().count("ARGS") == 2  # appended across restarts, kept


def test_a_server_that_exits_at_start_raises_with_its_error_lines(fake_binary: str) -> None:
    server = ServerProcess(fake_binary, options={"fail": 1})
    with pytest.raises(RuntimeError, match="exited with status 1[\\s\\S]*no parameter called"):
        server.start()
    assert not server.alive and server.workdir is None


def test_a_server_that_never_binds_times_out(fake_binary: str) -> None:
    server = ServerProcess(fake_binary, options={"nobind": 1}, startup_timeout_s=0.3)
    with pytest.raises(RuntimeError, match="did not bind UDP port"):
        server.start()
    assert not server.alive


def _server_pid(log: str) -> int:
    return int(next(line for line in log.splitlines() if line.startswith("PID ")).split()[1])




def test_stop_passes_sigterm_to_the_server_through_its_guard(fake_binary: str) -> None:
    with ServerProcess(fake_binary) as server:
        server_pid = _server_pid(_log(server))
        assert server.pid != server_pid and process_running(server_pid)
    assert wait_stopped(server_pid)


def test_the_guard_ends_as_its_server_did(fake_binary: str) -> None:
    with ServerProcess(fake_binary) as server:
        os.kill(_server_pid(_log(server)), signal.SIGKILL)
        deadline = time.monotonic() + 300.0  # ends the wait for a server that never stops
        while server.alive and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.returncode == -signal.SIGKILL


def test_a_guard_killed_with_sigkill_takes_its_server_along(fake_binary: str) -> None:
    with ServerProcess(fake_binary) as server:
        server_pid = _server_pid(_log(server))
        assert server.pid is not None
        os.kill(server.pid, signal.SIGKILL)
        assert wait_stopped(server_pid)
        assert not server.alive


STARTER = """
import sys, time
from elevens.robocup.server import ServerProcess
server = ServerProcess(sys.argv[1], log_path=sys.argv[2]).start()
print("started", flush=True)
time.sleep(60)
"""


def test_servers_stop_when_the_process_that_started_them_is_killed(
    fake_binary: str, tmp_path: Path
) -> None:
    """SIGKILL cannot be caught, so no cleanup code runs in the starter: the guard notices."""
    log_path = tmp_path / "server.log"
    starter = subprocess.Popen(
        [sys.executable, "-c", STARTER, fake_binary, str(log_path)],
        stdout=subprocess.PIPE, text=True,
    )
    try:
        assert starter.stdout is not None and starter.stdout.readline() == "started\n"
        server_pid = _server_pid(log_path.read_text())
        assert process_running(server_pid)
        starter.kill()
        starter.wait()
        assert wait_stopped(server_pid)
    finally:
        starter.kill()
        starter.wait()
        if starter.stdout is not None:
            starter.stdout.close()


def test_address_is_only_known_after_start(fake_binary: str) -> None:
    server = ServerProcess(fake_binary)
    with pytest.raises(RuntimeError, match="call start"):
        _ = server.address
    assert "server::port" not in server.options


# -- a real rcssserver ----------------------------------------------------------------


@needs_rcssserver
def test_real_server_accepts_every_training_option(rcss_server: ServerProcess) -> None:
    assert rcss_server.alive
    workdir = rcss_server.workdir
    assert workdir is not None
    conf = (workdir / "conf" / "server.conf").read_text()
    conf += (workdir / "conf" / "CSVSaver.conf").read_text()
    for name in TRAINING_OPTIONS:
        assert f"{name} =" in conf, name
    log = rcss_server.log_tail(200).lower()
    assert "error" not in log
    assert not list(workdir.glob("*.rc[gl]"))  # no game or text logs written
    assert not (Path(os.path.expanduser("~")) / ".rcssserver" / "elevens").exists()


@needs_rcssserver
def test_real_server_restart_and_unknown_option() -> None:
    with ServerProcess() as server:
        address = server.address
        server.restart()
        assert server.alive and server.address == address
    with pytest.raises(RuntimeError, match="has no parameter called 'no_such_option'"):
        ServerProcess(options={"no_such_option": 1}).start()
