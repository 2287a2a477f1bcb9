"""TrainConfig: every knob of a training run, as frozen, typed, documented dataclasses.

A run's config has two parts. ``LearnerConfig`` is everything that is compiled into the learner
(the game, the networks, PPO, the opponent, games per iteration and K): ``make_learner`` takes
it and the game built from it alone, so nothing of the host loop can change what is computed.
``RunConfig`` is the host loop (length, evaluation, checkpoints, seed, devices, run directory).
``TrainConfig`` holds both and the preset's name.

A config is built from a named preset plus overrides named as the flags are
(``make_config("2v2", **{"ppo.epochs": 3, "games_per_iteration": 32, "run.iterations": 10})``),
checked by ``validate`` before anything compiles, and saved as JSON beside every checkpoint
(``to_dict`` / ``from_saved``, ``config_version`` 2; a version-1 file, from before the split,
is read field by field; nothing is pickled). The comment under each field says where its
default comes from: the thesis (seeds/000: Algorithm 4, section 4.2, section 5.2, tables 6.1 and
6.2), SPEC.md (the game's defaults, which are ``EnvParams``'s), or our own choice and why.

Units of the learner (see ``elevens.train.rollout``): one iteration plays ``games_per_iteration``
whole episodes; in each of them the learning team's ``n`` players each give one sequence of
``episode_length`` steps. The PPO batch (``LearnerConfig.batch_size``) is those
``games_per_iteration * n`` player sequences (table 6.1's 660 is 330 games of 2 players, or 60
games of 11). ``ppo.minibatch_size`` counts sequences too; a minibatch holds whole games (the
critic, whose input is the same for a game's n players, then runs once per game instead of n
times), so it must be a multiple of n that divides the batch: table 6.1's 60 for 1 or 2 players
a side, 55 (5 games, 12 minibatches) for 11.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import typing
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Annotated, Any, ClassVar

import tyro

from elevens.env.params import MAX_PLAYERS_PER_TEAM, EnvParams
from elevens.env.randomize import Randomize
from elevens.env.soccer import Soccer
from elevens.env.state import NUM_SELF_FEATURES
from elevens.train.opponents import (
    LEAGUE_EVERY,
    LEAGUE_MIN_GAMES,
    LEAGUE_PSI,
    LEAGUE_WINDOW,
    OPPONENT_KINDS,
    POLYAK_TAU,
    POLYAK_THRESHOLD,
)
from elevens.train.ppo import PPOHyperparams
from elevens.train.shaping import SHAPING_THRESHOLD, SHAPING_WINDOW

EVAL_TEAMS: tuple[str, ...] = ("random", "naive", "teamwork")
"""The handcrafted teams the learner can be evaluated against (``elevens.eval.play``)."""
CONFIG_VERSION = 2
"""Written as ``config_version`` by ``to_dict``. 1 (no key): before LearnerConfig/RunConfig."""
_SCENARIO = re.compile(r"^(\d+)v(\d+)$")
_SHORT = tyro.conf.arg(prefix_name=False)
"""A group or field of the learner whose flag keeps its own short name (``--ppo.epochs``, not
``--learner.ppo.epochs``)."""


# --------------------------------------------------------------------------------------------
# The groups
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """The game the learner trains in: the simulator's own ``EnvParams`` (every rule and
    constant of SPEC.md, each a flag ``--env.NAME``) and the training-only schedules."""

    game: Annotated[EnvParams, tyro.conf.arg(name="env", prefix_name=False)] = EnvParams(
        players_per_team=2, spawn="random"
    )
    """The game, ``players_per_team`` a side. Default: the thesis' 4-player setting with random
    spawns ("we spawn the agents at random positions at the start of each 4 player game", 6.5);
    every other number is SPEC.md's (``elevens.env.params``)."""
    shaping_schedule: bool = True
    """Switch shaping off for good once the learner scores in > shaping_threshold of its recent
    games (thesis section 4.2). False keeps the shaping weights on for the whole run."""
    shaping_window: int = SHAPING_WINDOW
    """Recent games the scoring rate is measured over (shaping.py: 100; the thesis names none)."""
    shaping_threshold: float = SHAPING_THRESHOLD
    """Shaping goes off when the scoring rate is above this (section 4.2: "more than 75%")."""
    mix: tuple[str, ...] = ()
    """Other games trained in the same run beside the main one (thesis 7.4.4), as 'NvN', e.g.
    ('2v2',): the small games teach the basic skills cheaply, the full one team play. Each chunk
    of iterations plays one size, chosen so that each size gets its share (``mix_shares``).
    Every size plays the main game's batch of player sequences an iteration (batch / n games) in
    minibatches of ``ppo.minibatch_size`` sequences, so both must be multiples of each size's n.
    The networks attend over entity slots, so one set of weights plays every size with no
    padding (a 2 v 2 game costs what a 2 v 2 game costs). Evaluation and the GIF use the main
    game. (): one size."""
    mix_shares: tuple[float, ...] = ()
    """The share of the iterations of each game of ``mix``, in its order; the main game has the
    rest. E.g. ``mix=('2v2',), mix_shares=(0.5,)``: every other chunk is 2 v 2."""
    randomize: Randomize = Randomize()
    """Domain randomisation (thesis 7.4.5): with ``enabled`` every game of an iteration draws
    its ball friction, kick impulse, player speed and turn rate, field size, goal width, view
    angle and sight noise from these ranges, fixed for its episode (``elevens.env.randomize``),
    so the policy cannot overfit one set of dynamics. Off (the default): every game is
    ``env``'s. The simulator's own game only; the run's evaluations play ``env``'s game
    (held-out draws: ``elevens tournament --randomize SEED``)."""
    physics: str = "thesis"
    """The game's bodies and action: "thesis", the simulator's own game (``elevens.env.soccer``,
    the 2-value (move, rot) action). Other names belong to games registered by a package above
    the core (``register_game``), each with its own ``EnvConfig`` subclass; a config of one is
    made from its preset (``elevens train --help`` lists them), and a saved one reads back as
    its class."""

    PHYSICS: ClassVar[str] = "thesis"
    """The ``physics`` this class plays (a subclass names its own)."""

    def make_env(self, players_per_team: int) -> Soccer:
        """The game a learner trains in, ``players_per_team`` a side (pure reset and step)."""
        return Soccer(players_per_team)

    @property
    def actions(self) -> int:
        """Action values a player gives in this game (its env's ``actions``): 2, the
        simulator's (move, rot)."""
        return Soccer.actions

    @property
    def kinds(self) -> int | None:
        """The kinds of this game's parametrised decision, which ``network.kinds`` must match;
        None: the game sets none (the simulator's action is continuous)."""
        return None

    def check(self) -> None:
        """The checks of this game's own fields (the subclasses' extra ones); raises
        ``ValueError`` naming the first bad one."""

    @property
    def self_features(self) -> int:
        """Self features a player's observation holds in this game: ``SELF_FEATURES`` (a game
        may add its own after them)."""
        return NUM_SELF_FEATURES

    @property
    def players_per_team(self) -> int:
        """n, the players a side of the main game."""
        return self.game.players_per_team

    @property
    def scenario(self) -> str:
        """The main game as 'NvN' (the form of ``mix``)."""
        return f"{self.players_per_team}v{self.players_per_team}"


GAMES: dict[str, type[EnvConfig]] = {EnvConfig.PHYSICS: EnvConfig}
"""The games a learner can train in, by ``env.physics``: the simulator's own, and those a
package above the core registers (``register_game``)."""


def register_game(env_config: type[EnvConfig]) -> None:
    """Make a game known by its ``EnvConfig`` subclass's ``PHYSICS``: configs of it validate,
    and saved ones read back as that class."""
    GAMES[env_config.PHYSICS] = env_config


