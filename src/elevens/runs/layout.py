"""The run directory, in one place: what a training run writes and where.

::

    RUN_DIR/
      config.json              the run's TrainConfig (rewritten at every start)
      checkpoints/<iteration>/ Orbax checkpoints (train state, config, metadata), atomic
      damaged_checkpoints/     damaged checkpoints a resume set aside (never deleted)
      metrics.csv              every logged metric, long format (elevens.runs.logging)
      events.log               what happened when (resume, shaping off, time budget, Ctrl-C)
      events.out.tfevents.*    TensorBoard
      learning_curve.png       evaluation outcome against each team, by env steps and hours
      learner_vs_naive.gif     one game of the final learner
      episodes.csv             runs whose games are played outside the simulator: one row a game
      lock                     the process id of the run that holds the directory (flock)

A run of a wing above the core may write files of its own beside these (its whole config).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

CHECKPOINT_DIR = "checkpoints"
DAMAGED_DIR = "damaged_checkpoints"
CONFIG_JSON = "config.json"
METRICS_CSV = "metrics.csv"
LEARNING_CURVE = "learning_curve.png"
GIF_NAME = "learner_vs_naive.gif"
EPISODES_CSV = "episodes.csv"
LOCK_FILE = "lock"


@dataclasses.dataclass(frozen=True)
class RunLayout:
    """The paths of one run directory (nothing is created by building this)."""

    root: Path

    @classmethod
    def of(cls, run_dir: str | Path) -> RunLayout:
        return cls(Path(run_dir))

    @property
    def checkpoints(self) -> Path:
        return self.root / CHECKPOINT_DIR

    @property
    def damaged(self) -> Path:
        return self.root / DAMAGED_DIR

    @property
    def config(self) -> Path:
        return self.root / CONFIG_JSON

    @property
    def metrics_csv(self) -> Path:
        return self.root / METRICS_CSV

    @property
    def learning_curve(self) -> Path:
        return self.root / LEARNING_CURVE

    @property
    def gif(self) -> Path:
        return self.root / GIF_NAME

    @property
    def episodes_csv(self) -> Path:
        return self.root / EPISODES_CSV

    @property
    def lock(self) -> Path:
        return self.root / LOCK_FILE
