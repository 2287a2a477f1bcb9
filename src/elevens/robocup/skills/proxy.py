"""The proxy players of a skills team: find the built proxy, start its eleven players (and its
coach) against an rcssserver the way elevens starts helios-base (the folder's ``start.sh`` in
a process group of its own), pointed at elevens' decision server.

The proxy is CLSFramework's soccer-simulation-proxy, built beside the project with Thrift
only; elevens never ships or builds it. :func:`find_proxy` looks at a given folder, then
``$ELEVENS_SKILLS_PROXY``, then ``../ext/soccer-simulation-proxy/build/bin`` beside the
project: a folder holding ``start.sh`` and ``sample_player``.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from elevens.robocup.external import start_team, stop_team, wait_connected
from elevens.robocup.server import ServerAddress
from elevens.robocup.skills.runtime import Decide, DecisionServer

__all__ = [
    "BUILD_HINT",
    "ENV_VAR",
    "ProxyNotFound",
    "SkillsTeamResult",
    "find_proxy",
    "play_skills_team",
    "proxy_command",
]

ENV_VAR = "ELEVENS_SKILLS_PROXY"
#: The proxy's binaries beside the project (the repository's parent folder).
BESIDE = Path(__file__).resolve().parents[4].parent / "ext/soccer-simulation-proxy/build/bin"
BUILD_HINT = (
    "build CLSFramework/soccer-simulation-proxy with Thrift only in "
    "../ext/soccer-simulation-proxy beside the project (docs/guide.md, RoboCup) or set "
    f"{ENV_VAR} to its folder holding start.sh and sample_player"
)


class ProxyNotFound(FileNotFoundError):  # noqa: N818 - reads as what happened
    """No built proxy where elevens looked; the message says where and how to build it."""


def find_proxy(folder: str | os.PathLike[str] | None = None) -> Path:
    """The folder of the proxy's ``start.sh`` and ``sample_player``. A given folder or
    environment value that does not hold them raises instead of falling back."""
    given = folder if folder is not None else os.environ.get(ENV_VAR)
    candidate = Path(given) if given else BESIDE
    if (candidate / "start.sh").is_file() and os.access(candidate / "sample_player", os.X_OK):
        return candidate.resolve()
    raise ProxyNotFound(f"no skills proxy in {candidate}: {BUILD_HINT}")


def proxy_command(folder: Path, rpc_port: int, *, coach: bool = False,
                  rpc_host: str = "127.0.0.1", players: int = 11) -> str:
    """The team's start command, with ``{host}``, ``{port}``, ``{coach_port}`` and
    ``{team}`` left for :func:`elevens.robocup.external.start_team`; ``players``: how many
    start (the goalie first)."""
    cmd = (
        f"cd {folder} && ./start.sh -h {{host}} -p {{port}} -P {{coach_port}} -t {{team}} "
        f"-n {players} --rpc-host {rpc_host} --rpc-port {rpc_port} --rpc-type thrift"
    )
    return cmd if coach else cmd + " -C"


@dataclasses.dataclass(frozen=True)
class SkillsTeamResult:
    team: str
    ended: str  # "players left" (the game ended) or "interrupted" (Ctrl-C, SIGTERM)
    wall_s: float
    stats: dict[str, Any]  # the decision server's RuntimeStats
    decisions: dict[str, Any] = dataclasses.field(default_factory=dict)  # a trained team's report

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _group_alive(proc: subprocess.Popen[bytes]) -> bool:
    """Whether any process of the team's group still runs (start.sh leaves its players in
    the background and exits)."""
    proc.poll()
    try:
        os.killpg(proc.pid, 0)
    except ProcessLookupError:
        return False
    return True


def play_skills_team(
    decide: Decide,
    address: ServerAddress,
    team: str,
    *,
    proxy: str | os.PathLike[str] | None = None,
    players: int = 11,
    coach: bool = False,
    deadline_s: float = 0.040,
    gather_s: float = 0.015,
    server_log: Path | None = None,
    output: Path | None = None,
    connect_timeout_s: float = 120.0,
    on_start: Callable[[DecisionServer], None] | None = None,
) -> SkillsTeamResult:
    """Run the decision server and the proxy's players against the rcssserver at
    ``address`` until every player process has exited (the game ended) or Ctrl-C / SIGTERM
    (as ``elevens robocup match`` stops a team), then stop the players and report. With the
    server's log, waits until all ``players`` are in."""
    folder = find_proxy(proxy)
    start = time.monotonic()
    output = output or Path(os.devnull)
    with DecisionServer(decide, players=players, deadline_s=deadline_s,
                        gather_s=gather_s) as server:
        if on_start is not None:
            on_start(server)
        command = proxy_command(folder, server.port, coach=coach, players=players)
        proc = start_team(command, address, team, output)
        ended = "players left"
        try:
            if server_log is not None:
                wait_connected(server_log, team, players, proc, output, connect_timeout_s)
            while _group_alive(proc):
                time.sleep(0.5)
        except KeyboardInterrupt:
            ended = "interrupted"  # still a report: a match stops its teams this way
        finally:
            stop_team(proc)
        stats = server.stats().as_dict()
    report = getattr(decide, "report", None)
    return SkillsTeamResult(team=team, ended=ended, wall_s=time.monotonic() - start,
                            stats=stats, decisions=report() if callable(report) else {})