# Version 2 wrote these fields of another game's EnvConfig for every game; in the simulator's
# own game they held their defaults (any other value was refused) and are dropped on reading.
_OTHER_GAMES_FIELDS = {"stamina": False, "goalie": False, "see_period": 1}

NETWORK_ACTIONS = (2, 4, 12)
NETWORK_HEADS = ("gaussian", "parametrised")
PARAMETRISED_ACTIONS = 4
# Fields added after config version 2 whose default is all that older versions knew: filled
# without a warning.
_SILENT_DEFAULTS = (
    "learner.network.actions", "learner.network.head", "learner.network.kinds",
    "learner.network.kind_mask", "learner.network.last_kind_logit", "learner.env.defer",
    "learner.env.physics", "learner.env.see_period",
    "learner.env.stamina", "learner.env.goalie", "learner.env.reach_features",
    "learner.env.game.possession_shaping_weight",
    "learner.env.game.possession_radius", "learner.env.game.possession_by",
    "learner.env.game.observation_noise", "learner.env.randomize",
    "learner.ppo.teacher", "learner.ppo.teacher_weight", "learner.ppo.teacher_iterations",
    "learner.ppo.teacher_balance", "learner.ppo.teacher_group_balance",
    "learner.opponent.mix_games",
)


@dataclasses.dataclass(frozen=True)
class NetworkConfig:
    """The policy and critic networks (``elevens.nets``); defaults are the thesis network."""

    use_attention: bool = True
    """Attention over the seen entities (thesis 5.2.10). False: the feedforward ablation (6.4)."""
    use_lstm: bool = True
    """out_r is a 2-layer LSTM (table 6.2). False: a feedforward head without memory."""
    features: int = 64
    """Width of every feedforward block and of the attention (table 6.1: 64)."""
    num_heads: int = 4
    """Attention heads of features / num_heads each (nets default; the thesis gives no number)."""
    lstm_features: int = 32
    """LSTM units per layer (table 6.1: 32)."""
    lstm_layers: int = 2
    """LSTM layers in out_r (table 6.2: 2)."""
    actions: int = 2
    """Policy outputs: 2, the simulator's (move, rot); 12, the thesis's 12-value action (table
    4.1), for a game that takes it (``EnvConfig.actions``) or one played outside the
    simulator; 4, a parametrised action (kind, pointer, x, y), which ``head`` 'parametrised'
    gives as such (the Gaussian head gives 4 continuous values)."""
    head: str = "gaussian"
    """The action head. 'gaussian': a tanh-squashed Gaussian over ``actions`` values.
    'parametrised': a discrete kind, a pointer at a teammate or opponent slot (by attention over
    the encoder's per-entity embeddings) and a target (x, y) in [-1, 1]^2, the action
    (kind, pointer, x, y) (``nets.distributions.ParametrisedDistribution``); needs
    ``actions`` 4, ``kinds`` and attention."""
    kinds: int = 0
    """The parametrised head's number of kinds K (>= 1); 0 with the Gaussian head."""
    kind_mask: str = ""
    """The parametrised head: which kinds a player may choose in each situation, a mask its game
    registers (``nets.policy.KIND_MASKS``; the skill game's 'ball': the ball kinds with the
    ball within kicking reach, the others without); '': every kind, always."""
    last_kind_logit: float = 0.0
    """The parametrised head: a constant added to the last kind's logit. With the skill game's
    ``env.defer``, how strongly an untrained policy defers to ``skills_naive`` (6: about 98%
    of its draws against 8 other kinds near uniform; its mode defers)."""

    def policy(self) -> Any:
        """The ``AttentionPolicy`` module of this config."""
        from elevens.nets.policy import AttentionPolicy

        return AttentionPolicy(
            features=self.features,
            num_heads=self.num_heads,
            lstm_features=self.lstm_features,
            lstm_layers=self.lstm_layers,
            use_attention=self.use_attention,
            use_lstm=self.use_lstm,
            num_actions=self.actions,
            kinds=self.kinds if self.head == "parametrised" else 0,
            kind_mask=self.kind_mask if self.head == "parametrised" else "",
            last_kind_logit=self.last_kind_logit if self.head == "parametrised" else 0.0,
        )

    def critic(self) -> Any:
        """The ``AttentionCritic`` module of this config."""
        from elevens.nets.critic import AttentionCritic

        return AttentionCritic(
            features=self.features, num_heads=self.num_heads, use_attention=self.use_attention
        )


@dataclasses.dataclass(frozen=True)
class OpponentConfig:
    """Who the learning team plays during training (``elevens.train.opponents``)."""

    kind: str = "polyak"
    """'polyak': Polyak-averaged opponent with freezing (thesis 5.2.6, its best setting);
    'self': plain self-play against the latest learner (the ablation); 'league': past snapshots
    sampled by win rate (5.2.7)."""
    polyak_tau: float = POLYAK_TAU
    """alpha_s, the Polyak update rate (table 6.1: 0.01). 'polyak' only."""
    freeze_threshold: float = POLYAK_THRESHOLD
    """epsilon_s (table 6.1: 0.55): the opponent moves only if the learner's mean outcome in the
    iteration is above it, else it is frozen (Algorithm 4 line 25). 'polyak' only."""
    league_capacity: int = 32
    """Snapshots the league holds; the weakest evaluated one is evicted when full. The thesis
    names no limit; 32 policies are about 18 MB with the thesis network."""
    league_every: int = LEAGUE_EVERY
    """A snapshot of the learner joins every this many iterations (section 5.2.7: 10)."""
    league_psi: float = LEAGUE_PSI
    """psi of eq. 5.2, p_i proportional to w_i ** psi (section 5.2.7: 2)."""
    league_min_games: int = LEAGUE_MIN_GAMES
    """A snapshot's win rate is held at 0.5 until it has played this many games (5.2.7: 100)."""
    league_window: int = LEAGUE_WINDOW
    """Games per snapshot its win rate is averaged over (section 5.2.7: the past 1000)."""
    mix: tuple[str, ...] = ()
    """Fixed opponents beside self-play, ``TEAM=SHARE`` each: TEAM is any team spec of
    ``elevens tournament`` (naive, teamwork, random, a shipped team, a run or checkpoint
    ``PATH[@ITERATION]``, an exported folder) and SHARE its share of each iteration's games.
    ``self=SHARE`` sets the share of ``kind`` (default: the rest; ``self=0`` trains against the
    fixed teams alone). E.g. ``('self=0.8', 'naive=0.1', 'runs/x=0.1')``. The fixed teams'
    games train the learner like the others; the opponent's own updates (the Polyak freeze,
    the league's win rates) read the self-play games only."""
    mix_games: tuple[str, ...] = ()
    """The game sizes (``NvN``: the main game or games of ``env.mix``) whose iterations play
    the fixed teams of ``mix``; the others are all self-play. Empty: every size. E.g.
    ``('11v11',)`` in a run mixed with 2 v 2 keeps the 2 v 2 iterations for self-play."""


