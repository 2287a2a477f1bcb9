"""Full RoboCup matches: rcssserver with the referee, two teams, N matches, a score table.

``play_matches(team0, team1, matches=N)`` starts one rcssserver per match with regulation
options (:data:`MATCH_OPTIONS`: referee, auto mode, two halves of ``half_time`` cycles, fouls
on; synch or real-time mode), starts the left team and waits until all its players are in (the
first team to connect gets the left side), then the right team, and waits for the server to end
the game. Each team is an elevens team (a spec as ``elevens robocup play`` takes it, run as
``elevens robocup team`` in a child process) or another team's start command
(:class:`ExternalTeam`, e.g. helios-base's ``start.sh``), with ``{host}``, ``{port}`` and
``{team}`` filled in. The score comes from the server's own "Score: L - R" line, the cycles it
played from the last ``(show T ...)`` of its game log (kept in a temporary folder when no log
folder is given): a server that ends early (it exits after 20 cycles in a row without every
``(done)``) still prints a score, and only the game log shows the cycles lost.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elevens.robocup.external import read_text, start_team, stop_team, wait_connected
from elevens.robocup.protocol import ChangeView
from elevens.robocup.server import ServerProcess

__all__ = [
    "MATCH_OPTIONS",
    "ElevensTeam",
    "ExternalTeam",
    "MatchResult",
    "SkillsTeam",
    "played_cycles",
    "t_quantile_975",
    "MatchSummary",
    "play_match",
    "play_matches",
    "summarize",
]

#: Regulation options over the training defaults (rcssserver 19 names). The referee, fouls and
#: drop balls are back; time keeping and auto mode end the game by themselves.
MATCH_OPTIONS: dict[str, str] = {
    "server::coach_w_referee": "false",
    "server::coach": "false",
    "server::auto_mode": "true",
    # Cycles auto mode waits for both teams before kicking off an empty game regardless: a
    # team that compiles first must never find the game started without it.
    "server::connect_wait": "1000000",
    "server::kick_off_wait": "20",
    "server::game_over_wait": "20",
    "server::half_time": "300",
    "server::nr_normal_halfs": "2",
    "server::nr_extra_halfs": "0",
    "server::penalty_shoot_outs": "false",
    "server::drop_ball_time": "100",
    "server::foul_detect_probability": "0.5",
    "server::synch_mode": "true",
}
_SCORE = re.compile(r"Score:\s*(\d+)\s*-\s*(\d+)")
_SHOW = re.compile(rb"\(show (\d+) ")
_SHOW_BYTES = 1 << 16  # the tail of a game log read for its last show (one is ~3.2 KB)


@dataclasses.dataclass(frozen=True)
class ElevensTeam:
    """An elevens team: ``spec`` as ``elevens robocup team`` takes it."""

    spec: str
    name: str = "elevens"
    turn_scale: float = 180.0
    view: str = "wide"
    dead_reckoning: bool = False
    sample: bool = False

    def command(self, host: str, port: int, players: int, synch: bool) -> list[str]:
        args = [
            sys.executable, "-m", "elevens", "robocup", "team", "--team", self.spec,
            "--host", host, "--port", str(port), "--team-name", self.name,
            "--players", str(players), "--turn-scale", str(self.turn_scale),
            "--view", self.view, "--json",
        ]
        args += ["--dead-reckoning"] if self.dead_reckoning else []
        args += ["--sample"] if self.sample else []
        return args + ([] if synch else ["--real-time"])


@dataclasses.dataclass(frozen=True)
class SkillsTeam:
    """A skills team (``spec``: a name of ``elevens.robocup.skills.SKILLS`` or a trained
    skills team), run as ``elevens robocup skills-team``: elevens' decision server and the
    proxy's players, which it starts (``proxy``: their folder; None: where ``skills-team``
    looks by default). ``sample``: a trained team samples its actions; ``set_plays``: how it
    plays our set plays (``skills.set_plays.SET_PLAYS``)."""

    spec: str
    name: str = "elevens"
    proxy: str | None = None
    sample: bool = False
    set_plays: str = "routine"

    def command(self, host: str, port: int, players: int, synch: bool) -> list[str]:
        # The decision server batches by arrival: synch mode and real time need no flag.
        args = [
            sys.executable, "-m", "elevens", "robocup", "skills-team", "--skills", self.spec,
            "--host", host, "--port", str(port), "--team-name", self.name,
            "--players", str(players), "--json",
        ]
        args += ["--sample"] if self.sample else []
        args += [] if self.set_plays == "routine" else ["--set-plays", self.set_plays]
        return args + ([] if self.proxy is None else ["--proxy", self.proxy])


@dataclasses.dataclass(frozen=True)
class ExternalTeam:
    """Another team's binaries: a shell command started in its own process group, with
    ``{host}``, ``{port}`` (players), ``{coach_port}`` (online coach) and ``{team}`` replaced
    (e.g. ``start.sh -p {port} -P {coach_port} -t {team}``)."""

    cmd: str
    name: str = "external"

    def command(self, host: str, port: int, players: int, synch: bool) -> str:
        return self.cmd


Team = ElevensTeam | SkillsTeam | ExternalTeam
#: The teams run by an elevens command: one that exits before the game ends has failed.
_OURS = (ElevensTeam, SkillsTeam)


@dataclasses.dataclass(frozen=True)
class MatchResult:
    match: int
    names: tuple[str, str]  # left, right team names
    score: tuple[int, int]  # left, right goals
    wall_s: float
    server_cycles: int | None  # the server's clock at the end, from its game log (None: none)
    missed_cycles: int  # "Someone missed a cycle" lines in the server's log (synch mode)
    log_dir: str | None  # where the .rcg/.rcl went, when logging was on
    teams: tuple[dict[str, Any] | None, dict[str, Any] | None] = (None, None)
    """Each elevens team's own report (robocup.team.TeamResult: late cycles, catches, ...)."""
    lost_cycles: int | None = None
    """Regulation cycles (two halves of ``half_time``) the server did not play: it ended the
    match early. None when its game log could not be read."""

    @property
    def difference(self) -> int:
        """Left goals minus right goals."""
        return self.score[0] - self.score[1]


