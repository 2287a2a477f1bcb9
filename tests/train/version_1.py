"""A config as elevens wrote it before config_version 2 (LearnerConfig/RunConfig), to test that
old checkpoints and teams still load."""

from __future__ import annotations

import dataclasses
import json
from typing import Any

from elevens.train.config import TrainConfig


def as_version_1(config: TrainConfig) -> dict[str, Any]:
    """``config`` as the version before LearnerConfig/RunConfig wrote it."""
    learner, game = config.learner, config.learner.env.game
    env = {
        "scenario": learner.env.scenario,
        **{name: getattr(game, name) for name in (
            "spawn", "ball_spawn", "episode_length", "field_length", "field_width",
            "goal_width", "ball_shaping_weight", "approach_shaping_weight")},
        **{name: getattr(learner.env, name) for name in (
            "shaping_schedule", "shaping_window", "shaping_threshold")},
        "mix": list(learner.env.mix), "mix_shares": list(learner.env.mix_shares),
    }
    run = json.loads(json.dumps(dataclasses.asdict(config.run)))
    run.update(games_per_iteration=learner.games_per_iteration,
               iterations_per_chunk=learner.iterations_per_chunk)
    return {
        "preset": config.preset, "env": env,
        "network": dataclasses.asdict(learner.network),
        "ppo": {**dataclasses.asdict(learner.ppo), "batch_size": learner.batch_size},
        "opponent": json.loads(json.dumps(dataclasses.asdict(learner.opponent))),
        "run": run,
    }