@dataclasses.dataclass(frozen=True)
class LearnerConfig:
    """Everything compiled into the learner (``make_learner`` takes this and the game built
    from it, ``make_env``): the game, the networks, PPO, the opponent, and how many games and
    iterations one compiled call plays."""

    env: Annotated[EnvConfig, _SHORT] = EnvConfig()
    """The game."""
    network: Annotated[NetworkConfig, _SHORT] = NetworkConfig()
    """Policy and critic networks."""
    ppo: Annotated[PPOHyperparams, _SHORT] = PPOHyperparams()
    """PPO numbers (elevens.train.ppo: table 6.1 and Algorithm 4)."""
    opponent: Annotated[OpponentConfig, _SHORT] = OpponentConfig()
    """The training opponent."""
    games_per_iteration: Annotated[int, _SHORT] = 330
    """Games played per iteration, all at once (vmapped). The learner plays side 0 in the first
    ceil(G / 2) of them and side 1 in the rest. 330 x 2 players = table 6.1's batch of 660."""
    iterations_per_chunk: Annotated[int, _SHORT] = 5
    """K: iterations compiled into one call (lax.scan). Larger K means fewer host round trips;
    logging, evaluation and checkpoints happen only between chunks. It changes no result, so a
    resumed run may change it."""

    @property
    def players_per_team(self) -> int:
        return self.env.players_per_team

    @property
    def batch_size(self) -> int:
        """The PPO batch in player sequences: games_per_iteration * n (table 6.1: 660)."""
        return self.games_per_iteration * self.players_per_team

    @property
    def num_minibatches(self) -> int:
        """Minibatches per epoch (table 6.1: 660 / 60 = 11)."""
        return self.batch_size // self.ppo.minibatch_size

    @property
    def env_steps_per_iteration(self) -> int:
        """Game steps per iteration (one step of one game, all 2n players acting)."""
        return self.games_per_iteration * self.env.game.episode_length

    def validate(self) -> LearnerConfig:
        """Raise ``ValueError`` naming the first bad field and its allowed values; else return
        self. Pure Python: nothing is traced or compiled."""
        validate_learner(self)
        return self

    def make_env(self) -> Soccer:
        """The game to train in (``make_learner(config, config.make_env())``): the game's own
        fields checked (``EnvConfig.check``), then ``env.make_env`` at this config's team size."""
        self.env.check()
        return self.env.make_env(self.players_per_team)


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """How long to train, and what the host loop does between compiled chunks."""

    iterations: int = 5000
    """Learner iterations (one iteration = one episode in every game, then the PPO epochs)."""
    max_minutes: float = 0.0
    """Training time budget: the run ends like a finished one (final evaluation, checkpoint,
    curve, GIF) at the first chunk end where ``time/hours`` (compiling, chunks and evaluations,
    summed over resumed sessions) reaches it, even before ``iterations``. 0: no budget."""
    eval_every: int = 25
    """Evaluate against the handcrafted teams every this many iterations (at the first chunk end
    past each multiple), and at the end. 0: only at the end."""
    eval_games: int = 100
    """Games per handcrafted team per evaluation (half on each side)."""
    eval_teams: tuple[str, ...] = EVAL_TEAMS
    """Teams to evaluate against (thesis 6.1: random, naive, teamwork): handcrafted teams or any
    team spec, e.g. a shipped team or a checkpoint ``runs/x@300`` (figure 6.4's fourth line).
    A spec that does not load stops the run before anything compiles."""
    eval_deterministic: bool = False
    """False: the learner samples its actions in evaluation, as it does in training and as the
    thesis' executors did; True: it plays the mean action tanh(mean)."""
    checkpoint_every: int = 25
    """Checkpoint every this many iterations (at the first chunk end past each multiple), at the
    end, and on Ctrl-C. 0: only at the end and on Ctrl-C."""
    keep_checkpoints: int = 3
    """Newest checkpoints kept on disk; older ones are deleted after a successful save."""
    seed: int = 0
    """Seed of the run: initial params, every game, every minibatch shuffle."""
    devices: int = 0
    """Devices the games of an iteration are split over (data parallel; parameters replicated):
    0 = every device of every process (one on a plain CPU), N = the first N. The games per
    iteration and per minibatch must be multiples of it. The result does not depend on it (to
    float tolerance); a resume must use the same number."""
    init_from: str = ""
    """Start from another run's networks instead of random ones: a run, checkpoints or step
    directory (``PATH@ITERATION`` picks a checkpoint), trained at any team size; its network
    fields must be this run's. Adam starts afresh and the opponent starts as the loaded policy.
    A resume ignores it (the checkpoint holds the networks). "": random networks."""
    run_dir: str = "runs/2v2"
    """Where logs, checkpoints, the learning curve and the GIF go."""
    write_plot: bool = True
    """Write ``learning_curve.png`` at the end."""
    write_gif: bool = True
    """Write ``learner_vs_naive.gif`` (one game against the naive team) at the end."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """A whole training run. Build with ``make_config``; check with ``validate``."""

    preset: str = "2v2"
    """The preset this config started from (informational; the fields below are what count)."""
    learner: LearnerConfig = LearnerConfig()
    """What is computed (flags: --env.*, --network.*, --ppo.*, --opponent.*,
    --games-per-iteration, --iterations-per-chunk)."""
    run: RunConfig = RunConfig()
    """Length, evaluation, checkpoints, seed, devices and run directory."""

    def validate(self) -> TrainConfig:
        """Raise ``ValueError`` naming the first bad field and its allowed values; else return
        self. Pure Python: nothing is traced or compiled."""
        validate(self)
        return self

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (tuples become lists), with ``config_version``."""
        fields = json.loads(json.dumps(dataclasses.asdict(self)))
        return {"config_version": CONFIG_VERSION, **fields}

    @classmethod
    def from_saved(cls, data: Mapping[str, Any], source: str) -> TrainConfig:
        """A config read back from ``source`` (a checkpoint's or an exported team's
        config.json), older versions' included (``from_dict(fill_missing=True)``); a
        ``ValueError`` naming ``source`` if it is not a TrainConfig of any version."""
        try:
            return cls.from_dict(data, fill_missing=True)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{source} is not a TrainConfig of this version: {error}") from None

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], fill_missing: bool = False) -> TrainConfig:
        """The inverse of ``to_dict``; unknown keys are a ``ValueError``, and so are missing
        keys unless ``fill_missing``.

        ``fill_missing`` reads a config saved by an older version (a checkpoint's
        config.json): a version-1 dict is first mapped to version 2 (``migrate_v1``); fields
        added since then take their defaults, which reproduce the old behaviour (a new field
        must default to what the code did before it existed), and a ``UserWarning`` names them.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"config: expected an object, got {type(data).__name__}")
        version = data.get("config_version", 1)
        if version == 1 and fill_missing:
            data = migrate_v1(data)
        elif version != CONFIG_VERSION:
            raise ValueError(
                f"config_version={version!r} is not readable here: this version of elevens "
                f"writes {CONFIG_VERSION} and reads 1 (with fill_missing) and {CONFIG_VERSION}"
                + (" (was it saved by a newer version of elevens?)"
                   if _is_int(version) and version > CONFIG_VERSION else "")
            )
        fields = {key: value for key, value in data.items() if key != "config_version"}
        filled: list[str] | None = [] if fill_missing else None
        config = _from_dict(cls, fields, "", filled)
        filled = [name for name in filled or [] if name not in _SILENT_DEFAULTS]
        if filled:
            warnings.warn(
                "the config was saved by an older version of elevens; these fields are not in "
                f"it and take their defaults: {', '.join(filled)}",
                stacklevel=2,
            )
        return config

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"

    @classmethod
    def from_json(cls, text: str) -> TrainConfig:
        return cls.from_dict(json.loads(text))


_V1_GAME_FIELDS = (
    "spawn", "ball_spawn", "episode_length", "field_length", "field_width", "goal_width",
    "ball_shaping_weight", "approach_shaping_weight",
)
"""Version 1's copies of EnvParams fields in ``env``; now in ``env.game``."""


