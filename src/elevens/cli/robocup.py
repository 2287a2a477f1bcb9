"""`elevens robocup serve|play|train|bench|match|team|logs`: the RoboCup bridge from the
command line.

Every command finds rcssserver through ``--rcssserver``, ``$ELEVENS_RCSSSERVER`` or PATH; when
it is missing it says so and how to install it (``elevens.robocup.server.INSTALL_HINT``).
"""

from __future__ import annotations

import json as json_lib
import sys
import time
from dataclasses import asdict, dataclass, replace
from typing import Annotated, Any

import tyro

from elevens.cli.checks import EXIT_INTERRUPTED, Commands, exit_with_error
from elevens.robocup.server import find_rcssserver
from elevens.robocup.train import RoboCupTrainConfig


@dataclass(frozen=True)
class RoboCupServeArgs:
    """Start N rcssserver processes (training options, synch mode) on free loopback ports and
    keep them running until Ctrl-C."""

    servers: int = 1
    """How many server processes."""
    rcssserver: str | None = None
    """The server binary (default: $ELEVENS_RCSSSERVER, then PATH)."""


@dataclass(frozen=True)
class RoboCupPlayArgs:
    """Play a checkpoint or a handcrafted team against another in rcssserver."""

    team0: str = "naive"
    """Left team: naive, random, a shipped trained team (elevens-11v11, elevens-2v2) or a
    checkpoint path (run, checkpoints or step directory)."""
    team1: str = "random"
    """Right team, as --team0."""
    players: int = 11
    """Players per team, 1..11."""
    episodes: int = 1
    """Episodes to play."""
    steps: int = 400
    """Steps (server cycles) per episode."""
    action: str = "sim"
    """'sim': the simulator's (move, rot) actions (checkpoints need it); 'thesis12': table 4.1's
    12 values (handcrafted teams only)."""
    keep_ball_in_play: bool = False
    """Put the ball back at the lines instead of the referee's kick-ins."""
    seed: int = 0
    """Spawns and the teams' sampling."""
    json: bool = False
    """Print one JSON object per episode."""
    rcssserver: str | None = None
    """The server binary (default: $ELEVENS_RCSSSERVER, then PATH)."""


@dataclass(frozen=True)
class RoboCupTrainArgs:
    """Train with the same PPO in rcssserver: one server process per game of an iteration feeds
    the compiled learner. The flags are elevens train's (--env.*, --network.*, --ppo.*,
    --opponent.*, --games-per-iteration, --run.*) and the server's (--server.*)."""

    config: Annotated[RoboCupTrainConfig, tyro.conf.arg(name="")] = RoboCupTrainConfig()
    """The run: the simulator's learner and host loop, and the servers."""
    resume: bool = False
    """Continue the latest checkpoint of --run.run-dir (its config must match)."""


@dataclass(frozen=True)
class RoboCupBenchArgs:
    """Synchronous cycles per second with 22 players and the trainer from one Python process,
    random actions, and where the time goes (send, wait for the server, parse)."""

    players: int = 11
    """Players per team."""
    cycles: int = 2000
    """Cycles to time (after a warm-up)."""
    parse: bool = True
    """Parse every see and sense_body (what RoboCupEnv needs); False only finds each (think)."""
    eye: bool = False
    """Turn on the trainer's see_global every cycle (the critic's view)."""
    json: bool = False
    """Print one JSON object (key cycles_per_s) instead of a line."""
    rcssserver: str | None = None
    """The server binary (default: $ELEVENS_RCSSSERVER, then PATH)."""


