#!/usr/bin/env bash
# The recipe of the robust 22-player team (issue 37; docs/results/robustness.md): the shipped
# elevens-11v11's two stages and budget, with two changes against overfitting its own population.
# The budget is the shipped team's iterations (670 of 2 v 2, then 331 of 11 v 11 mixed half and
# half with 2 v 2: its 80 + 100 minutes on one core), not wall minutes, so that a run sharing a
# busy machine gets the same compute; the process's CPU time says how much of a core it had.
# The changes:
#   - every game draws its physics and geometry from the default ranges (--env.randomize.enabled);
#   - beside Polyak self-play, fixed opponents take part of each iteration's games: each of the
#     seven panel teams 5% and the shipped elevens-11v11 6.25% (at 11 v 11, 16 games: one game
#     each, 8 of self-play; at 2 v 2, 88 games: 4 each, 6 of elevens-11v11, 54 of self-play).
# Each stage is its own run directory and resumes with --resume, so re-running the script after
# an interruption goes on where it stopped.
# One core (taskset -c CORE), niced, like the shipped team's recipe.
#
# Usage: scripts/train_robust_team.sh RUNS_DIR [CORE]
set -euo pipefail
runs=${1:?usage: scripts/train_robust_team.sh RUNS_DIR [CORE]}
core=${2:-1}
elevens=${ELEVENS:-elevens}
mkdir -p "$runs"

resume_flag() { [ -d "$1/checkpoints" ] && echo --resume || true; }
mix=(--opponent.mix man-marking=0.05 high-press=0.05 deep-block=0.05 long-ball=0.05
     wing-play=0.05 counter=0.05 possession=0.05 elevens-11v11=0.0625)
run() { nice -n 10 taskset -c "$core" "$elevens" train "$@"; }

# Stage 1: 2 v 2, 670 iterations.
run 2v2 $(resume_flag "$runs/stage1") --no-progress --run.iterations 670 --run.max-minutes 0 \
  --run.run-dir "$runs/stage1" --env.randomize.enabled "${mix[@]}" \
  --run.eval-teams naive counter

# Stage 2: 11 v 11 mixed with 2 v 2, 331 iterations from stage 1 (the shipped team's stage 2).
run 11v11 $(resume_flag "$runs/stage2") --no-progress \
  --run.init-from "$runs/stage1" --run.iterations 331 \
  --run.run-dir "$runs/stage2" --env.mix 2v2 --env.mix-shares 0.5 \
  --games-per-iteration 16 \
  --ppo.minibatch-size 44 --ppo.learning-rate 3e-4 --ppo.gamma 0.99 \
  --ppo.advantage-estimator gae --ppo.normalize-advantages --ppo.entropy-weight 1e-3 \
  --opponent.polyak-tau 0.05 --env.no-shaping-schedule --env.approach-shaping-weight 0 \
  --env.randomize.enabled "${mix[@]}" \
  --run.eval-every 20 --run.eval-games 50 --run.eval-teams naive teamwork counter

"$elevens" export-team "$runs/stage2" --out "$runs/export/elevens-robust"