def migrate_v1(data: Mapping[str, Any]) -> dict[str, Any]:
    """A version-1 config dict (before LearnerConfig/RunConfig) as version 2, field by field:
    ``env.scenario`` 'NvN' and the copied EnvParams fields go to ``env.game``; ``ppo.batch_size``
    goes (it is derived now; a value other than games x n is an error);
    ``run.games_per_iteration`` and ``run.iterations_per_chunk`` move to the learner. Keys it
    does not know are left for ``from_dict`` to refuse."""
    old = {key: (dict(value) if isinstance(value, Mapping) else value)
           for key, value in data.items()}
    env, ppo, run = (old.get(name, {}) for name in ("env", "ppo", "run"))
    if not all(isinstance(group, dict) for group in (env, ppo, run)):
        raise ValueError("config version 1: env, ppo and run must be objects")
    scenario = env.pop("scenario", "2v2")
    match = _SCENARIO.match(scenario) if isinstance(scenario, str) else None
    if match is None or match.group(1) != match.group(2):
        raise ValueError(f"config version 1: {_scenario_error(scenario)}")
    n = int(match.group(1))
    # Version 1 could not set the other EnvParams fields: they had EnvParams's defaults. Its
    # EnvConfig spawned at random by default (EnvParams: formation).
    game = {field.name: field.default for field in dataclasses.fields(EnvParams)}
    game.update(players_per_team=n, spawn="random")
    game.update({name: env.pop(name) for name in _V1_GAME_FIELDS if name in env})
    learner: dict[str, Any] = {
        "env": {"game": game, **env},
        **{name: old.pop(name) for name in ("network", "opponent") if name in old},
    }
    for name in ("games_per_iteration", "iterations_per_chunk"):
        if name in run:
            learner[name] = run.pop(name)
    batch = ppo.pop("batch_size", None)
    games = learner.get("games_per_iteration")
    if batch is not None and isinstance(games, int) and batch != games * n:
        raise ValueError(
            f"config version 1: ppo.batch_size={batch!r} is not run.games_per_iteration x "
            f"players = {games} x {n}; version 2 derives the batch from those two"
        )
    learner["ppo"] = ppo
    old.pop("env", None)
    old.pop("ppo", None)
    old["run"] = run
    return {**old, "learner": learner, "config_version": CONFIG_VERSION}


# --------------------------------------------------------------------------------------------
# Presets
# --------------------------------------------------------------------------------------------


def _quickstart() -> TrainConfig:
    # 1 v 1 on a 50 x 35 field (a quarter of the area) with 100-step episodes: a random team
    # rarely scores there while a learner that runs at the ball and pushes it forward does, so the
    # eval outcome against random rises from 0.5 to about 0.8 within the first 40 iterations
    # (a minute on a 2-core CPU). A smaller network (32 wide, one LSTM layer of 16) keeps compile
    # and update times short; 64 games of 1 player with minibatches of 16 sequences give 4 Adam
    # steps per epoch, at a learning rate of 1e-3 (10x table 6.1: few, small steps). gamma 0.99
    # suits 100-step episodes (0.999 barely discounts them). 300 iterations: about 2-3 minutes.
    return TrainConfig(
        preset="quickstart",
        learner=LearnerConfig(
            env=EnvConfig(
                game=EnvParams(
                    players_per_team=1,
                    spawn="random",
                    ball_spawn="random",
                    episode_length=100,
                    field_length=50.0,
                    field_width=35.0,
                    goal_width=20.0,
                )
            ),
            network=NetworkConfig(features=32, num_heads=4, lstm_features=16, lstm_layers=1),
            ppo=PPOHyperparams(learning_rate=1e-3, minibatch_size=16, gamma=0.99, epochs=5),
            opponent=OpponentConfig(kind="polyak"),
            games_per_iteration=64,
            iterations_per_chunk=5,
        ),
        run=RunConfig(
            iterations=300,
            eval_every=10,
            eval_games=64,
            eval_teams=("random", "naive"),
            checkpoint_every=20,
            run_dir="runs/quickstart",
        ),
    )


def _two_v_two() -> TrainConfig:
    # The thesis' 4-player setting (random spawns, 400-step episodes, its networks, clip 0.1,
    # 5 epochs, Polyak opponent with the freeze rule), with the update tuned for wall-clock on
    # one machine rather than the thesis' day-long runs: 64 games an iteration in minibatches of
    # 8 games, Adam 5e-4, GAE(0.95) with standardised advantages, a Polyak rate of 0.05 (the
    # opponent trails by tens of iterations, not hundreds), shaping kept on, and an entropy
    # weight of 1e-3 (against standardised advantages table 6.1's 0.01 widens the Gaussian
    # until the actions saturate). The measurements behind each choice, and table 6.1's exact
    # flags, are in docs/results/2v2_learning.md.
    return TrainConfig(
        preset="2v2",
        learner=LearnerConfig(
            env=EnvConfig(
                game=EnvParams(players_per_team=2, spawn="random", episode_length=400),
                shaping_schedule=False,
            ),
            ppo=PPOHyperparams(
                learning_rate=5e-4,
                minibatch_size=16,
                gamma=0.99,
                advantage_estimator="gae",
                normalize_advantages=True,
                entropy_weight=1e-3,
            ),
            opponent=OpponentConfig(kind="polyak", polyak_tau=0.05),
            games_per_iteration=64,
            iterations_per_chunk=5,
        ),
        run=RunConfig(
            iterations=5000,
            eval_every=10,
            eval_games=100,
            eval_teams=("random", "naive"),
            checkpoint_every=10,
            run_dir="runs/2v2",
        ),
    )


def _eleven_v_eleven() -> TrainConfig:
    # The full game against a Polyak-averaged opponent (thesis 6.3, its best setting): formation
    # spawns, 400 steps, table 6.1 numbers. 60 games x 11 players = the batch of 660 sequences,
    # in minibatches of 5 whole games (55 sequences; 60 is not a multiple of 11, and the thesis
    # chose 60 only as what fit its 8 GB GPU, section 6.2.2). One iteration is 24,000 game steps
    # (about two minutes on a 2-core CPU), hence K = 1.
    return TrainConfig(
        preset="11v11",
        learner=LearnerConfig(
            env=EnvConfig(
                game=EnvParams(players_per_team=11, spawn="formation", episode_length=400)
            ),
            ppo=PPOHyperparams(minibatch_size=55),
            opponent=OpponentConfig(kind="polyak"),
            games_per_iteration=60,
            iterations_per_chunk=1,
        ),
        run=RunConfig(
            iterations=5000,
            eval_every=10,
            eval_games=50,
            checkpoint_every=10,
            run_dir="runs/11v11",
        ),
    )


def _two_v_two_gpu() -> TrainConfig:
    # The 2v2 preset with batches sized for one GPU: 1,024 games an iteration in minibatches of
    # 512 player sequences. An Adam step over 400-step LSTM sequences is latency bound on a GPU,
    # so each step takes a large minibatch (20 steps an iteration instead of 40). What it gave on
    # an H200 is in docs/results/scaling.md.
    config = _two_v_two()
    learner = config.learner
    return dataclasses.replace(
        config,
        preset="2v2-gpu",
        learner=dataclasses.replace(
            learner,
            ppo=dataclasses.replace(learner.ppo, minibatch_size=512),
            games_per_iteration=1024,
        ),
        run=dataclasses.replace(
            config.run,
            eval_every=50,
            eval_games=200,
            checkpoint_every=50,
            run_dir="runs/2v2-gpu",
        ),
    )


PRESETS = {
    "quickstart": _quickstart,
    "2v2": _two_v_two,
    "2v2-gpu": _two_v_two_gpu,
    "11v11": _eleven_v_eleven,
}
"""Named starting points: a few-minute CPU demo, the thesis' 4-player and 22-player settings,
and the 4-player setting with batches for one GPU; games registered above the core add their
own (``register_preset``)."""

PRESET_DESCRIPTIONS: dict[str, str] = {}
"""What each preset registered with ``register_preset`` is (the CLI's help)."""


