"""Team specs for the evaluation commands: a handcrafted team by name, or a trained checkpoint.

A spec is one command-line word:

* ``random``, ``naive``, ``teamwork``: the handcrafted teams (``elevens.eval.play.resolve_team``);
* ``PATH`` or ``PATH@ITERATION``: a checkpoint of a training run. ``PATH`` is a run directory
  (holding ``checkpoints/``), a checkpoint directory (holding the step directories) or one step
  directory (``runs/a/checkpoints/500``). Without ``@ITERATION`` the latest checkpoint is used.
* ``elevens-11v11``, ``elevens-2v2``: the trained teams shipped with the package
  (``elevens.teams.trained``; ``shipped_team_names()`` lists them);
* ``LABEL=SPEC``: any of the above, shown as ``LABEL`` in tables and plots
  (``22p=runs/11v11@5000``). LABEL may not contain ``/``, ``=`` or ``@``.

A trained policy's parameters do not depend on the team size (attention over a variable number of
entities, thesis 5.2.10), so a checkpoint trained in 2 v 2 plays 11 v 11 as it is. The exception
is the feedforward ablation (``network.use_attention = false``), whose first layer is sized for the
team it trained with; ``check_team_size`` refuses it at another size with a clear message.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import re
from pathlib import Path
from typing import Any, cast

import jax
import jax.numpy as jnp

from elevens.runs.layout import CHECKPOINT_DIR
from elevens.teams.base import Team, TeamPolicy
from elevens.teams.registry import HANDCRAFTED
from elevens.teams.trained import shipped_team_names


def handcrafted_names() -> tuple[str, ...]:
    """The handcrafted teams' names (teams.registry's, those games above the core add too)."""
    return tuple(HANDCRAFTED)


NETWORK_TEAM_NAME = "network"
"""The ``NetworkTeam.name`` of every loaded checkpoint. The team is a static argument of the
compiled match, so equal architectures with equal names share one compile across checkpoints
(their weights are arguments); the label shown in tables lives in ``Team.name`` instead."""

_LABEL = re.compile(r"^[^/=@\s]+$")


@dataclasses.dataclass(frozen=True)
class TeamSpec:
    """A parsed team spec (see the module docstring)."""

    text: str
    """The spec as given."""
    name: str
    """The label for tables and plots."""
    handcrafted: str | None = None
    """The handcrafted team's name, or None for a checkpoint."""
    shipped: str | None = None
    """The shipped trained team's name, or None."""
    path: Path | None = None
    """The checkpoint path as given (run, checkpoint or step directory), or None."""
    iteration: int | None = None
    """The checkpoint's iteration; None: the latest (or the step directory's own)."""


def _allowed_names() -> str:
    return ", ".join((*handcrafted_names(), *shipped_team_names()))


def parse_team_spec(text: str) -> TeamSpec:
    """Parse one spec word. Raises ``ValueError`` for an empty word, a bad label or iteration;
    the path is not checked here (``load_team`` does that)."""
    original = text
    text = text.strip()
    if not text:
        raise ValueError(f"team spec is empty: use {_allowed_names()} or a checkpoint path")
    label: str | None = None
    head, sep, tail = text.partition("=")
    if sep and "/" not in head and os.sep not in head:
        if not _LABEL.match(head):
            raise ValueError(
                f"team spec {original!r}: label {head!r} is invalid (no spaces, '/', '=' or '@')"
            )
        label, text = head, tail.strip()
        if not text:
            raise ValueError(f"team spec {original!r}: nothing after the label {label!r}")
    if text in handcrafted_names():
        return TeamSpec(text=original, name=label or text, handcrafted=text)
    if text in shipped_team_names():
        return TeamSpec(text=original, name=label or text, shipped=text)
    path_text, iteration = text, None
    before, at, after = text.rpartition("@")
    if at:
        if not re.fullmatch(r"\d+", after):
            raise ValueError(
                f"team spec {original!r}: the iteration after '@' must be a whole number >= 0, "
                f"got {after!r}"
            )
        path_text, iteration = before, int(after)
    if not path_text:
        raise ValueError(f"team spec {original!r} has no checkpoint path before '@'")
    path = Path(path_text)
    if label is None:
        base = path.parent.name if path.name in (CHECKPOINT_DIR, "") else path.name
        label = base or path_text
        if iteration is not None:
            label = f"{label}@{iteration}"
    return TeamSpec(text=original, name=label, path=path, iteration=iteration)


