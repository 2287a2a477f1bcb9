"""`elevens robocup skills-team`: a skills team (elevens decides, the proxy's players execute
librcsc's skills) joins a running rcssserver; `elevens robocup train skills-11v11`: a skills
team fine-tuned in matches against another team's binaries."""

from __future__ import annotations

import gc
import json as json_lib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated

import numpy as np
import tyro

from elevens.cli.checks import EXIT_INTERRUPTED, Commands, exit_with_error
from elevens.robocup.skills.finetune import PRESET, SkillsTrainConfig

TRAIN_COMMAND = "robocup-train-skills"


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
    set_plays: str = "routine"
    """Our kick-offs, free kicks, kick-ins and corners: the proxy's ready behaviour
    ("routine") or the team's own decisions ("decided"; docs/robocup_skills.md)."""
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
    """A request not decided this long after it arrived gets the default action (a team
    decided request by request, as skills_naive, is neither gathered nor has a deadline)."""
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
    from elevens.robocup.skills.set_plays import check_set_plays

    # Bad input first, in one line each: the team (its config only), its name, the proxy;
    # then the team's networks are loaded and compiled, before the players start.
    check_skills_policy(args.skills)
    check_set_plays(args.set_plays)
    InitPlayer(args.team_name)
    if args.gather_ms >= args.deadline_ms:
        raise ValueError(
            f"--gather-ms {args.gather_ms:g} is invalid: it must be below --deadline-ms "
            f"{args.deadline_ms:g}"
        )
    find_proxy(args.proxy)
    decide = skills_policy(args.skills, deterministic=not args.sample,
                           set_plays=args.set_plays)
    # What is loaded by now lives as long as the process: out of the collector's full passes,
    # each of which (some 130,000 objects with JAX, tens of ms) held a cycle's decisions up.
    gc.freeze()
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


@dataclass(frozen=True)
class RoboCupSkillsTrainArgs:
    """Fine-tune a skills team in rcssserver (`elevens robocup train skills-11v11`): real
    matches against --server.opponent-cmd, one server per game of an iteration, our eleven
    proxy players deciding with the learner's sampled policy. The flags are elevens train
    skills-11v11's (--env.*, --network.*, --ppo.*, --games-per-iteration, --run.* with
    --run.init-from a skills checkpoint) and the matches' (--server.*)."""

    config: Annotated[SkillsTrainConfig, tyro.conf.arg(name="")] = SkillsTrainConfig()
    """The run: the skill game's learner and host loop, and the matches."""
    resume: bool = False
    """Continue the latest checkpoint of --run.run-dir (its config must match)."""


def skills_train_argv(argv: list[str]) -> list[str]:
    """``robocup-train PRESET ...`` with a skills preset as this module's command line; any
    other command line as it is. A skills preset the server cannot play is a ValueError."""
    if argv[:1] != ["robocup-train"] or len(argv) < 2 or not argv[1].startswith("skills-"):
        return argv
    if argv[1] != PRESET:
        raise ValueError(
            f"preset {argv[1]!r} is invalid in elevens robocup train: the skills proxy plays "
            f"11 a side; use {PRESET} (a 2 v 2 policy starts it with --run.init-from RUN)")
    return [TRAIN_COMMAND, *argv[2:]]


def skills_train(args: RoboCupSkillsTrainArgs) -> None:
    from elevens.robocup.server import find_rcssserver
    from elevens.robocup.skills.finetune import train_skills
    from elevens.robocup.skills.proxy import find_proxy
    from elevens.runs.errors import RunRefusedError
    from elevens.train.checkpoint import CheckpointError

    name = f"elevens robocup train {PRESET}: error"
    try:  # bad input first, before the server and the proxy are looked for
        args.config.validate()
        from elevens.runs.teams import team_on_field
        from elevens.train.learner import check_teacher

        check_teacher(args.config.learner, team_on_field)  # before anything compiles or starts
    except ValueError as error:
        exit_with_error(name, error, 2)
    find_proxy(args.config.server.proxy)
    server = replace(args.config.server,
                     rcssserver=find_rcssserver(args.config.server.rcssserver))
    try:
        result = train_skills(replace(args.config, server=server), resume=args.resume)
    except (RunRefusedError, CheckpointError) as error:
        exit_with_error(name, error, 2)
    print(
        f"robocup train {PRESET}: {result.iteration} iterations, {result.env_steps} env "
        f"steps, {result.matches} match{'' if result.matches == 1 else 'es'} in "
        f"{result.wall_s:.0f} s; checkpoint "
        f"{result.checkpoint}"
    )
    if result.interrupted:
        raise SystemExit(EXIT_INTERRUPTED)


