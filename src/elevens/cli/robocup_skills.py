"""`elevens robocup skills-team`: a skills team (elevens decides, the proxy's players execute
librcsc's skills) joins a running rcssserver."""

from __future__ import annotations

import json as json_lib
from dataclasses import dataclass

from elevens.cli.checks import Commands


@dataclass(frozen=True)
class RoboCupSkillsTeamArgs:
    """Join a running rcssserver with a skills team: start the decision server and the
    proxy's eleven players (built beside the project, see docs/robocup_skills.md) and play
    until the game ends; then print the decision latency."""

    skills: str = "skills_naive"
    """The skills team: skills_naive, skills_random, skills_naive_sim, or a trained skills team
    (a checkpoint of elevens train skills-2v2 / skills-11v11, PATH@ITERATION, or a team
    exported from one)."""
    sample: bool = False
    """A trained team samples its actions instead of playing their mode."""
    host: str = "127.0.0.1"
    """The server's host."""
    port: int = 6000
    """The server's player port (the online coach's is port + 2)."""
    team_name: str = "elevens"
    """The team's name in the server."""
    players: int = 11
    """Proxy players to start (the first is the goalie)."""
    coach: bool = False
    """Start the proxy's online coach too (it substitutes player types)."""
    deadline_ms: float = 40.0
    """A request not decided this long after it arrived gets the default action."""
    gather_ms: float = 15.0
    """A cycle's batch is decided when all players asked or this long after the first."""
    proxy: str | None = None
    """The proxy's folder with start.sh and sample_player (default: $ELEVENS_SKILLS_PROXY,
    then ../ext/soccer-simulation-proxy/build/bin beside the project)."""
    json: bool = False
    """Print the result as one JSON object."""


def skills_team(args: RoboCupSkillsTeamArgs) -> None:
    from elevens.robocup.protocol import InitPlayer
    from elevens.robocup.server import ServerAddress
    from elevens.robocup.skills import check_skills_policy, skills_policy
    from elevens.robocup.skills.proxy import find_proxy, play_skills_team

    # Bad input first, in one line each: the team (its config only), its name, the proxy;
    # then the team's networks are loaded and compiled, before the players start.
    check_skills_policy(args.skills)
    InitPlayer(args.team_name)
    if args.gather_ms >= args.deadline_ms:
        raise ValueError(
            f"--gather-ms {args.gather_ms:g} is invalid: it must be below --deadline-ms "
            f"{args.deadline_ms:g}"
        )
    find_proxy(args.proxy)
    decide = skills_policy(args.skills, deterministic=not args.sample)
    result = play_skills_team(
        decide, ServerAddress.from_port(args.port, args.host), args.team_name,
        proxy=args.proxy, players=args.players, coach=args.coach,
        deadline_s=args.deadline_ms / 1e3, gather_s=args.gather_ms / 1e3,
    )
    if args.json:
        print(json_lib.dumps(result.as_dict()))
    else:
        s = result.stats
        print(
            f"{args.team_name} ({args.skills}, {result.ended}): {s['requests']} requests in "
            f"{s['batches']} batches, {s['defaults']} defaults; latency p50 "
            f"{s['latency_ms_p50']:.1f} ms, p99 {s['latency_ms_p99']:.1f} ms; round trip p50 "
            f"{s['roundtrip_ms_p50']:.1f} ms, p99 {s['roundtrip_ms_p99']:.1f} ms"
        )


COMMANDS: Commands = {"robocup-skills-team": (RoboCupSkillsTeamArgs, skills_team)}
"""The skills team's subcommand."""