def _checkpoint_directory(path: Path) -> tuple[Path, int | None]:
    """(directory holding step directories, the step the path names or None)."""
    if not path.exists():
        raise FileNotFoundError(
            f"team spec: {path} does not exist (expected a run directory, its checkpoints/ "
            f"directory or a step directory; or one of {_allowed_names()})"
        )
    if (path / CHECKPOINT_DIR).is_dir():
        return path / CHECKPOINT_DIR, None
    if path.name.isdigit() and (path / "state").is_dir():
        return path.parent, int(path.name)
    return path, None


def _policy_target(policy: Any, config: Any) -> Any:
    """Abstract ``{"params": ...}`` of ``policy`` in ``config``'s game (shapes only: nothing is
    computed)."""
    players_per_team = config.learner.players_per_team
    env = config.learner.make_env()
    _, obs = jax.eval_shape(env.reset, jax.random.key(0), env.default_params())
    team_obs = jax.tree.map(lambda leaf: jax.ShapeDtypeStruct(leaf.shape[1:], leaf.dtype), obs)
    return jax.eval_shape(
        policy.init,
        jax.random.key(0),
        policy.initial_carry((players_per_team,)),
        team_obs,
        jnp.zeros((players_per_team,), bool),
    )


def load_checkpoint_team(
    path: str | os.PathLike[str],
    iteration: int | None = None,
    *,
    deterministic: bool | None = None,
) -> tuple[TeamPolicy, Any]:
    """A trained checkpoint as ``(NetworkTeam, policy params)``, ready for ``play_match``.

    path: a run directory (with ``checkpoints/``), a checkpoint directory, or a step directory.
    iteration: the checkpoint's step; None takes the step directory's own or the latest.
    deterministic: play ``tanh(mean)`` (True) or sample (False); None takes the run's
    ``run.eval_deterministic`` (default False: sampling, as in training and the thesis).

    What the loader expects (``elevens.train.learner`` / ``checkpoint`` as of this writing):

    * the step's ``config.json`` (``checkpoint.load_config``) is a ``TrainConfig.to_dict()``
      (config_version 2, or an older one that ``TrainConfig.from_saved`` maps); its
      ``learner.network`` builds the policy (``NetworkConfig.policy()``) and
      ``learner.env.game.players_per_team`` is the team size it trained with;
    * the saved state is either the trainer's ``TrainState`` (restored against
      ``train_state_shape(config.learner, ...)``; the policy is ``state.params.policy``),
      or the policy's own variables ``{"params": ...}`` as ``AttentionPolicy.init`` returns them.

    Raises FileNotFoundError (no such path or no checkpoint), ``CheckpointError`` (corrupt, or a
    state of neither layout), ValueError (a config that is not a TrainConfig of this version).
    """
    team, params, _ = _load_checkpoint(Path(path), iteration, deterministic)
    return team, params


def _open_checkpoint(path: Path, iteration: int | None) -> tuple[Any, int, Any]:
    """(open Checkpointer, step, TrainConfig) of the checkpoint ``path`` names (a run,
    checkpoints or step directory; ``iteration`` None: the path's own step or the latest).
    The caller closes the Checkpointer. Clear errors for a missing step or a foreign config."""
    from elevens.train.checkpoint import Checkpointer, load_config
    from elevens.train.config import TrainConfig

    directory, path_step = _checkpoint_directory(path)
    if iteration is not None and path_step is not None and iteration != path_step:
        raise ValueError(
            f"{path} is the checkpoint of iteration {path_step}, but iteration {iteration} was "
            "asked for"
        )
    step = iteration if iteration is not None else path_step
    checkpointer = Checkpointer(directory, max_to_keep=None)
    try:
        if step is None:
            step = checkpointer.latest_step()
            if step is None:
                raise FileNotFoundError(f"no checkpoint in {directory}")
        elif step not in checkpointer.all_steps():
            raise FileNotFoundError(
                f"no checkpoint of iteration {step} in {directory}; saved iterations: "
                f"{checkpointer.all_steps() or 'none'}"
            )
        config = TrainConfig.from_saved(
            load_config(directory, step), f"the config.json of checkpoint {directory / str(step)}"
        )
    except BaseException:
        checkpointer.close()
        raise
    return checkpointer, step, config