def register_preset(name: str, make: Callable[[], TrainConfig], description: str) -> None:
    """Add the preset ``name`` (``make`` builds its config) for ``make_config`` and the CLI."""
    PRESETS[name] = make
    PRESET_DESCRIPTIONS[name] = description


def make_config(preset: str = "quickstart", **overrides: Any) -> TrainConfig:
    """A validated config: ``preset`` plus overrides named as the flags are, with underscores.

    Example: ``make_config("2v2", **{"ppo.learning_rate": 3e-4, "env.episode_length": 200,
    "games_per_iteration": 32, "run.iterations": 10})``; the separator may also be a double
    underscore (``run__iterations=10``) to pass them as keywords. A whole group may be given
    too (``ppo=PPOHyperparams(...)``, ``env=EnvConfig(...)``, ``learner=...``). Raises
    ``ValueError`` for an unknown preset (naming the allowed ones), an unknown field (naming the
    allowed fields), or any value that ``validate`` rejects; nothing is compiled.
    """
    if preset not in PRESETS:
        raise ValueError(
            f"preset={preset!r} is unknown: allowed presets are {', '.join(PRESETS)}"
        )
    config = PRESETS[preset]()
    return apply_overrides(config, overrides).validate()


_Config = typing.TypeVar("_Config")

RENAMED_IN_V2 = {
    "env.scenario": "env.players_per_team (an int)",
    "ppo.batch_size": "nothing: the batch is games_per_iteration x players",
    "run.games_per_iteration": "games_per_iteration",
    "run.iterations_per_chunk": "iterations_per_chunk",
}
"""Version 1's override names that no longer exist, and what replaces them."""


def short_path(path: str) -> str:
    """A field's name as its flag has it: 'learner.env.game.kick_impulse' -> 'env.kick_impulse',
    'learner.games_per_iteration' -> 'games_per_iteration', 'run.seed' -> 'run.seed'."""
    path = path.removeprefix("learner.")
    return "env." + path.removeprefix("env.game.") if path.startswith("env.game.") else path


def config_paths(config: Any) -> dict[str, str]:
    """Short name (``short_path``) -> path of every group and field of ``config`` (a
    ``TrainConfig``, or any dataclass holding a ``learner`` the same way)."""
    paths: dict[str, str] = {}

    def walk(node: Any, prefix: str) -> None:
        for field in dataclasses.fields(node):
            path = f"{prefix}{field.name}"
            paths[short_path(path)] = path
            value = getattr(node, field.name)
            if dataclasses.is_dataclass(value):
                walk(value, path + ".")

    walk(config, "")
    return paths


def apply_overrides(config: _Config, overrides: Mapping[str, Any]) -> _Config:
    """``config`` (a ``TrainConfig``, or one that holds a ``learner`` the same way, e.g.
    a wing's run config) with fields replaced by short name (see ``make_config``); not
    validated beyond what each group checks on construction (EnvParams and PPOHyperparams
    do)."""
    paths = config_paths(config)
    by_parent: dict[str, dict[str, Any]] = {}
    for raw_name, value in overrides.items():
        name = raw_name.replace("__", ".")
        if name not in paths:
            group = name.rpartition(".")[0]
            allowed = sorted(k for k in paths if k.rpartition(".")[0] == group) or sorted(paths)
            hint = f" (renamed in config version 2: use {RENAMED_IN_V2[name]})" if (
                name in RENAMED_IN_V2) else ""
            raise ValueError(
                f"override {raw_name!r}: unknown field{hint}; allowed names are "
                f"{', '.join(allowed)}"
            )
        parent, _, field = paths[name].rpartition(".")
        by_parent.setdefault(parent, {})[field] = value
    # Whole groups before the fields inside them.
    for parent in sorted(by_parent, key=lambda path: path.count(".") if path else -1):
        config = _replace_at(config, parent, by_parent[parent])
    return config


def _replace_at(config: _Config, parent: str, fields: Mapping[str, Any]) -> _Config:
    """``config`` with ``fields`` of the group at ``parent`` ('' for the top) replaced."""
    names = parent.split(".") if parent else []

    def rebuild(node: Any, depth: int) -> Any:
        if depth == len(names):
            label = short_path(f"{parent}.x").rpartition(".")[0] if parent else ""
            return _replace_group(node, fields, label)
        child = rebuild(getattr(node, names[depth]), depth + 1)
        return dataclasses.replace(node, **{names[depth]: child})

    return typing.cast(_Config, rebuild(config, 0))


def _replace_group(node: Any, fields: Mapping[str, Any], name: str) -> Any:
    """EnvParams and PPOHyperparams check themselves on construction; their errors get the
    group's name, and the PPO cases they word less clearly are checked first."""
    if isinstance(node, PPOHyperparams):
        _check_ppo_extras({**dataclasses.asdict(node), **fields})
    try:
        return dataclasses.replace(node, **fields)
    except ValueError as error:
        named = not name or str(error).startswith(f"{name}.")  # it names its group already
        raise ValueError(str(error) if named else f"{name}: {error}") from None


# --------------------------------------------------------------------------------------------
# Validation (pure Python, before anything compiles)
# --------------------------------------------------------------------------------------------


def _scenario_error(scenario: object) -> str:
    return (
        f"env.scenario={scenario!r} is invalid: use 'NvN' with N from 1 to "
        f"{MAX_PLAYERS_PER_TEAM}, e.g. '1v1', '2v2' or '11v11'"
    )


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


def _int_at_least(path: str, value: object, minimum: int) -> None:
    _require(
        _is_int(value) and value >= minimum,  # type: ignore[operator]
        f"{path}={value!r} is invalid: it must be an integer >= {minimum}",
    )


def _in_unit_interval(path: str, value: object) -> None:
    _require(
        _is_number(value) and 0.0 <= value <= 1.0,  # type: ignore[operator]
        f"{path}={value!r} is invalid: it must be a number in [0, 1]",
    )


def _check_ppo_extras(fields: Mapping[str, Any]) -> None:
    """What PPOHyperparams does not check, or words as a divisibility problem."""
    lr = fields["learning_rate"]
    _require(
        _is_number(lr) and math.isfinite(lr) and lr > 0,
        f"ppo.learning_rate={lr!r} is invalid: it must be a finite number > 0",
    )
    for name in ("minibatch_size", "epochs"):
        _int_at_least(f"ppo.{name}", fields[name], 1)
    for name in ("policy_weight", "value_weight", "entropy_weight", "teacher_weight"):
        value = fields[name]
        _require(
            _is_number(value) and math.isfinite(value) and value >= 0,
            f"ppo.{name}={value!r} is invalid: it must be a finite number >= 0",
        )
    teacher = fields["teacher"]
    _require(
        isinstance(teacher, str) and teacher == teacher.strip(),
        f"ppo.teacher={teacher!r} is invalid: it must be a team spec (e.g. 'naive', a shipped "
        "team or runs/NAME), without spaces around it, or '' for none",
    )
    _int_at_least("ppo.teacher_iterations", fields["teacher_iterations"], 0)
    balance = fields["teacher_balance"]
    _require(
        isinstance(balance, bool),
        f"ppo.teacher_balance={balance!r} is invalid: it must be True or False",
    )
    groups = fields["teacher_group_balance"]
    _require(
        isinstance(groups, bool),
        f"ppo.teacher_group_balance={groups!r} is invalid: it must be True or False",
    )
    _require(
        not (groups and balance),
        "ppo.teacher_group_balance=True is invalid with ppo.teacher_balance=True: weigh the "
        "teacher's entries by their kind or by their kind mask's group, not both",
    )