@dataclasses.dataclass(frozen=True)
class MatchSummary:
    names: tuple[str, str]
    matches: int
    wins: int  # of the left team (team0)
    draws: int
    losses: int
    goals_for: float  # mean per match, team0
    goals_against: float
    difference: float  # mean score difference, team0 minus team1
    difference_ci: tuple[float, float]  # 95% t-interval of the mean difference (nan: 1 match)
    lost_cycles: int | None = None  # summed over the matches (None: no game log was read)

    def line(self) -> str:
        low, high = self.difference_ci
        if self.matches < 2:
            interval = "(one match: no interval)"
        else:
            interval = f"[{low:+.2f}, {high:+.2f}] (95% t-interval"
            interval += f"; under {FEW_MATCHES} matches: rough)" if self.few else ")"
        lost = "?" if self.lost_cycles is None else str(self.lost_cycles)
        return (
            f"{self.names[0]} v {self.names[1]}: {self.matches} matches, W/D/L "
            f"{self.wins}/{self.draws}/{self.losses}, goals {self.goals_for:.2f} - "
            f"{self.goals_against:.2f}, score difference {self.difference:+.2f} {interval}, "
            f"cycles lost {lost}"
        )

    @property
    def few(self) -> bool:
        """Too few matches for the interval to say much (it leans on normal scores)."""
        return self.matches < FEW_MATCHES


FEW_MATCHES = 5
# Student's t, 97.5% quantile, 1 to 30 degrees of freedom (standard tables).
_T975 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
    2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
)
_Z975 = 1.959963984540054


