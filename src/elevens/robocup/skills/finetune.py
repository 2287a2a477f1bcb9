"""Fine-tuning a skills team in rcssserver: ``elevens robocup train skills-11v11``.

The skill game's learner (``elevens train skills-11v11``, or a run started from a skills
checkpoint with ``--run.init-from``) plays real matches against another team's binaries
(``--server.opponent-cmd``, e.g. helios-base): each game of an iteration is an rcssserver
process in synch mode with the referee (kick-offs, restarts, halves), our eleven proxy players
and a decision server whose ``decide`` is a ``record.Recorder`` sampling the learner's current
policy. An iteration records ``env.episode_length`` cycles of every game at once (the games
run in parallel, each on its own server), packs them into the ``Rollout`` the compiled unroll
returns (``record.pack``) and hands it to ``elevens.runs.loop.train``'s ``HostGames``: the
learner's ``improve``, logs, checkpoints, resume and time budget are the simulator's. With
``--ppo.teacher`` (e.g. ``skills_naive``) the teacher acts on every recorded observation
(``record.teacher_actions``) and its term pulls the policy towards it on the server's own
states (DAgger's correction of imitation's drift), where the policy played.

The match goes on across iterations: while the learner updates, each decision waits
``server.hold_ms`` first, so the match crawls (the server waits up to 1.25 s a cycle for its
players, helios-base 5 s for the server) instead of being played unrecorded; each player's
memory carries over into the next segment. A match that ends (``server.half_time``) or a
server that dies is replaced by a fresh match, which ends one episode in the rollout and
starts the next.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jax

from elevens.robocup.external import read_text, start_team, stop_team, wait_connected
from elevens.robocup.match import MATCH_OPTIONS
from elevens.robocup.server import ServerProcess
from elevens.robocup.skills.decode import SKILL_ACTION_SIZE
from elevens.robocup.skills.game import skills_config, skills_field
from elevens.robocup.skills.observe import PLAYERS
from elevens.robocup.skills.proxy import find_proxy, proxy_command
from elevens.robocup.skills.record import Recorder, pack, teacher_actions
from elevens.robocup.skills.runtime import DecisionServer
from elevens.robocup.skills.set_plays import check_set_plays
from elevens.robocup.skills.team import DEFER, self_feature_count
from elevens.robocup.train import ROBOCUP_CONFIG_JSON, ROBOCUP_RUN
from elevens.runs.layout import RunLayout
from elevens.runs.loop import Collect, HostGames, TrainResult, train
from elevens.runs.teams import team_on_field
from elevens.train.config import LearnerConfig, RunConfig, TrainConfig, apply_overrides, validate
from elevens.train.learner import Learner, TrainState, make_learner

__all__ = [
    "SKILLS_EPISODE_FIELDS",
    "SkillsServerConfig",
    "SkillsTrainConfig",
    "make_skills_train_config",
    "train_skills",
]

TEAM_NAME = "elevens"
PRESET = "skills-11v11"
SKILLS_EPISODE_FIELDS = (
    "iteration", "game", "match", "goals_for", "goals_against", "steps", "routine",
    "defaulted", "filled", "matches", "restarts", "missed", "wall_s",
)
"""Columns of episodes.csv: per game and iteration, the goals of the segment, the player-steps
a routine played (masked), that got the deadline's default (masked) or were filled in for a
player that did not ask (masked), the matches it spans, the fresh matches started during
it (the last one ended, or its server died) and the cycles the server has gone on without a
player's (done) in the current match so far (rcssserver's "missed a cycle")."""
_SERVER_WAIT_S = 1.25  # rcssserver's wait for its players' (done) each synch cycle
_STALL_S = 60.0  # no new cycle for this long: the game is restarted


@dataclasses.dataclass(frozen=True)
class SkillsServerConfig:
    """The matches: the server, the opponent and the decision server's timing."""

    opponent_cmd: str | None = None
    """The opponent's start command (required), with {host}, {port}, {coach_port} and {team}
    filled in, e.g. "HELIOS/start.sh -p {port} -P {coach_port} -t {team}"; we play left."""
    opponent_name: str = "opponent"
    """The opponent's team name in the server."""
    rcssserver: str | None = None
    """The server binary (default: $ELEVENS_RCSSSERVER, then PATH)."""
    proxy: str | None = None
    """The skills proxy's folder (default: $ELEVENS_SKILLS_PROXY, then beside the project)."""
    half_time: int = 300
    """The server's half_time: 300 is a regulation half (3000 cycles), then a fresh match;
    -1 turns time keeping off (one match without end)."""
    deadline_ms: float = 1000.0
    """A request not decided this long after it arrived gets the default (masked)."""
    gather_ms: float = 15.0
    """A cycle's batch is decided when all players asked or this long after the first."""
    hold_ms: float = 500.0
    """Between iterations each decision waits this long first: the match crawls while the
    learner updates."""
    set_plays: str = "routine"
    """Our kick-offs, free kicks, kick-ins and corners: the proxy's ready behaviour
    ("routine") or the policy's decisions, recorded and learned like open play ("decided")."""

    def __post_init__(self) -> None:
        if self.opponent_cmd is not None and not self.opponent_cmd.strip():
            raise ValueError(f"server.opponent_cmd={self.opponent_cmd!r} is invalid: give the "
                             "opponent's start command")
        if self.opponent_name in ("", TEAM_NAME):
            raise ValueError(f"server.opponent_name={self.opponent_name!r} is invalid: it must "
                             f"be a team name other than {TEAM_NAME}")
        if self.half_time != -1 and self.half_time < 1:
            raise ValueError(f"server.half_time={self.half_time!r} is invalid: it must be -1 "
                             "(no time keeping) or at least 1")
        limit = _SERVER_WAIT_S * 1e3
        if not 0 < self.gather_ms < self.deadline_ms < limit:
            raise ValueError(
                f"server.deadline_ms={self.deadline_ms!r} and server.gather_ms="
                f"{self.gather_ms!r} are invalid: 0 < gather_ms < deadline_ms < {limit:g} (the "
                "server's wait for its players each cycle)")
        check_set_plays(self.set_plays, "server.set_plays")
        if not 0 <= self.hold_ms < self.deadline_ms:
            raise ValueError(f"server.hold_ms={self.hold_ms!r} is invalid: it must be from 0 "
                             f"to below server.deadline_ms={self.deadline_ms!r}")


