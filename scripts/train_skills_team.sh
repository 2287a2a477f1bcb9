#!/usr/bin/env bash
# The recipe of a learned skills team (issue 36, item 1): self-play in the simulator's skill game
# (rcssserver's bodies; each player picks a skill, a pointer and a target, as the skills runtime
# plays the server), with skills_naive as a fixed opponent beside Polyak self-play. Two stages:
# 2 v 2 from scratch, then 11 v 11 with skills_naive as a teacher at first. The budget is
# iterations, so a run on a busy machine gets the same compute. Each stage is its own run
# directory and resumes with --resume: re-running the script goes on where it stopped.
# One core (taskset -c CORE), niced. The exported team plays the server unchanged:
#   elevens robocup match --team0 RUNS/export/elevens-skills ...
#
# Usage: scripts/train_skills_team.sh RUNS_DIR [CORE]
set -euo pipefail
runs=${1:?usage: scripts/train_skills_team.sh RUNS_DIR [CORE]}
core=${2:-0}
elevens=${ELEVENS:-elevens}
mkdir -p "$runs"

resume_flag() { [ -d "$1/checkpoints" ] && echo --resume || true; }
run() { nice -n 10 taskset -c "$core" "$elevens" train "$@"; }

# Stage 1: 2 v 2, a quarter of the games against skills_naive.
run skills-2v2 $(resume_flag "$runs/stage1") --no-progress --run.iterations 1000 \
  --run.max-minutes 0 --run.run-dir "$runs/stage1" --opponent.mix skills_naive=0.25 \
  --run.eval-every 25 --run.eval-games 50 --run.eval-teams skills_naive skills_random

# Stage 2: 11 v 11 from stage 1, with skills_naive as a teacher: the loss pulls the policy
# towards skills_naive's decisions on the learner's own states, every kind weighed alike
# (--ppo.teacher-balance: GO_TO is 85% of them), the weight falling from 1 to 0 over the first
# 200 iterations, after which PPO alone goes on (docs/results/robocup_learned.md).
run skills-11v11 $(resume_flag "$runs/stage2") --no-progress \
  --run.init-from "$runs/stage1" --run.iterations 300 --run.max-minutes 0 \
  --run.run-dir "$runs/stage2" --games-per-iteration 16 --ppo.minibatch-size 44 \
  --opponent.mix skills_naive=0.25 \
  --ppo.teacher skills_naive --ppo.teacher-weight 1 --ppo.teacher-iterations 200 \
  --ppo.teacher-balance \
  --run.eval-every 20 --run.eval-games 50 --run.eval-teams skills_naive skills_random

"$elevens" export-team "$runs/stage2" --out "$runs/export/elevens-skills"