@dataclass(frozen=True)
class ChainsInitArgs:
    """Write a chain chooser (docs/robocup_skills.md): skills_helios_parts with its ball
    holder's chain chosen by elevens, helios-base's own choice to start with, that plays a
    uniform one of the top --top-k chains --explore of the time and records its choices in
    --record-dir. Play it by its path: elevens robocup match --team0 FILE ..."""

    out: str
    """The chooser's file (.json)."""
    top_k: int = 4
    """The chains of helios-base's best evaluations it picks among."""
    explore: float = 0.0
    """How often it plays a uniform one of them instead (0 to 1)."""
    record_dir: str | None = None
    """Where it records its choices: give each match its own folder, its --log-dir."""
    seed: int = 0
    """The exploring generator's seed (each process adds its pid)."""


def chains_init(args: ChainsInitArgs) -> None:
    from elevens.robocup.skills.chains import ChooserSpec, save_chooser

    if not args.out.endswith(".json"):
        raise ValueError(f"--out {args.out!r} is invalid (allowed: a .json file)")
    record = None if args.record_dir is None else str(Path(args.record_dir).resolve())
    save_chooser(args.out, ChooserSpec(top_k=args.top_k, explore=args.explore,
                                       seed=args.seed, record_dir=record))
    print(f"wrote {args.out}")


@dataclass(frozen=True)
class ChainsFitArgs:
    """Fit a chain chooser's weights on the matches an exploring chooser recorded: each
    choice's outcome read from its match's game log (the possession value 50 cycles on less
    the value then; a goal in between counts +1 or -1), a ridge regression on the chosen
    chain's features less its search's mean (with that mean beside them, each choice weighed by
    the inverse of its probability), and estimates on each match held out in turn."""

    matches: tuple[str, ...]
    """Match folders, each the --record-dir of one match (its records and its .rcg)."""
    out: str
    """The fitted chooser's file (.json): top-k as recorded, no exploring, no recording."""
    team: str = "elevens"
    """Our team's name in the game logs."""
    values_from: tuple[str, ...] = ()
    """More game logs (folders or .rcg) for the possession values, beside the matches'."""
    l2: float = 10.0
    """The ridge penalty."""
    top_k: int = 4
    """The fitted chooser's top-k (the exploring one's)."""
    margin: float = 0.0
    """Play helios-base's best chain unless another's predicted outcome beats it by more."""


def chains_fit(args: ChainsFitArgs) -> None:
    from elevens.robocup.rcg import find_logs, read_rcg
    from elevens.robocup.skills.chains import (
        ChooserSpec,
        fit_chooser,
        label_records,
        match_records,
        possession_values,
        save_chooser,
    )

    if not args.out.endswith(".json"):
        raise ValueError(f"--out {args.out!r} is invalid (allowed: a .json file)")
    found = match_records(args.matches)
    logs = [read_rcg(path) for _, path in found]
    extra = [read_rcg(p) for p in find_logs(list(args.values_from))] if args.values_from else []
    values = possession_values(logs + extra, args.team)
    labelled = [(records, label_records(records, log, args.team, values))
                for (records, _), log in zip(found, logs, strict=True)]
    report = fit_chooser(labelled, args.l2, args.margin)
    fit = {**report.as_dict(), "matches_fitted": list(args.matches), "l2": args.l2,
           "values": np.round(values, 4).tolist()}
    save_chooser(args.out, ChooserSpec(weights=report.weights, top_k=args.top_k,
                                       margin=args.margin, fit=fit))
    print(json_lib.dumps({k: v for k, v in fit.items() if k != "values"}))


COMMANDS: Commands = {
    "robocup-chains-init": (ChainsInitArgs, chains_init),
    "robocup-chains-fit": (ChainsFitArgs, chains_fit),
    "robocup-skills-team": (RoboCupSkillsTeamArgs, skills_team),
    TRAIN_COMMAND: (RoboCupSkillsTrainArgs, skills_train),
}
"""The skills team's subcommands."""

STARTS_A_SERVER = (RoboCupSkillsTrainArgs,)
"""The commands here that start rcssserver."""