def validate(config: TrainConfig) -> None:
    """Check every field of ``config``; raise ``ValueError`` naming the first bad one."""
    _require(isinstance(config, TrainConfig), f"expected a TrainConfig, got {type(config)}")
    _require(
        isinstance(config.learner, LearnerConfig),
        f"learner must be a LearnerConfig, got {type(config.learner).__name__}",
    )
    _validate_run(config.run)
    validate_learner(config.learner)
    if config.learner.env.actions != 2:
        # The GIF plays the simulator's handcrafted teams, whose players give 2-value actions.
        _require(
            not config.run.write_gif,
            f"run.write_gif=True is invalid with env.physics={config.learner.env.physics!r}: "
            "the GIF's game is against the simulator's handcrafted teams, which give the "
            "2-value action; leave it out (--run.no-write-gif)",
        )
    _check_team_actions("run.eval_teams", config.run.eval_teams, config.learner)


def game_actions(learner: LearnerConfig) -> int:
    """Action values the game of ``learner`` takes from a team (``EnvConfig.actions``)."""
    return learner.env.actions


def _check_team_actions(flag: str, specs: Any, learner: LearnerConfig) -> None:
    """Handcrafted teams among ``specs`` must give the action the game takes (the simulator's
    2-value one, or another game's). Trained teams are checked when they load."""
    from elevens.teams.registry import HANDCRAFTED, action_size, handcrafted_for

    actions = game_actions(learner)
    for spec in specs if isinstance(specs, tuple) else ():
        team = HANDCRAFTED.get(spec) if isinstance(spec, str) else None
        _require(
            team is None or action_size(team) == actions,
            f"{flag} team {spec!r} gives {action_size(team) if team else 0} action values, "
            f"but env.physics={learner.env.physics!r} takes {actions}: the handcrafted teams "
            f"for it are {', '.join(handcrafted_for(actions))}",
        )


def validate_learner(learner: LearnerConfig) -> None:
    """Check every field of ``learner``; raise ``ValueError`` naming the first bad one."""
    validate_training(learner)
    learner.env.check()


def validate_training(learner: LearnerConfig) -> None:
    """Check the fields a learner reads: all of ``learner``'s but its game's own, which only
    building the game reads (``EnvConfig.check``, ``LearnerConfig.make_env``)."""
    _require(isinstance(learner, LearnerConfig), f"expected a LearnerConfig, got {type(learner)}")
    _validate_env(learner.env)
    _validate_network(learner.network)
    game_kinds = learner.env.kinds
    if learner.network.head == "parametrised" and game_kinds is not None:
        _require(
            learner.network.kinds == game_kinds,
            f"network.kinds={learner.network.kinds!r} is invalid with this game: its decision "
            f"has {game_kinds} kinds (set network.kinds={game_kinds})",
        )
    _int_at_least("games_per_iteration", learner.games_per_iteration, 1)
    _int_at_least("iterations_per_chunk", learner.iterations_per_chunk, 1)
    _validate_ppo(learner)
    _validate_opponent(learner.opponent)
    _validate_mix(learner)
    _validate_opponent_mix(learner)


def _validate_env(env: EnvConfig) -> None:
    # EnvParams checks its own fields on construction (a from_dict or a flag included).
    _require(
        isinstance(env.game, EnvParams),
        f"env.game must be an EnvParams, got {type(env.game).__name__}",
    )
    _require(
        isinstance(env.shaping_schedule, bool),
        f"env.shaping_schedule={env.shaping_schedule!r} is invalid: it must be True or False",
    )
    _int_at_least("env.shaping_window", env.shaping_window, 1)
    _in_unit_interval("env.shaping_threshold", env.shaping_threshold)
    _require(
        env.physics == type(env).PHYSICS and env.physics in GAMES,
        f"env.physics={env.physics!r} is invalid here: this config's game is "
        f"{type(env).PHYSICS!r}; a game is chosen by its preset (elevens train --help), and the "
        f"games known to this process are {', '.join(sorted(GAMES))}",
    )
    _require(
        isinstance(env.randomize, Randomize),
        f"env.randomize must be a Randomize, got {type(env.randomize).__name__}",
    )
    # A Randomize checks its ranges when built (a flag, an override, a saved config).
    _require(
        not env.randomize.enabled or env.physics == EnvConfig.PHYSICS,
        f"env.randomize.enabled=True is invalid with env.physics={env.physics!r}: only the "
        f"simulator's own game ({EnvConfig.PHYSICS!r}) draws its constants",
    )


def _players_of(scenario: str) -> int:
    match = _SCENARIO.match(scenario)
    assert match is not None
    return int(match.group(1))


def _validate_mix(learner: LearnerConfig) -> None:
    env, ppo = learner.env, learner.ppo
    _require(
        isinstance(env.mix, tuple) and isinstance(env.mix_shares, tuple),
        "env.mix and env.mix_shares must be tuples",
    )
    for scenario in env.mix:
        match = _SCENARIO.match(scenario) if isinstance(scenario, str) else None
        _require(
            match is not None
            and match.group(1) == match.group(2)
            and 1 <= int(match.group(1)) <= MAX_PLAYERS_PER_TEAM,
            f"env.mix: {_scenario_error(scenario)}",
        )
    if not env.mix and not env.mix_shares:
        return
    _require(
        env.scenario not in env.mix and len(set(env.mix)) == len(env.mix),
        f"env.mix={env.mix!r} is invalid: its games must differ from each other and from "
        f"the main game ({env.scenario}, env.players_per_team={env.players_per_team})",
    )
    _require(
        len(env.mix_shares) == len(env.mix)
        and all(_is_number(share) and 0 < share < 1 for share in env.mix_shares)
        and sum(env.mix_shares) < 1,
        f"env.mix_shares={env.mix_shares!r} is invalid: give one share in (0, 1) per game of "
        f"env.mix={env.mix!r}, summing to less than 1 (the main game has the rest)",
    )
    batch = learner.batch_size
    for scenario in env.mix:
        n = _players_of(scenario)
        _require(
            batch % n == 0 and ppo.minibatch_size % n == 0,
            f"env.mix={env.mix!r} is invalid with a batch of {batch} player sequences "
            f"(games_per_iteration x players) and ppo.minibatch_size={ppo.minibatch_size}: "
            f"a {scenario} iteration needs multiples of {n} (whole games)",
        )
    _require(
        learner.opponent.kind != "league",
        "env.mix is invalid with opponent.kind='league': the league plays one snapshot per "
        "game, and the sizes differ in games per iteration; use 'polyak' or 'self'",
    )
    _require(
        learner.network.use_attention,
        "env.mix is invalid with network.use_attention=False: the feedforward network's first "
        "layer fits one team size",
    )


SELF = "self"
"""The name of the self-play opponent (``opponent.kind``) in ``opponent.mix``."""


def opponent_mix(learner: LearnerConfig) -> list[tuple[str, int]]:
    """``opponent.mix`` as (team spec, games an iteration), self-play (``SELF``) first, then the
    fixed teams in their order; every game has one opponent. Self-play may have 0 games."""
    games = learner.games_per_iteration
    entries = [_mix_entry(entry) for entry in learner.opponent.mix]
    fixed = [(spec, share) for spec, share in entries if spec != SELF]
    counts = [(spec, round(share * games)) for spec, share in fixed]
    return [(SELF, games - sum(count for _, count in counts)), *counts]


def self_play_games(learner: LearnerConfig) -> int:
    """Games an iteration against ``opponent.kind`` (all of them without ``opponent.mix``)."""
    return opponent_mix(learner)[0][1]


def _mix_entry(entry: str) -> tuple[str, float]:
    spec, _, share = entry.rpartition("=")
    return spec, float(share)


