"""Another team's binaries beside an rcssserver: start them, wait until their players are in,
stop them (with every player they left in the background).

The team is a shell command (helios-base: ``start.sh -p {port} -P {coach_port} -t {team}``) in a
process group of its own; ``{host}``, ``{port}`` (players), ``{coach_port}`` (online coach) and
``{team}`` are filled in. Whether its players are in is read from the server's log, where
rcssserver writes "A new (vN) player (TEAM UNUM) connected." for each.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

from elevens.robocup.server import ServerAddress

__all__ = [
    "TeamCommandNotFound", "connected_players", "start_team", "stop_team", "wait_connected"
]

_CONNECTED = re.compile(r"A new \(v\d+\) player \((\S+) (\d+)\) connected\.")


def connected_players(log_text: str, team: str) -> int:
    """How many players of ``team`` the server's log says connected."""
    return sum(1 for m in _CONNECTED.finditer(log_text) if m.group(1) == team)


def read_text(path: Path | None) -> str:
    """A log's text so far ("" when it does not exist yet)."""
    if path is None:
        return ""
    try:
        return path.read_text(errors="replace")
    except FileNotFoundError:
        return ""


def start_team(
    cmd: str | list[str], address: ServerAddress, team: str, output: Path
) -> subprocess.Popen[bytes]:
    """Start a team: a shell command with the placeholders filled in, or an argument list
    as it is. Its output goes to ``output``."""
    if isinstance(cmd, str):
        text = cmd.format(
            host=address.host, port=address.port, coach_port=address.olcoach_port, team=team
        )
        args = ["/bin/sh", "-c", text]
    else:
        args = list(cmd)
    with open(output, "wb") as out:
        return subprocess.Popen(
            args, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True,
        )


class TeamCommandNotFound(FileNotFoundError):  # noqa: N818 - reads as what happened
    """A team's start command that the shell could not find or run (status 127 or 126):
    restarting the server will not help."""


def wait_connected(
    server_log: Path | None,
    team: str,
    players: int,
    proc: subprocess.Popen[bytes],
    output: Path,
    timeout_s: float,
    *,
    exit_is_error: bool = False,
    failed_start_grace_s: float = 5.0,
) -> None:
    """Wait until ``players`` players of ``team`` are in the server's log. Raises
    RuntimeError with the team's output when it takes longer than ``timeout_s``, or when the
    team's process exits first and ``exit_is_error`` (a start.sh exits at once, leaving its
    players running: not an error). A start command that fails (a non-zero status, e.g. 127
    for a script that does not exist) with no player connected ``failed_start_grace_s``
    later is an error at once, not after ``timeout_s``: TeamCommandNotFound when the shell
    found no such command (status 126 or 127), RuntimeError otherwise."""
    deadline = time.monotonic() + timeout_s
    failed_at: float | None = None
    while (count := connected_players(read_text(server_log), team)) < players:
        status = proc.poll()
        if exit_is_error and status is not None:
            raise RuntimeError(
                f"team {team!r} exited (status {status}) before connecting:\n"
                f"{read_text(output)[-2000:]}"
            )
        if status not in (None, 0) and count == 0:
            failed_at = failed_at if failed_at is not None else time.monotonic()
            if time.monotonic() - failed_at > failed_start_grace_s:
                message = (
                    f"team {team!r}: its start command failed (status {status}) and no "
                    f"player connected; its output:\n{read_text(output)[-2000:]}"
                )
                # The shell's statuses for a command not found (127) or not executable (126).
                if status in (126, 127):
                    raise TeamCommandNotFound(message)
                raise RuntimeError(message)
        if time.monotonic() > deadline:
            raise RuntimeError(
                f"team {team!r} connected {count} of {players} players within {timeout_s:g} s; "
                f"its output:\n{read_text(output)[-2000:]}"
            )
        time.sleep(0.1)


def stop_team(proc: subprocess.Popen[bytes]) -> None:
    """SIGTERM the team's process group (start.sh leaves its players in the background), then
    SIGKILL what is left."""
    for sig, wait in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(wait)
            os.killpg(proc.pid, signal.SIGKILL)  # the leader is gone; its children may not be
        except (subprocess.TimeoutExpired, ProcessLookupError):
            continue
        return