def _skills_learner() -> LearnerConfig:
    # skills-11v11's learner with one server (one game a minibatch), one iteration per step
    # of the host loop, and 400 cycles of every match an iteration.
    learner = skills_config("11v11").learner
    return dataclasses.replace(
        learner, games_per_iteration=1, iterations_per_chunk=1,
        ppo=dataclasses.replace(learner.ppo, minibatch_size=PLAYERS),
    )


SKILLS_RUN = dataclasses.replace(ROBOCUP_RUN, run_dir="runs/robocup-skills")


@dataclasses.dataclass(frozen=True)
class SkillsTrainConfig:
    """A skills team fine-tuned in rcssserver: the skill game's learner and host loop (the
    flags of ``elevens train skills-11v11``) plus the matches'."""

    learner: LearnerConfig = dataclasses.field(default_factory=_skills_learner)
    """The skill game's learner: networks, PPO, the reward's weights and shaping schedule;
    ``env.episode_length`` is the cycles each server records an iteration,
    ``games_per_iteration`` the servers."""
    run: RunConfig = SKILLS_RUN
    """Length, checkpoints, seed, init_from (a skills checkpoint), run directory; evaluation
    in the simulator's skill game with eval_teams (e.g. skills_naive)."""
    server: SkillsServerConfig = SkillsServerConfig()
    """The matches."""

    def validate(self) -> SkillsTrainConfig:
        """``elevens.train.config.validate`` on the learner and run, and what only the
        server's skills team can play; ValueError naming the field."""
        learner, env = self.learner, self.learner.env
        if learner.opponent.mix:
            raise ValueError(f"opponent.mix={learner.opponent.mix!r} is invalid in elevens "
                             f"robocup train {PRESET}: the server's opponent is "
                             "--server.opponent-cmd's team; leave it out")
        validate(self.train_config())
        if getattr(env, "physics", None) != "skills" or learner.network.actions != (
                SKILL_ACTION_SIZE):
            raise ValueError(
                f"env.physics={getattr(env, 'physics', None)!r} with network.actions="
                f"{learner.network.actions} is invalid here: the skills proxy plays the skill "
                f"game's {SKILL_ACTION_SIZE}-value decision (start from {PRESET})")
        if env.players_per_team != PLAYERS:
            raise ValueError(
                f"env.players_per_team={env.players_per_team!r} is invalid in elevens robocup "
                f"train {PRESET}: the proxy plays {PLAYERS} a side (start a 2 v 2 policy with "
                "--run.init-from: the networks read entity slots)")
        if env.mix:
            raise ValueError(f"env.mix={env.mix!r} is invalid in elevens robocup train "
                             f"{PRESET}: the server plays one game; leave it out")
        if self.run.devices not in (0, 1):
            raise ValueError(f"run.devices={self.run.devices!r} is invalid in elevens robocup "
                             "train: the games play on the host; use 0 or 1")
        if env.game.episode_length < 2:
            raise ValueError(f"env.episode_length={env.game.episode_length!r} is invalid: it "
                             "must be at least 2 server cycles")
        if self.server.opponent_cmd is None:
            raise ValueError(
                "server.opponent_cmd=None is invalid in elevens robocup train "
                f"{PRESET}: give the opponent's start command, e.g. --server.opponent-cmd "
                "\"HELIOS/start.sh -p {port} -P {coach_port} -t {team}\"")
        return self

    def train_config(self) -> TrainConfig:
        """The TrainConfig saved with every checkpoint (a resume compares it)."""
        return TrainConfig(preset=f"robocup-{PRESET}", learner=self.learner, run=self.run)