def t_quantile_975(df: int) -> float:
    """Student's t 97.5% quantile for ``df`` >= 1 degrees of freedom: the table up to 30,
    beyond it the Cornish-Fisher expansion about the normal quantile (error < 1e-4 there)."""
    if df < 1:
        raise ValueError(f"df={df!r} is invalid: a t quantile needs >= 1 degree of freedom")
    if df <= len(_T975):
        return _T975[df - 1]
    z = _Z975
    return (
        z
        + (z**3 + z) / (4 * df)
        + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * df**2)
        + (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / (384 * df**3)
    )


def summarize(results: Sequence[MatchResult]) -> MatchSummary:
    """W/D/L of the left team and its mean score difference with a 95% t-interval (a
    bootstrap's interval of 3 matches is the range of their scores, far too narrow)."""
    if not results:
        raise ValueError("no matches to summarize")
    diff = np.array([r.difference for r in results], np.float64)
    if len(diff) > 1:
        half = t_quantile_975(len(diff) - 1) * float(diff.std(ddof=1)) / math.sqrt(len(diff))
        ci = (float(diff.mean()) - half, float(diff.mean()) + half)
    else:
        ci = (math.nan, math.nan)
    lost = [r.lost_cycles for r in results if r.lost_cycles is not None]
    return MatchSummary(
        names=results[0].names,
        matches=len(results),
        wins=int((diff > 0).sum()),
        draws=int((diff == 0).sum()),
        losses=int((diff < 0).sum()),
        goals_for=float(np.mean([r.score[0] for r in results])),
        goals_against=float(np.mean([r.score[1] for r in results])),
        difference=float(diff.mean()),
        difference_ci=ci,
        lost_cycles=sum(lost) if lost else None,
    )


def played_cycles(folder: str | os.PathLike[str]) -> int | None:
    """The server's clock at the end of the game logged in ``folder``: the time of the last
    ``(show T ...)`` of its .rcg (None: no game log, or one without a show)."""
    found: int | None = None
    for path in sorted(Path(folder).glob("*.rcg")):
        with open(path, "rb") as f:
            f.seek(max(0, path.stat().st_size - _SHOW_BYTES))
            shows = _SHOW.findall(f.read())
        if shows:
            last = int(shows[-1])
            found = last if found is None else max(found, last)
    return found