def train_state_shape(config: Any) -> Any:
    """The abstract TrainState ``config`` builds (shapes only: nothing is computed). Shapes do
    not depend on the devices a run used, so one device serves any checkpoint."""
    from elevens.train.learner import train_state_shape

    return train_state_shape(config.learner, config.learner.make_env(), devices=1)


def _restore_train_state(checkpointer: Any, step: int, config: Any) -> Any:
    """The TrainState saved at ``step``, restored into the shapes ``config`` builds."""
    state, _, _ = checkpointer.restore(train_state_shape(config), step)
    return state


def _intact_train_state_step(checkpointer: Any, before: int, config: Any) -> int | None:
    """The newest step before ``before`` whose TrainState restores, or None."""
    return cast(int | None, checkpointer.last_intact_step(train_state_shape(config), before))


def _network_team(config: Any, deterministic: bool | None) -> TeamPolicy:
    """The NetworkTeam of ``config``'s policy; ``deterministic`` None takes the run's
    ``run.eval_deterministic``."""
    from elevens.teams.network import NetworkTeam

    if deterministic is None:
        deterministic = bool(config.run.eval_deterministic)
    return NetworkTeam(
        policy=config.learner.network.policy(), deterministic=deterministic,
        name=NETWORK_TEAM_NAME, self_features=config.learner.env.self_features,
    )


def load_train_state(path: Path, iteration: int | None = None) -> tuple[Any, Any]:
    """(TrainConfig, TrainState) of a training checkpoint (see ``_open_checkpoint``)."""
    checkpointer, step, config = _open_checkpoint(path, iteration)
    try:
        return config, _restore_train_state(checkpointer, step, config)
    finally:
        checkpointer.close()


def _load_checkpoint(
    path: Path, iteration: int | None, deterministic: bool | None
) -> tuple[TeamPolicy, Any, Any]:
    """(NetworkTeam, policy params, TrainConfig) of a checkpoint; see load_checkpoint_team."""
    from elevens.train.checkpoint import CheckpointError

    checkpointer, step, config = _open_checkpoint(path, iteration)
    try:
        policy = config.learner.network.policy()
        errors = []
        policy_params = None
        try:
            policy_params = _restore_train_state(checkpointer, step, config).params.policy
        except CheckpointError as error:
            errors.append(f"as a TrainState: {error}")
        if policy_params is None:
            try:
                policy_params, _, _ = checkpointer.restore(_policy_target(policy, config), step)
            except CheckpointError as error:
                errors.append(f"as policy variables: {error}")
        if policy_params is None:
            hint = ""
            if iteration is None:
                good = _intact_train_state_step(checkpointer, step, config)
                if good is not None:
                    hint = f"; checkpoint {good} is intact: use {path}@{good}"
            raise CheckpointError(
                f"checkpoint {checkpointer.step_directory(step)} holds neither a TrainState "
                "nor policy variables {'params': ...}: " + "; ".join(errors) + hint
            )
    finally:
        checkpointer.close()
    return _network_team(config, deterministic), policy_params, config