def make_skills_train_config(**overrides: Any) -> SkillsTrainConfig:
    """The default ``SkillsTrainConfig`` with fields replaced by their flags' names
    (``env.episode_length``, ``run.iterations``, ``server.opponent_cmd``, ...); validated."""
    return apply_overrides(SkillsTrainConfig(), overrides).validate()


class ServerMatch:
    """One game of an iteration: an rcssserver with the referee, our proxy players (asking
    ``decision``) on the left, the opponent on the right. :meth:`start` plays a fresh match;
    :attr:`alive` says whether it still runs."""

    def __init__(self, config: SkillsServerConfig, decision: DecisionServer, folder: Path,
                 connect_timeout_s: float = 120.0) -> None:
        self.config, self.decision, self.folder = config, decision, folder
        self.connect_timeout_s = connect_timeout_s
        self.server: ServerProcess | None = None
        self.teams: list[Any] = []
        self.proxy = find_proxy(config.proxy)

    def start(self) -> None:
        self.stop()
        options = {**MATCH_OPTIONS, "server::half_time": str(self.config.half_time),
                   "server::game_logging": "false", "server::text_logging": "false"}
        log = self.folder / "rcssserver.log"
        log.unlink(missing_ok=True)  # connections are counted in it
        self.server = ServerProcess(self.config.rcssserver, options=options, log_path=log)
        self.server.start()
        address = self.server.address
        assert self.config.opponent_cmd is not None  # validated
        for command, name in (
            (proxy_command(self.proxy, self.decision.port), TEAM_NAME),
            (self.config.opponent_cmd, self.config.opponent_name),
        ):  # the first team in plays left
            output = self.folder / f"{name}.log"
            self.teams.append(start_team(command, address, name, output))
            wait_connected(log, name, PLAYERS, self.teams[-1], output, self.connect_timeout_s)

    @property
    def alive(self) -> bool:
        return self.server is not None and self.server.alive

    def missed_cycles(self) -> int:
        """The cycles this match's server went on without some player's (done)."""
        return read_text(self.folder / "rcssserver.log").count("missed a cycle")

    def stop(self) -> None:
        for proc in self.teams:
            stop_team(proc)
        self.teams = []
        if self.server is not None:
            self.server.stop()
            self.server = None


@dataclasses.dataclass
class SkillsTrainResult(TrainResult):
    """``elevens.runs.loop.train``'s result and the matches this call started."""

    matches: int = 0