@dataclass(frozen=True)
class RoboCupMatchArgs:
    """Play full matches in rcssserver with the referee (two halves, set pieces, fouls): an
    elevens team or another team's binaries on each side; the score, W/D/L and the mean score
    difference with a 95% interval."""

    team0: str | None = "naive"
    """Left team: naive, random, a shipped trained team, a checkpoint path or a skills team
    (skills_naive, skills_random, skills_naive_sim, or a checkpoint of elevens train
    skills-2v2 / skills-11v11: elevens decides, the skills proxy's players execute;
    docs/robocup_skills.md) (or use --team0-cmd)."""
    team1: str | None = None
    """Right team, as --team0 (or use --team1-cmd)."""
    team0_cmd: str | None = None
    """Left team as a start command; {host}, {port} (players), {coach_port} (online coach) and
    {team} are filled in, e.g. "HELIOS/start.sh -p {port} -P {coach_port} -t {team}"."""
    team1_cmd: str | None = None
    """Right team as a start command; {host}, {port} (players), {coach_port} (online coach)
    and {team} are filled in, as in --team0-cmd."""
    team0_name: str = "elevens"
    """Left team's name in the server (at most 15 of A-Z a-z 0-9 _ + -)."""
    team1_name: str = "opponent"
    """Right team's name in the server (different from --team0-name)."""
    team0_turn_scale: float = 180.0
    """Left elevens team: turn moment in degrees at rot = 1 (22.9: the simulator's rate)."""
    team1_turn_scale: float = 180.0
    """Right elevens team, as --team0-turn-scale."""
    team0_view: str = "wide"
    """Left elevens team's view width: "wide" (180 degrees, a see every 3rd cycle), "normal"
    (120, every 2nd) or "narrow" (60, every cycle)."""
    team1_view: str = "wide"
    """Right elevens team, as --team0-view."""
    team0_dead_reckoning: bool = False
    """Left elevens team: move the pose and the ball estimate on between sees (elevens
    robocup team --dead-reckoning)."""
    team1_dead_reckoning: bool = False
    """Right elevens team, as --team0-dead-reckoning."""
    team0_sample: bool = False
    """Left elevens team: play the policy's sampled action (elevens robocup team --sample)."""
    team1_sample: bool = False
    """Right elevens team, as --team0-sample."""
    team0_set_plays: str = "routine"
    """Left skills team: our kick-offs, free kicks, kick-ins and corners played by the proxy's
    ready behaviour ("routine") or by the team's own decisions ("decided")."""
    team1_set_plays: str = "routine"
    """Right skills team, as --team0-set-plays."""
    matches: int = 1
    """Matches to play (a new server for each)."""
    players: int = 11
    """Players per team."""
    half_time: int = 300
    """Cycles per half x 0.1 as rcssserver counts (300 = 3000 cycles, regulation)."""
    real_time: bool = False
    """Play with the server's 100 ms cycles (a competition's mode) instead of synch mode."""
    log_dir: str | None = None
    """Keep each match's .rcg and .rcl game logs and the server's output here."""
    results: str | None = None
    """Append one JSON line per match to this file."""
    json: bool = False
    """Print one JSON line per match as it ends (what --results appends), then the summary as
    one JSON object."""
    rcssserver: str | None = None
    """The server binary (default: $ELEVENS_RCSSSERVER, then PATH)."""


@dataclass(frozen=True)
class RoboCupTeamArgs:
    """Join a running rcssserver as one team (a competition's server, or one that `elevens
    robocup match` started): connect the players, play until time over."""

    team: str = "naive"
    """naive, random, a shipped trained team or a checkpoint path."""
    host: str = "127.0.0.1"
    """The server's host."""
    port: int = 6000
    """The server's player port."""
    team_name: str = "elevens"
    """The team's name in the server (at most 15 of A-Z a-z 0-9 _ + -)."""
    players: int = 11
    """Players to connect (the first is the goalie)."""
    real_time: bool = False
    """The server runs 100 ms cycles (no synch mode)."""
    no_rules: bool = False
    """Let the policy play set pieces too (no kick-off formation, set-piece routines or
    goalie catch)."""
    turn_scale: float = 180.0
    """Turn moment in degrees at rot = 1 (22.9 turns at the simulator's rate)."""
    view: str = "wide"
    """View width: "wide" (180 degrees, a see every 3rd cycle: the simulator's field of view),
    "normal" (120, every 2nd) or "narrow" (60, every cycle)."""
    dead_reckoning: bool = False
    """Between two sees, move each player's pose and ball estimate on by its own commands and
    sense_body (and the ball by its decay), instead of holding the last see."""
    sample: bool = False
    """Play the policy's sampled action, as PPO trained it and as the simulator's evaluations
    and tournaments play it (run.eval_deterministic is off by default), instead of its mean."""
    seed: int = 0
    """Seeds the sampled actions (--sample)."""
    json: bool = False
    """Print the result as one JSON object."""


def serve(args: RoboCupServeArgs) -> None:
    from elevens.robocup.server import ServerProcess

    binary = find_rcssserver(args.rcssserver)
    servers = [ServerProcess(binary).start() for _ in range(args.servers)]
    try:
        for server in servers:
            a = server.address
            print(
                f"rcssserver pid {server.pid}: players {a.host}:{a.port}, trainer {a.coach_port}, "
                f"online coach {a.olcoach_port}, log {server.log_path}",
                flush=True,
            )
        print("Ctrl-C stops them.", flush=True)
        while all(server.alive for server in servers):
            time.sleep(0.5)
        print("a server exited:", file=sys.stderr)
        for server in servers:
            if not server.alive:
                print(server.log_tail(10), file=sys.stderr)
    except KeyboardInterrupt:
        pass
    finally:
        for server in servers:
            server.stop()