def play_match(
    team0: Team,
    team1: Team,
    *,
    match: int = 0,
    players_per_team: int = 11,
    synch: bool = True,
    half_time: int = 300,
    log_dir: str | os.PathLike[str] | None = None,
    rcssserver: str | None = None,
    connect_timeout_s: float = 180.0,
    match_timeout_s: float = 3600.0,
) -> MatchResult:
    """One match (module docstring). ``log_dir``: keep the server's .rcg/.rcl game logs and
    its stdout there (None: no game logs). Raises RuntimeError naming the team that did not
    connect or the server's log tail when the game did not end properly."""
    if team0.name == team1.name:
        raise ValueError(f"both teams are named {team0.name!r}: the server needs two names")
    options = dict(MATCH_OPTIONS)
    options["server::synch_mode"] = "true" if synch else "false"
    options["server::half_time"] = str(half_time)
    if log_dir is not None:
        _check_new_log_folder(log_dir, match)
    work = Path(tempfile.mkdtemp(prefix="elevens-match-"))
    if log_dir is not None:
        game_logs = Path(log_dir) / f"match_{match:03d}"
        game_logs.mkdir(parents=True, exist_ok=True)
        options.update({
            "server::game_logging": "true", "server::text_logging": "true",
            "server::game_log_dir": str(game_logs.resolve()),
            "server::text_log_dir": str(game_logs.resolve()),
        })
        log_path = game_logs / "rcssserver.log"
    else:
        game_logs = None
        log_path = work / "rcssserver.log"
        # The .rcg alone, for the cycles played (the .rcl, much larger, is not needed).
        options.update({
            "server::game_logging": "true", "server::text_logging": "false",
            "server::game_log_dir": str(work.resolve()),
        })
    server = ServerProcess(rcssserver, options=options, log_path=log_path)
    procs: list[subprocess.Popen[bytes]] = []
    began = time.perf_counter()
    try:
        server.start()
        address = server.address
        for team in (team0, team1):
            output = work / f"{team.name}.log"
            command = team.command(address.host, address.port, players_per_team, synch)
            procs.append(start_team(command, address, team.name, output))
            wait_connected(
                log_path, team.name, players_per_team, procs[-1], output, connect_timeout_s,
                exit_is_error=isinstance(team, _OURS),
            )
        deadline = time.monotonic() + match_timeout_s
        while server.alive and time.monotonic() < deadline:
            time.sleep(0.2)
        if server.alive:
            raise RuntimeError(f"the match did not end within {match_timeout_s:g} s")
        text = read_text(log_path)
        score = _SCORE.search(text)
        if score is None:
            raise RuntimeError(
                f"rcssserver ended without a score line:\n{server.last_log_tail or text[-2000:]}"
            )
        times = [int(t) for t in re.findall(r"missed a cycle at (\d+)", text)]
        for proc in procs:  # an elevens team prints its report as it leaves
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(10.0)
        for team, proc in zip((team0, team1), procs, strict=True):
            if isinstance(team, _OURS) and proc.returncode not in (0, None):
                tail = read_text(work / f"{team.name}.log")[-2000:]
                raise RuntimeError(
                    f"team {team.name!r} failed during the match (status {proc.returncode}):"
                    f"\n{tail}"
                )
        reports = tuple(_team_report(work / f"{team.name}.log") for team in (team0, team1))
        played = played_cycles(game_logs if game_logs is not None else work)
        regulation = 20 * half_time  # two halves; half_time counts tenths of 100 cycles
        return MatchResult(
            match=match,
            names=(team0.name, team1.name),
            score=(int(score.group(1)), int(score.group(2))),
            wall_s=time.perf_counter() - began,
            server_cycles=played,
            missed_cycles=len(times),
            log_dir=str(game_logs) if game_logs is not None else None,
            teams=(reports[0], reports[1]),
            lost_cycles=None if played is None else max(0, regulation - played),
        )
    finally:
        for proc in procs:
            stop_team(proc)
        server.stop()
        if log_dir is not None:  # keep the teams' output beside the game logs
            for path in work.glob("*.log"):
                if path.name != "rcssserver.log":
                    shutil.copy(path, Path(log_dir) / f"match_{match:03d}" / path.name)
        shutil.rmtree(work, ignore_errors=True)


def _check_new_log_folder(log_dir: str | os.PathLike[str], match: int) -> None:
    """A match's log folder must be new or empty: the server appends its output (and so its
    score line) to an existing rcssserver.log, and readers of .rcg files take the first one."""
    folder = Path(log_dir) / f"match_{match:03d}"
    if folder.is_dir() and any(folder.iterdir()):
        raise FileExistsError(
            f"{folder} already holds an earlier match's logs; give a new --log-dir (the "
            "score would be read from the earlier server output)"
        )


def _team_report(path: Path) -> dict[str, Any] | None:
    """The JSON line an elevens team prints at the end of its match (None: not one)."""
    for line in reversed(read_text(path).splitlines()):
        if line.startswith("{"):
            try:
                report = json.loads(line)
            except json.JSONDecodeError:
                return None
            return report if isinstance(report, dict) else None
    return None


def _decision_times(result: MatchResult) -> str:
    """A skills team's decision round trips (its report's stats), as text for the match's
    line ("" for the other teams)."""
    text = ""
    for name, report in zip(result.names, result.teams, strict=True):
        stats = (report or {}).get("stats")
        if isinstance(stats, dict) and "roundtrip_ms_p99" in stats:
            text += (
                f"; {name} decisions: round trip p50 {stats['roundtrip_ms_p50']:.1f} ms, "
                f"p99 {stats['roundtrip_ms_p99']:.1f} ms, {stats['defaults']} defaults"
            )
        decided = (report or {}).get("decisions")
        if isinstance(decided, dict) and decided.get("open_play"):
            text += (f", {decided['open_play']} open-play rows, "
                     f"{decided['open_play'] - decided['deferred']} not deferred")
    return text