def scenario_config(learner: LearnerConfig, scenario: str) -> LearnerConfig:
    """The one-size learner that plays ``scenario``'s iterations of a mixed run: the same batch
    and minibatch in player sequences, batch / n games, no mix."""
    n = _players_of(scenario)
    env = learner.env
    opponent = learner.opponent
    if opponent.mix_games and scenario not in opponent.mix_games:
        opponent = dataclasses.replace(opponent, mix=(), mix_games=())
    return dataclasses.replace(
        learner,
        opponent=opponent,
        env=dataclasses.replace(
            env, game=dataclasses.replace(env.game, players_per_team=n), mix=(), mix_shares=()
        ),
        games_per_iteration=learner.batch_size // n,
    )


def mix_schedule(learner: LearnerConfig, chunks: int) -> list[str]:
    """The game each of the first ``chunks`` chunks of a run plays: at every chunk the game
    furthest below its share (the main game first on ties). Deterministic, so a resumed run
    follows the same schedule."""
    games = (learner.env.scenario, *learner.env.mix)
    shares = (1.0 - sum(learner.env.mix_shares), *learner.env.mix_shares)
    played = [0] * len(games)
    schedule = []
    for chunk in range(chunks):
        deficits = [share * (chunk + 1) - done for share, done in zip(shares, played, strict=True)]
        pick = max(range(len(games)), key=lambda index: (deficits[index], -index))
        played[pick] += 1
        schedule.append(games[pick])
    return schedule


def _validate_network(network: NetworkConfig) -> None:
    for name in ("features", "num_heads", "lstm_features", "lstm_layers"):
        _int_at_least(f"network.{name}", getattr(network, name), 1)
    _require(
        network.actions in NETWORK_ACTIONS,
        f"network.actions={network.actions!r} is invalid: it must be 2 (move, rot), 4 (a "
        "parametrised action: kind, pointer, x, y) or 12 (the thesis's 12-value action of table "
        "4.1)",
    )
    _require(
        network.features % network.num_heads == 0,
        f"network.num_heads={network.num_heads} is invalid: it must divide "
        f"network.features={network.features}",
    )
    for name in ("use_attention", "use_lstm"):
        value = getattr(network, name)
        _require(
            isinstance(value, bool),
            f"network.{name}={value!r} is invalid: it must be True or False",
        )
    _require(
        network.head in NETWORK_HEADS,
        f"network.head={network.head!r} is invalid: allowed values are {NETWORK_HEADS}",
    )
    if network.head == "parametrised":
        _require(
            _is_int(network.kinds) and network.kinds >= 1,
            f"network.kinds={network.kinds!r} is invalid with network.head='parametrised': it "
            "must be an int >= 1 (the number of discrete kinds)",
        )
        _require(
            network.actions == PARAMETRISED_ACTIONS,
            f"network.actions={network.actions!r} is invalid with network.head='parametrised': "
            f"its action is {PARAMETRISED_ACTIONS} values (kind, pointer, x, y); set "
            f"network.actions={PARAMETRISED_ACTIONS}",
        )
        _require(
            network.use_attention is True,
            f"network.use_attention={network.use_attention!r} is invalid with "
            "network.head='parametrised': its pointer attends over the attention encoder's "
            "per-entity embeddings",
        )
        _require(
            isinstance(network.last_kind_logit, (int, float))
            and not isinstance(network.last_kind_logit, bool)
            and math.isfinite(network.last_kind_logit),
            f"network.last_kind_logit={network.last_kind_logit!r} is invalid: it must be a "
            "finite number",
        )
        if network.kind_mask:
            from elevens.nets.policy import KIND_MASKS

            _require(
                network.kind_mask in KIND_MASKS,
                f"network.kind_mask={network.kind_mask!r} is invalid: allowed values are '' "
                f"(every kind) and the masks of the games known: {sorted(KIND_MASKS)}",
            )
    else:
        _require(
            network.kind_mask == "",
            f"network.kind_mask={network.kind_mask!r} is invalid with network.head='gaussian': "
            "it masks the parametrised head's kinds (leave it '')",
        )
        _require(
            network.kinds == 0,
            f"network.kinds={network.kinds!r} is invalid with network.head='gaussian': kinds "
            "belong to network.head='parametrised' (leave it 0)",
        )
        _require(
            network.last_kind_logit == 0,
            f"network.last_kind_logit={network.last_kind_logit!r} is invalid with "
            "network.head='gaussian': it shifts the parametrised head's last kind (leave it 0)",
        )


def _validate_ppo(learner: LearnerConfig) -> None:
    ppo = learner.ppo
    _require(
        isinstance(ppo, PPOHyperparams), f"ppo must be a PPOHyperparams, got {type(ppo).__name__}"
    )
    _check_ppo_extras(dataclasses.asdict(ppo))
    units, n = learner.batch_size, learner.players_per_team
    _require(
        units % ppo.minibatch_size == 0,
        f"ppo.minibatch_size={ppo.minibatch_size} is invalid: it must divide the batch of "
        f"{units} player sequences (games_per_iteration x players = "
        f"{learner.games_per_iteration} x {n})",
    )
    if ppo.minibatch_size % n != 0:
        fits = [m for m in range(n, units + 1, n) if units % m == 0]
        near = sorted(fits, key=lambda m: abs(m - ppo.minibatch_size))[:3]
        raise ValueError(
            f"ppo.minibatch_size={ppo.minibatch_size} is invalid for {n} players a side: "
            "minibatches hold whole games (the critic runs once per game), so it must be a "
            f"multiple of {n} that divides the batch of {units}, e.g. "
            f"{', '.join(str(m) for m in sorted(near))}"
        )


    if ppo.teacher:
        _require(
            ppo.teacher != SELF,
            f"ppo.teacher={ppo.teacher!r} is invalid: the teacher is a fixed team (a team spec, "
            "e.g. 'naive'), not self-play",
        )
        _check_team_actions("ppo.teacher", (ppo.teacher,), learner)


def _validate_opponent(opponent: OpponentConfig) -> None:
    _require(
        opponent.kind in OPPONENT_KINDS,
        f"opponent.kind={opponent.kind!r} is invalid: allowed values are "
        f"{', '.join(repr(k) for k in OPPONENT_KINDS)}",
    )
    _require(
        _is_number(opponent.polyak_tau) and 0.0 < opponent.polyak_tau <= 1.0,
        f"opponent.polyak_tau={opponent.polyak_tau!r} is invalid: it must be in (0, 1]",
    )
    _in_unit_interval("opponent.freeze_threshold", opponent.freeze_threshold)
    _int_at_least("opponent.league_capacity", opponent.league_capacity, 1)
    _int_at_least("opponent.league_every", opponent.league_every, 1)
    _require(
        _is_number(opponent.league_psi) and opponent.league_psi >= 0,
        f"opponent.league_psi={opponent.league_psi!r} is invalid: it must be a number >= 0",
    )
    _int_at_least("opponent.league_min_games", opponent.league_min_games, 0)
    _int_at_least("opponent.league_window", opponent.league_window, 1)
    _require(
        isinstance(opponent.mix, tuple), f"opponent.mix={opponent.mix!r} must be a tuple"
    )
    _require(
        isinstance(opponent.mix_games, tuple),
        f"opponent.mix_games={opponent.mix_games!r} must be a tuple",
    )


