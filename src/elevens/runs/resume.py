"""Opening a run directory: refusing another run's checkpoints, resuming, falling back past
damaged checkpoints, and loading a run's (or a shipped team's) networks to start from.

Everything here reads config.json or the checkpoints' metadata before anything compiles, so a
refused run costs nothing and touches nothing saved.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from elevens.runs.errors import RunRefusedError
from elevens.runs.layout import DAMAGED_DIR
from elevens.runs.lock import lock_run_directory
from elevens.runs.teams import load_learner_params, train_state_shape
from elevens.train import parallel
from elevens.train.config import TrainConfig, config_differences
from elevens.train.learner import LearnerParams


def latest_resumable_step(
    checkpointer: Any, resume: bool, resume_flag: str, run_dir_flag: str
) -> int | None:
    """Take the run directory (the parent of ``checkpointer.directory``) for this run and
    return its latest checkpoint's step, or None for a new run.

    The directory is locked (``elevens.runs.lock``, by process 0 of a multi-process run) until
    ``checkpointer.close()``; a directory another process holds is a ``RunRefusedError`` naming
    that process. So is a directory with checkpoints without ``resume`` (a new run must not
    overwrite another's) and one without any with ``resume`` (a typo must not start a new run
    from zero). The messages name the command's own flags."""
    run_dir = Path(checkpointer.directory).parent
    no_run = (
        f"cannot resume: {run_dir} holds no run (no checkpoint in {checkpointer.directory}); "
        f"check {run_dir_flag}, or start a new run there without {resume_flag}"
    )
    if resume and not run_dir.is_dir():
        raise RunRefusedError(no_run)
    if parallel.is_lead():
        checkpointer.release_on_close(lock_run_directory(run_dir, run_dir_flag).release)
    latest = checkpointer.latest_step()
    if latest is not None and not resume:
        raise RunRefusedError(
            f"{checkpointer.directory} already holds checkpoints (latest: iteration {latest}); "
            f"pass {resume_flag} to continue that run, or choose another {run_dir_flag}"
        )
    if latest is None and resume:
        raise RunRefusedError(no_run)
    return latest


def resume_line(run_dir: Path, iteration: int, env_steps: int, train_seconds: float | None) -> str:
    """The line every resume prints: where the run continues from."""
    minutes = "" if train_seconds is None else f", {train_seconds / 60:.1f} min of training"
    return (
        f"resuming {run_dir} from iteration {iteration:,} ({env_steps:,} env steps{minutes})"
    )


def load_start_params(text: str, config: TrainConfig) -> tuple[TrainConfig, LearnerParams]:
    """``load_learner_params(text)``, refused (``RunRefusedError``, listing the fields) unless
    its networks are ``config``'s. The team size may differ: the networks read entity slots,
    so a 2 v 2 team starts an 11 v 11 run (and the other way round); so may the kind mask
    (``network.kind_mask``: no parameter of its own)."""
    source, params = load_learner_params(text)
    network = config.learner.network
    differences = [
        f"--network.{name.replace('_', '-')} {getattr(source.learner.network, name)!r} "
        f"(this run: {getattr(network, name)!r})"
        for name in (field.name for field in dataclasses.fields(network))
        if name != "kind_mask" and getattr(source.learner.network, name) != getattr(network, name)
    ]
    if differences:
        raise RunRefusedError(
            f"run.init_from={text!r} has other networks than this run; pass "
            + ", ".join(differences)
        )
    return source, _grown_inputs(params, train_state_shape(config).params, text)


def _grown_inputs(params: LearnerParams, target: Any, text: str) -> LearnerParams:
    """``params`` shaped as ``target`` (abstract LearnerParams of this run) where this run's
    game gives more input features at the end of an observation part (a skill game's
    ``env.reach_features``): a kernel whose input axis grew gains zero rows, so the networks
    compute what they computed and learn the new inputs' weights. Any other shape difference
    is a ``RunRefusedError`` naming the parameter."""
    import jax
    import jax.numpy as jnp

    def grown(path: Any, leaf: Any, want: Any) -> Any:
        have = tuple(leaf.shape)
        if have == tuple(want.shape):
            return leaf
        if len(have) == 2 and have[1] == want.shape[1] and have[0] < want.shape[0]:
            return jnp.concatenate([leaf, jnp.zeros((want.shape[0] - have[0], have[1]),
                                                    leaf.dtype)])
        raise RunRefusedError(
            f"run.init_from={text!r}: parameter {jax.tree_util.keystr(path)} has shape {have}, "
            f"this run's {tuple(want.shape)}: its game's observation differs other than by "
            "features added at the end"
        )

    return jax.tree_util.tree_map_with_path(grown, params, target)


def check_resumable(checkpointer: Any, config: TrainConfig, step: int | None = None) -> None:
    """Raise ``RunRefusedError`` unless the checkpoint's config (``step``, default the latest)
    matches ``config`` (outside ``RESUMABLE_FIELDS``), listing every difference. Reads only
    config.json, so it runs before anything compiles (every run
    calls it on a resume)."""
    try:
        saved = TrainConfig.from_saved(
            checkpointer.read_config(step), f"the config.json in {checkpointer.directory}"
        )
    except ValueError as error:
        raise RunRefusedError(f"cannot resume: {error}") from error
    differences = config_differences(saved, config)
    if differences:
        raise RunRefusedError(
            f"cannot resume from {checkpointer.directory}: the config differs from the "
            "checkpoint's in fields that change what is computed:\n  "
            + "\n  ".join(differences)
            + "\nuse the checkpoint's values, or another run directory"
        )


def last_good_step(
    checkpointer: Any, target: Any, latest: int, damage: Exception, use_it: bool,
    run_dir: Path,
) -> int:
    """The step a resume falls back to when checkpoint ``latest`` is damaged (``damage``):
    with ``use_it``, the newest intact one, after moving the damaged ones aside; otherwise a
    ``CheckpointError`` naming the damage and what is intact."""
    from elevens.train.checkpoint import CheckpointError

    good = checkpointer.last_intact_step(target, before=latest)
    if good is None:
        raise CheckpointError(f"{damage}; no earlier checkpoint is intact") from damage
    if not use_it:
        raise CheckpointError(
            f"{damage}; checkpoint {good} ({checkpointer.step_directory(good)}) is intact: "
            f"pass --resume-from-last-good to continue from it (the damaged ones move to "
            f"{run_dir / DAMAGED_DIR}, nothing is deleted)"
        ) from damage
    if parallel.is_lead():
        for step in checkpointer.all_steps():
            if step > good:
                checkpointer.set_aside(step, run_dir / DAMAGED_DIR)
    parallel.barrier("elevens: damaged checkpoints set aside")
    return int(good)