def play_matches(
    team0: Team,
    team1: Team,
    *,
    matches: int = 1,
    print_fn: Callable[[str], None] = print,
    results_path: str | os.PathLike[str] | None = None,
    on_result: Callable[[MatchResult], None] | None = None,
    **kwargs: Any,
) -> list[MatchResult]:
    """``matches`` matches (sides kept: team0 always left); one line printed per match, one
    JSON line appended per match to ``results_path``, ``on_result`` called with each match's
    result as it ends."""
    if matches < 1:
        raise ValueError(f"matches={matches!r} is invalid: it must be >= 1")
    if kwargs.get("log_dir") is not None:
        for m in range(matches):
            _check_new_log_folder(kwargs["log_dir"], m)
    results = []
    for m in range(matches):
        result = play_match(team0, team1, match=m, **kwargs)
        results.append(result)
        played = "?" if result.server_cycles is None else result.server_cycles
        lost = "?" if result.lost_cycles is None else result.lost_cycles
        print_fn(
            f"match {m}: {result.names[0]} {result.score[0]} - {result.score[1]} "
            f"{result.names[1]} ({result.wall_s:.0f} s, {played} cycles, lost {lost}, "
            f"missed cycles {result.missed_cycles}{_decision_times(result)})"
        )
        if results_path is not None:
            with open(results_path, "a") as f:
                f.write(json.dumps(dataclasses.asdict(result)) + "\n")
        if on_result is not None:
            on_result(result)
    return results


def parse_team(
    spec: str | None, cmd: str | None, name: str, *, turn_scale: float = 180.0,
    view: str = "wide",
    dead_reckoning: bool = False,
    sample: bool = False,
    set_plays: str = "routine",
    set_plays_flag: str = "--set-plays",
) -> Team:
    """--teamN / --teamN-cmd / --teamN-name as a Team; exactly one of spec and cmd;
    ``set_plays`` (flag ``set_plays_flag``) other than "routine" only for a skills team."""
    from elevens.robocup.skills.set_plays import check_set_plays

    check_set_plays(set_plays, set_plays_flag)
    only_skills = ValueError(
        f"{set_plays_flag} {set_plays!r} is for a skills team (skills_naive, skills_random, "
        f"skills_naive_sim or a trained skills team), not {spec or cmd!r}")
    if (spec is None) == (cmd is None):
        raise ValueError(
            f"give a team ({name}) as an elevens team (--team0/--team1: naive, random, a shipped "
            "name or a checkpoint) or as a start command (--team0-cmd/--team1-cmd), not both"
        )
    if cmd is not None:
        if not shlex.split(cmd):
            raise ValueError("the team's start command is empty")
        if set_plays != "routine":
            raise only_skills
        return ExternalTeam(cmd, name)
    assert spec is not None
    from elevens.robocup.skills import SKILLS
    from elevens.robocup.skills.chains import is_chooser
    from elevens.robocup.skills.learned import is_skills_team

    # A trained team plays through the skills proxy when its action is the skill decision.
    if spec in SKILLS or is_skills_team(spec) or is_chooser(spec):
        return SkillsTeam(spec, name, sample=sample, set_plays=set_plays)
    if set_plays != "routine":
        from elevens.robocup.skills.learned import check_skills_team

        check_skills_team(spec, sorted(SKILLS))  # a spec that does not load says why
        raise only_skills
    try:
        ChangeView(view)
    except ValueError as error:
        raise ValueError(f"team {name!r}: {error}") from None
    return ElevensTeam(spec, name, turn_scale, view, dead_reckoning, sample)