def load_team(spec: str | TeamSpec, *, deterministic: bool | None = None) -> Team:
    """A ``Team`` from a spec word (or a parsed ``TeamSpec``); see the module docstring."""
    from elevens.teams.registry import action_size, resolve_team

    parsed = parse_team_spec(spec) if isinstance(spec, str) else spec
    if parsed.handcrafted is not None:
        policy = resolve_team(parsed.handcrafted)
        return Team(
            name=parsed.name, policy=policy, spec=parsed.text, actions=action_size(policy)
        )
    folder = load_team_folder(parsed)
    if folder is not None:
        config, networks = folder
        policy, params = _network_team(config, deterministic), networks.policy
    else:
        assert parsed.path is not None
        policy, params, config = _load_checkpoint(parsed.path, parsed.iteration, deterministic)
    game = config.learner.env.game
    return Team(
        name=parsed.name,
        policy=policy,
        params=params,
        trained_players=config.learner.players_per_team,
        size_dependent=not config.learner.network.use_attention,
        spec=parsed.text,
        field=(game.field_length, game.field_width, game.goal_width),
        actions=config.learner.network.actions,
    )


def trained_config(spec: str | TeamSpec) -> Any | None:
    """The TrainConfig of a trained team spec (a shipped name, an exported folder or a
    checkpoint), read without its networks: what it plays is known before the weights load.
    None for a handcrafted team; a bad spec raises as ``load_team`` does."""
    import json

    from elevens.teams.trained import CONFIG_FILE
    from elevens.train.config import TrainConfig

    parsed = parse_team_spec(spec) if isinstance(spec, str) else spec
    if parsed.handcrafted is not None:
        return None
    folder = team_folder(parsed)
    if folder is not None:
        where = folder / CONFIG_FILE
        return TrainConfig.from_saved(json.loads(where.read_text()), str(where))
    assert parsed.path is not None
    checkpointer, _, config = _open_checkpoint(parsed.path, parsed.iteration)
    checkpointer.close()
    return config


def is_exported_team(path: Path) -> bool:
    """True for a folder written by ``export_team`` (or a shipped team's)."""
    from elevens.teams.trained import NETWORKS_FILE

    return (path / NETWORKS_FILE).is_file()


def team_folder(spec: TeamSpec) -> Path | None:
    """The folder of a shipped team or an exported one that ``spec`` names, else None (a
    handcrafted team or a training checkpoint); an exported team with ``@ITERATION`` is a
    ValueError, and an unknown shipped name one listing the shipped teams."""
    from elevens.teams.trained import shipped_team_directory

    if spec.shipped is not None:
        return shipped_team_directory(spec.shipped)
    if spec.path is None or not is_exported_team(spec.path):
        return None
    if spec.iteration is not None:
        raise ValueError(
            f"team spec {spec.text!r}: an exported team has one set of networks, drop the "
            "'@ITERATION'"
        )
    return spec.path


def load_team_folder(spec: TeamSpec) -> tuple[Any, Any] | None:
    """(TrainConfig, LearnerParams) when ``spec`` names a shipped team or an exported folder,
    else None (a handcrafted team or a training checkpoint)."""
    folder = team_folder(spec)
    return None if folder is None else load_exported_team(folder)


def load_exported_team(directory: Path) -> tuple[Any, Any]:
    """(TrainConfig, LearnerParams) of a folder written by ``export_team``, checked against the
    networks its config builds; damaged files are a ``ShippedTeamError`` naming the file."""
    from elevens.teams.trained import CONFIG_FILE, ShippedTeamError, check_like, load_networks
    from elevens.train.config import TrainConfig
    from elevens.train.learner import LearnerParams

    raw_config, networks = load_networks(directory)
    try:
        config = TrainConfig.from_saved(raw_config, str(directory / CONFIG_FILE)).validate()
    except ValueError as error:
        raise ShippedTeamError(str(error)) from None
    target = train_state_shape(config).params
    check_like(networks, {"policy": target.policy, "critic": target.critic}, str(directory))
    return config, LearnerParams(
        policy=jax.tree.map(jnp.asarray, networks["policy"]),
        critic=jax.tree.map(jnp.asarray, networks["critic"]),
    )