def play(args: RoboCupPlayArgs) -> None:
    from elevens.robocup.play import load_robocup_team, play_robocup

    for spec in (args.team0, args.team1):  # an unknown team is named before a missing server
        load_robocup_team(spec, args.action)
    binary = find_rcssserver(args.rcssserver)
    results = play_robocup(
        args.team0, args.team1, players_per_team=args.players, episodes=args.episodes,
        episode_length=args.steps, action=args.action, keep_ball_in_play=args.keep_ball_in_play,
        rcssserver=binary, seed=args.seed,
        print_fn=(lambda _: None) if args.json else print,
    )
    if args.json:
        for result in results:
            print(json_lib.dumps(asdict(result)))
    else:
        goals = [sum(r.goals[side] for r in results) for side in (0, 1)]
        print(f"total: {args.team0} {goals[0]} - {goals[1]} {args.team1}")


def train(args: RoboCupTrainArgs) -> None:
    from elevens.robocup.train import train_robocup
    from elevens.runs.errors import RunRefusedError
    from elevens.train.checkpoint import CheckpointError

    try:  # a bad config is refused before the server binary is looked for
        args.config.validate()
    except ValueError as error:
        exit_with_error("elevens robocup train: error", error, 2)
    server = replace(args.config.server, rcssserver=find_rcssserver(args.config.server.rcssserver))
    config = replace(args.config, server=server)
    try:
        result = train_robocup(config, resume=args.resume)
    except RunRefusedError as error:  # another run's checkpoints in --run-dir
        exit_with_error("elevens robocup train: error", error, 2)
    except CheckpointError as error:  # a damaged checkpoint: the message names the file
        exit_with_error("elevens robocup train: error", error, 2)
    print(
        f"robocup train: {result.iteration} iterations, {result.env_steps} env steps, "
        f"{result.episodes} episodes, {result.restarts} server restarts in {result.wall_s:.0f} s; "
        f"checkpoint {result.checkpoint}"
    )
    if result.interrupted:
        raise SystemExit(EXIT_INTERRUPTED)


def bench(args: RoboCupBenchArgs) -> None:
    from elevens.robocup.client import measure_cycles
    from elevens.robocup.server import ServerProcess

    binary = find_rcssserver(args.rcssserver)
    with ServerProcess(binary) as server:
        result = measure_cycles(
            server.address, players_per_team=args.players, cycles=args.cycles, eye=args.eye,
            parse=args.parse,
        )
    result = {"players": 2 * args.players, "parse": args.parse, "eye": args.eye, **result}
    if args.json:
        print(json_lib.dumps(result))
        return
    print(
        f"rcssserver {2 * args.players} players + trainer (eye {'on' if args.eye else 'off'}, "
        f"parse {'on' if args.parse else 'off'}): {result['cycles_per_s']:,.0f} cycles/s | per "
        f"cycle: send {result['send_ms']:.2f} ms, wait for the server {result['wait_ms']:.2f} ms, "
        f"parse {result['parse_ms']:.2f} ms, other {result['other_ms']:.2f} ms"
    )


def match_teams(args: RoboCupMatchArgs) -> tuple[Any, Any]:
    """The two sides of ``elevens robocup match`` as ``robocup.match`` Teams, each with its
    own flags (ValueError for a bad side)."""
    from elevens.robocup.match import parse_team

    team0 = parse_team(
        args.team0 if args.team0_cmd is None else None, args.team0_cmd, args.team0_name,
        turn_scale=args.team0_turn_scale, view=args.team0_view,
        dead_reckoning=args.team0_dead_reckoning, sample=args.team0_sample,
        set_plays=args.team0_set_plays, set_plays_flag="--team0-set-plays",
    )
    team1 = parse_team(
        args.team1, args.team1_cmd, args.team1_name, turn_scale=args.team1_turn_scale,
        view=args.team1_view, dead_reckoning=args.team1_dead_reckoning,
        sample=args.team1_sample, set_plays=args.team1_set_plays,
        set_plays_flag="--team1-set-plays",
    )
    return team0, team1