def _validate_opponent_mix(learner: LearnerConfig) -> None:
    mix = learner.opponent.mix
    mix_games = learner.opponent.mix_games
    sizes = (learner.env.scenario, *learner.env.mix)
    for game in mix_games:
        _require(
            game in sizes,
            f"opponent.mix_games entry {game!r} is invalid (allowed: the run's games "
            f"{', '.join(sizes)})",
        )
    _require(
        bool(mix) or not mix_games,
        f"opponent.mix_games={mix_games!r} is invalid without opponent.mix: it says which "
        "games play the fixed teams",
    )
    if not mix:
        return
    form = (
        "give TEAM=SHARE entries (TEAM a team spec or 'self', SHARE in [0, 1]), e.g. "
        "'self=0.8 naive=0.1 runs/x=0.1'"
    )
    entries = []
    for entry in mix:
        try:
            spec, value = _mix_entry(entry)
        except (AttributeError, ValueError):  # not a string, or no number after the last '='
            spec, value = "", math.nan
        _require(
            bool(spec) and math.isfinite(value) and 0 <= value <= 1,
            f"opponent.mix entry {entry!r} is invalid: {form}",
        )
        entries.append((spec, value))
    specs = [spec for spec, _ in entries]
    _require(
        len(set(specs)) == len(specs), f"opponent.mix={mix!r} is invalid: a team appears twice"
    )
    total = sum(value for _, value in entries)
    explicit_self = SELF in specs
    _require(
        math.isclose(total, 1.0, abs_tol=1e-9) if explicit_self else total < 1 + 1e-9,
        f"opponent.mix={mix!r} is invalid: the shares sum to {total:g}; with 'self=...' they "
        "must sum to 1, without it to at most 1 (self-play plays the rest)",
    )
    games = learner.games_per_iteration
    for spec, value in entries:
        count = round(value * games)
        _require(
            spec == SELF or count >= 1,
            f"opponent.mix entry {spec}={value:g} is invalid with games_per_iteration="
            f"{games}: it gives {value * games:g} games, round to at least 1",
        )
    self_games = self_play_games(learner)
    _require(
        self_games >= 0,
        f"opponent.mix={mix!r} is invalid with games_per_iteration={games}: the rounded "
        "games of the fixed teams exceed the games of an iteration",
    )
    _require(
        self_games > 0 or learner.opponent.kind != "league",
        "opponent.mix without self-play is invalid with opponent.kind='league': the league "
        "learns from its own games",
    )
    _check_team_actions("opponent.mix", tuple(specs), learner)


def _validate_run(run: RunConfig) -> None:
    _int_at_least("run.iterations", run.iterations, 1)
    _require(
        _is_number(run.max_minutes) and math.isfinite(run.max_minutes) and run.max_minutes >= 0,
        f"run.max_minutes={run.max_minutes!r} is invalid: it must be a finite number of "
        "minutes >= 0 (0: no time budget)",
    )
    _int_at_least("run.eval_every", run.eval_every, 0)
    _int_at_least("run.eval_games", run.eval_games, 1)
    _int_at_least("run.checkpoint_every", run.checkpoint_every, 0)
    _int_at_least("run.keep_checkpoints", run.keep_checkpoints, 1)
    _require(_is_int(run.seed), f"run.seed={run.seed!r} is invalid: it must be an integer")
    _int_at_least("run.devices", run.devices, 0)
    _require(
        isinstance(run.init_from, str),
        f"run.init_from={run.init_from!r} is invalid: it must be a checkpoint path or ''",
    )
    malformed = [
        team for team in run.eval_teams
        if not isinstance(team, str) or not team or team != team.strip()
    ] if isinstance(run.eval_teams, tuple) else [run.eval_teams]
    _require(
        not malformed and len(set(run.eval_teams)) == len(run.eval_teams),
        f"run.eval_teams={run.eval_teams!r} is invalid: give distinct team specs ("
        f"{', '.join(EVAL_TEAMS)}, a shipped team, a run or checkpoint PATH[@ITERATION])",
    )
    _require(
        isinstance(run.run_dir, str) and run.run_dir != "",
        f"run.run_dir={run.run_dir!r} is invalid: it must be a non-empty path",
    )


# --------------------------------------------------------------------------------------------
# JSON
# --------------------------------------------------------------------------------------------


def _from_dict(
    cls: type, data: Mapping[str, Any], where: str, filled: list[str] | None = None
) -> Any:
    """``filled`` None: missing keys are an error; a list: missing fields that have defaults
    are left to them, and their paths appended to it."""
    if not isinstance(data, Mapping):
        raise ValueError(f"config{where}: expected an object, got {type(data).__name__}")
    if isinstance(cls, type) and issubclass(cls, EnvConfig):
        game, data = _game_class(data, where)
        cls = game
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(typing.cast(Any, cls))}
    names = list(fields)
    unknown = sorted(set(data) - set(names))
    missing = [name for name in names if name not in data]
    if filled is not None:
        missing = [name for name in missing if not _has_default(fields[name])]
    if unknown or missing:
        raise ValueError(
            f"config{where or ' (top level)'}: unknown keys {unknown or 'none'}, missing keys "
            f"{missing or 'none'}; expected keys {', '.join(names)}"
            + (" (unknown keys: was it saved by a newer version of elevens?)" if unknown else "")
        )
    values = {}
    for name in names:
        if name not in data:
            assert filled is not None
            filled.append(f"{where}.{name}".lstrip("."))
            continue
        hint, value = hints[name], data[name]
        if dataclasses.is_dataclass(hint):
            values[name] = _from_dict(
                typing.cast(type, hint), value, f"{where}.{name}", filled
            )
        elif typing.get_origin(hint) is tuple and isinstance(value, list):
            values[name] = tuple(value)
        elif hint is float and _is_int(value):
            values[name] = float(value)
        else:
            values[name] = value
    return cls(**values)


def _game_class(data: Mapping[str, Any], where: str) -> tuple[type[EnvConfig], Mapping[str, Any]]:
    """The registered EnvConfig class of a saved env group (by its ``physics``), and the group
    without the fields version 2 kept for other games."""
    physics = data.get("physics", EnvConfig.PHYSICS)
    if physics not in GAMES:
        raise ValueError(
            f"config{where}.physics={physics!r} names a game this process does not know: "
            f"known are {', '.join(sorted(GAMES))} (a game's package registers it on import)"
        )
    cls = GAMES[physics]
    own = {f.name for f in dataclasses.fields(cls)}
    data = {
        key: value for key, value in data.items()
        if key in own or _OTHER_GAMES_FIELDS.get(key, object()) != value
    }
    return cls, data


def _has_default(field: dataclasses.Field[Any]) -> bool:
    return (
        field.default is not dataclasses.MISSING
        or field.default_factory is not dataclasses.MISSING
    )


def load_config(path: str | Path) -> TrainConfig:
    """A TrainConfig from a JSON file (e.g. a checkpoint's ``config.json``), which may be from
    an older version (see ``TrainConfig.from_dict``'s ``fill_missing``)."""
    return TrainConfig.from_saved(json.loads(Path(path).read_text(encoding="utf-8")), str(path))


RESUMABLE_FIELDS: tuple[str, ...] = (
    "preset",
    "run.iterations",
    "run.max_minutes",
    "run.init_from",
    "learner.iterations_per_chunk",
    "run.eval_every",
    "run.eval_games",
    "run.eval_teams",
    "run.eval_deterministic",
    "run.checkpoint_every",
    "run.keep_checkpoints",
    "run.run_dir",
    "run.write_plot",
    "run.write_gif",
)
"""Fields (paths) a resumed run may change: they steer the host loop, or, like K, do not change
what is computed. Everything else must equal the checkpoint's config (a run cannot silently
continue as another run); seed and devices too."""


def config_differences(saved: TrainConfig, current: TrainConfig) -> list[str]:
    """'name: saved -> current' for every differing field outside ``RESUMABLE_FIELDS``, named
    as its flag is (``short_path``)."""
    differences = []

    def walk(a: Any, b: Any, path: str) -> None:
        if dataclasses.is_dataclass(a) and dataclasses.is_dataclass(b):
            for field in dataclasses.fields(a):
                name = f"{path}.{field.name}" if path else field.name
                walk(getattr(a, field.name), getattr(b, field.name), name)
        elif a != b and path not in RESUMABLE_FIELDS:
            differences.append(f"{short_path(path)}: {a!r} -> {b!r}")

    walk(saved, current, "")
    return differences