class SkillGames:
    """The games of a fine-tuning run: ``open`` (``HostGames.open``) starts a decision
    server per game and gives ``collect``, which starts (or resumes) the matches, records
    ``env.episode_length`` cycles of each and packs them (``record.pack``)."""

    def __init__(self, config: SkillsTrainConfig) -> None:
        self.config = config
        self.games: list[tuple[Recorder, DecisionServer, ServerMatch]] = []
        self.matches = 0
        self.began = time.perf_counter()
        game = config.learner.env.game
        self.params = skills_field(PLAYERS, **{name: getattr(game, name) for name in (
            "goal_reward", "ball_shaping_weight", "approach_shaping_weight",
            "possession_shaping_weight", "possession_radius", "possession_by")})

    @contextlib.contextmanager
    def open(self, learner: Learner) -> Iterator[Collect]:
        config, server = self.config, self.config.server
        layout = RunLayout.of(config.run.run_dir)
        layout.root.mkdir(parents=True, exist_ok=True)
        written = json.dumps(dataclasses.asdict(config), indent=2)
        (layout.root / ROBOCUP_CONFIG_JSON).write_text(written, encoding="utf-8")
        self.policy = learner.policy
        teacher = learner.setup.teacher
        self.teacher = None if teacher is None else teacher_actions(teacher)
        with contextlib.ExitStack() as stack, layout.episodes_csv.open(
                "a", newline="", encoding="utf-8") as self.csv:
            if self.csv.tell() == 0:
                csv.writer(self.csv).writerow(SKILLS_EPISODE_FIELDS)
            work = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="elevens-ft-")))
            for g in range(config.learner.games_per_iteration):
                recorder = Recorder(learner.policy, seed=config.run.seed + g,
                                    hold_s=server.hold_ms / 1e3, set_plays=server.set_plays,
                                    reach=config.learner.env.self_features
                                    == self_feature_count(True),
                                    defer=config.learner.env.kinds == DEFER + 1,
                                    defer_to=getattr(config.learner.env, "defer_to",
                                                     "skills_naive"))
                decision = stack.enter_context(DecisionServer(
                    recorder, players=PLAYERS, deadline_s=server.deadline_ms / 1e3,
                    gather_s=server.gather_ms / 1e3, on_default=recorder.defaulted))
                folder = work / f"game_{g}"
                folder.mkdir()
                match = ServerMatch(server, decision, folder)
                stack.callback(match.stop)
                self.games.append((recorder, decision, match))
            yield self.collect

    def collect(self, state: TrainState, key: jax.Array) -> tuple[Any, dict[str, float]]:
        """``env.episode_length`` cycles of every game for ``state``'s policy, as the
        compiled ``collect``'s Rollout, and the matches' counts (also in episodes.csv)."""
        began = time.perf_counter()
        steps = self.config.learner.env.game.episode_length
        restarts = [0] * len(self.games)
        for g, (recorder, _, match) in enumerate(self.games):
            recorder.set_params(state.params.policy, jax.random.fold_in(key, g))
            if not match.alive:
                recorder.warm_up()  # the first call compiles before the server starts
                restarts[g] += self._fresh_match(recorder, match)
            recorder.start()
        seen = [(0, time.monotonic())] * len(self.games)
        while True:
            done = True
            for g, (recorder, _, match) in enumerate(self.games):
                count = recorder.recorded()
                if count >= steps + 1:
                    continue
                done = False
                if count != seen[g][0]:
                    seen[g] = (count, time.monotonic())
                elif not match.alive or time.monotonic() - seen[g][1] > _STALL_S:
                    restarts[g] += self._fresh_match(recorder, match)
                    seen[g] = (count, time.monotonic())
            if done:
                break
            time.sleep(0.02)
        segments = [recorder.stop() for recorder, _, _ in self.games]
        played = time.perf_counter()
        rollout, counts = pack(segments, steps, self.policy, self.params,
                               shaping=bool(state.shaping.active), teacher=self.teacher,
                               key=jax.random.fold_in(key, len(self.games)))
        writer, iteration = csv.writer(self.csv), int(state.iteration) + 1
        for g, c in enumerate(counts):
            writer.writerow((iteration, g, self.games[g][0].match, c["goals_for"],
                             c["goals_against"], steps, c["routine"], c["defaulted"],
                             c["filled"], c["matches"], restarts[g],
                             self.games[g][2].missed_cycles(), f"{played - self.began:.1f}"))
        self.csv.flush()
        total = steps * PLAYERS * len(counts)
        row = {f"robocup/{name}": sum(c[name] for c in counts) / total
               for name in ("routine", "defaulted", "filled")}
        row["robocup/restarts"] = float(sum(restarts))
        row["time/play_steps_per_s"] = len(counts) * steps / max(played - began, 1e-9)
        return rollout, row

    def _fresh_match(self, recorder: Recorder, match: ServerMatch) -> int:
        """Start a fresh match for ``recorder``'s game: 1 when one ran before (it ended, or
        its server died), 0 for the game's first."""
        restarted = int(match.server is not None)
        recorder.new_match()
        match.start()
        self.matches += 1
        return restarted


def train_skills(config: SkillsTrainConfig, *, resume: bool = False,
                 progress: bool = True) -> SkillsTrainResult:
    """Run ``config`` with ``elevens.runs.loop.train``, every iteration's games recorded from
    matches in rcssserver (module docstring)."""
    config.validate()
    games = SkillGames(config)
    host = HostGames(
        make_learner=lambda learner, env: make_learner(
            learner, env, team_on_field, devices=1, external_games=True,
            external_teacher=True),
        open=games.open,
    )
    result = train(config.train_config(), resume=resume, progress=progress, host=host)
    fields = {field.name: getattr(result, field.name) for field in dataclasses.fields(result)}
    return SkillsTrainResult(**fields, matches=games.matches)