def load_learner_params(text: str) -> tuple[Any, Any]:
    """(config, LearnerParams) of a shipped team (``elevens-11v11``) or a training checkpoint:
    a run, checkpoints or step directory, optionally ``PATH@ITERATION``."""
    from elevens.runs.errors import RunRefusedError
    from elevens.train.config import TrainConfig
    from elevens.train.learner import LearnerParams

    spec = parse_team_spec(text)
    folder = load_team_folder(spec)
    if folder is not None:
        return cast(tuple[TrainConfig, LearnerParams], folder)
    if spec.path is None:
        raise RunRefusedError(
            f"{text!r} is a handcrafted team, not a checkpoint: a run starts only from a "
            "training checkpoint (a run, checkpoints or step directory, or PATH@ITERATION)"
        )
    config, state = load_train_state(spec.path, spec.iteration)
    return config, state.params


def export_team(
    spec: str, directory: str | Path, card: str | None = None
) -> tuple[Path, Any]:
    """Write the networks and config of ``spec`` (a checkpoint ``PATH[@ITERATION]``, an
    exported folder or a shipped name) as a compact team folder (``networks.npz``,
    ``config.json`` and, when given, ``MODEL_CARD.md``): what the package ships, and what
    ``load_team`` and ``--run.init-from`` read. Returns (the folder, its TrainConfig)."""
    from elevens.teams.trained import save_networks

    config, params = load_learner_params(spec)
    networks = {"policy": params.policy, "critic": params.critic}
    folder = save_networks(directory, jax.device_get(networks), config.to_dict(), card)
    return folder, config


FIELD_NAMES = ("field_length", "field_width", "goal_width")


def common_field(teams: list[Team]) -> dict[str, float]:
    """The EnvParams overrides of the field the checkpoints among ``teams`` trained on ({} when
    none is a checkpoint). Raises ``ValueError`` naming the teams if they trained on different
    fields: a match between them would put one of them on a field it never saw."""
    fields = {team.field for team in teams if team.field is not None}
    if len(fields) > 1:
        listed = "; ".join(f"{team.name}: {team.field}" for team in teams if team.field)
        raise ValueError(
            "the checkpoints trained on different fields (length, width, goal): "
            f"{listed}; compare checkpoints of one field"
        )
    if not fields:
        return {}
    (field,) = fields
    return dict(zip(FIELD_NAMES, field, strict=True))


def fit_to_field(team: Team, params: Any) -> Team:
    """A handcrafted team told the field of ``params`` (checkpoints are returned as they are)."""
    from elevens.teams.registry import resolve_team

    if team.field is not None or team.params is not None:
        return team
    name = parse_team_spec(team.spec).handcrafted if team.spec else None
    if name is None:
        return team
    return dataclasses.replace(team, policy=resolve_team(name, params))


def team_on_field(spec: str, env_params: Any, field: str) -> Team:
    """The ``Team`` of a team spec, a handcrafted one told the field of ``env_params``; a spec
    that does not load is a ValueError naming ``field`` (the config field that gave it)."""
    return fit_to_field(_loaded_team(spec, field), env_params)


@functools.lru_cache(maxsize=8)
def _loaded_team(spec: str, field: str) -> Team:
    """``load_team(spec)``, once per process: evaluations repeat every few iterations."""
    try:
        return load_team(spec)
    except (ValueError, FileNotFoundError) as error:
        raise ValueError(f"{field} team {spec!r}: {error}") from error


def check_team_size(team: Team, players_per_team: int, actions: int = 2) -> None:
    """Raise ``ValueError`` if ``team`` cannot play ``players_per_team`` a side in a game that
    takes ``actions`` action values."""
    team.check_size(players_per_team, actions)


def unique_names(teams: list[Team]) -> list[str]:
    """The teams' labels, with ``#2``, ``#3`` appended to repeats so table rows stay apart."""
    seen: dict[str, int] = {}
    names = []
    for team in teams:
        count = seen.get(team.name, 0) + 1
        seen[team.name] = count
        names.append(team.name if count == 1 else f"{team.name}#{count}")
    return names