def match(args: RoboCupMatchArgs) -> None:
    from elevens.robocup.match import play_matches, summarize

    binary = find_rcssserver(args.rcssserver)
    try:
        team0, team1 = match_teams(args)
        if args.team0_name == args.team1_name:
            raise ValueError(
                f"--team0-name and --team1-name are both {args.team0_name!r}: the server "
                "needs two different names"
            )
        if args.half_time < 1:
            raise ValueError(f"--half-time {args.half_time!r} is invalid: it must be >= 1")
    except ValueError as error:
        exit_with_error("elevens robocup match: error", error, 2)
    from elevens.robocup.match import ElevensTeam, SkillsTeam
    from elevens.robocup.play import load_robocup_team
    from elevens.robocup.skills.proxy import find_proxy

    for side in (team0, team1):
        if isinstance(side, ElevensTeam):  # a bad spec fails here, not in a child process
            load_robocup_team(side.spec, "sim", any_action=True)
        elif isinstance(side, SkillsTeam):  # so does a missing proxy (one line: how to build)
            find_proxy(side.proxy)
    results = play_matches(
        team0, team1, matches=args.matches, players_per_team=args.players,
        synch=not args.real_time, half_time=args.half_time, log_dir=args.log_dir,
        rcssserver=binary, results_path=args.results,
        print_fn=(lambda _: None) if args.json else (lambda line: print(line, flush=True)),
        on_result=(
            (lambda r: print(json_lib.dumps(asdict(r)), flush=True)) if args.json else None
        ),
    )
    summary = summarize(results)
    if args.json:
        print(json_lib.dumps(asdict(summary)))
    else:
        print(summary.line())


def _resolvable(host: str) -> str:
    """``host`` if it resolves to an IPv4 address (the server's UDP), else a ValueError."""
    import socket

    try:
        socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as error:
        reason = error.strerror if isinstance(error, socket.gaierror) else str(error)
        raise ValueError(
            f"--host {host!r} cannot be resolved ({reason}): give a host name or an IPv4 "
            "address of the machine rcssserver runs on"
        ) from None
    return host


def team(args: RoboCupTeamArgs) -> None:
    from elevens.robocup.protocol import InitPlayer
    from elevens.robocup.server import ServerAddress
    from elevens.robocup.team import RoboCupTeam

    # Bad names and hosts before the policy's compile, not after it.
    InitPlayer(args.team_name)
    address = ServerAddress.from_port(args.port, _resolvable(args.host))
    player = RoboCupTeam(
        args.team, players_per_team=args.players, team_name=args.team_name,
        synch=not args.real_time, rules=not args.no_rules, turn_scale=args.turn_scale,
        view=args.view, dead_reckoning=args.dead_reckoning, deterministic=not args.sample,
        seed=args.seed,
    )
    seconds = player.warm_up()
    if not args.json:
        print(f"{args.team_name}: compiled and ran the policy once in {seconds:.1f} s", flush=True)
    result = player.play(
        address,
        on_connect=None if args.json else (
            lambda side: print(f"{args.team_name}: connected on the {'lr'[side]} side",
                               flush=True)
        ),
    )
    if args.json:
        print(json_lib.dumps(result.as_dict()))
    else:
        print(
            f"{args.team_name} ({result.team}, {'left' if result.side == 0 else 'right'}): "
            f"{result.goals_for} - {result.goals_against} after {result.cycles} cycles "
            f"({result.ended}; late player-cycles {result.late_player_cycles}, "
            f"catches {result.catches})"
        )


@dataclass(frozen=True)
class RoboCupLogsArgs:
    """Read rcssserver's game logs (.rcg) and tell one team's matches: the score, who touched
    the ball, where the scorers won it before each goal it conceded, the free-kick faults it
    gave away (a set piece's taker touching the ball twice) and the goals conceded after them
    before its next touch, and when its players' stamina capacity ran out."""

    logs: tyro.conf.Positional[Annotated[tuple[str, ...], tyro.conf.arg(metavar="PATH...")]]
    """.rcg files, or folders searched through (e.g. a match series' --log-dir)."""
    team: str | None = None
    """The team of view, by its name in the server (default: the left team of each log)."""
    json: bool = False
    """Print the summary, every conceded goal included, as one JSON object."""


def logs(args: RoboCupLogsArgs) -> None:
    from elevens.robocup.rcg import find_logs, read_rcg, summarize_team

    paths = find_logs(args.logs)
    games = [read_rcg(path) for path in paths]
    summary = summarize_team(games, args.team)
    if args.json:
        print(json_lib.dumps(summary.as_dict()))
    else:
        print("\n".join(summary.lines()))


COMMANDS: Commands = {
    "robocup-logs": (RoboCupLogsArgs, logs),
    "robocup-serve": (RoboCupServeArgs, serve),
    "robocup-play": (RoboCupPlayArgs, play),
    "robocup-train": (RoboCupTrainArgs, train),
    "robocup-bench": (RoboCupBenchArgs, bench),
    "robocup-match": (RoboCupMatchArgs, match),
    "robocup-team": (RoboCupTeamArgs, team),
}
"""The RoboCup subcommands: name -> (args, command)."""

STARTS_A_SERVER = (RoboCupPlayArgs, RoboCupTrainArgs, RoboCupBenchArgs, RoboCupMatchArgs)
"""The commands that start rcssserver (``robocup team`` joins someone else's server)."""
