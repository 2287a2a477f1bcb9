#!/usr/bin/env bash
# The recipe of the shipped teams (docs/results/table_6_3.md): one budget B for both teams.
#   Stage 1           : the 2v2 preset for S minutes: the shipped elevens-2v2 (S = 80).
#   4-player team     : the same 2v2 run goes on to B minutes (the table's equal-budget team).
#   22-player team    : stage 1's networks, then B - S minutes of 11 v 11 mixed with 2 v 2 (half
#                       the iterations each, --env.mix 2v2 --env.mix-shares 0.5): the shipped
#                       elevens-11v11 (B = 180). The 2v2 preset's PPO numbers, but Adam 3e-4,
#                       GAE, 16 games an iteration in minibatches of 4 games (88 and 22 in the 2v2
#                       iterations: the same player sequences), and no approach shaping: at 11 v 11
#                       it paid each player about 15 an episode for running at the ball, against
#                       0.4 for the ball shaping and +-1 a goal, which makes a clump.
# Each stage is its own run directory and resumes with --resume, so re-running this script after
# an interruption continues where it stopped. The last two stages run side by side, one core each.
#
# Usage: scripts/train_shipped_teams.sh RUNS_DIR [B_MINUTES] [S_MINUTES]   (session 11: 180 80)
set -euo pipefail
runs=${1:?usage: scripts/train_shipped_teams.sh RUNS_DIR [B_MINUTES] [S_MINUTES]}
budget=${2:-180}
switch=${3:-80}
elevens=${ELEVENS:-elevens}
mkdir -p "$runs"

resume_flag() { [ -d "$1/checkpoints" ] && echo --resume || true; }

# Stage 1: 2 v 2 for S minutes (the shared start of both teams).
nice -n 10 taskset -c 1 "$elevens" train 2v2 $(resume_flag "$runs/2v2_start") --no-progress \
  --run.max-minutes "$switch" --run.run-dir "$runs/2v2_start"

# Stage 2a: the 4-player team goes on in 2 v 2 to B minutes (a copy, so the start stays).
if [ ! -d "$runs/4p" ]; then cp -r "$runs/2v2_start" "$runs/4p"; fi
nice -n 10 taskset -c 1 "$elevens" train 2v2 --resume --no-progress \
  --run.max-minutes "$budget" --run.run-dir "$runs/4p" &
four=$!

# Stage 2b: the 22-player team: 11 v 11 mixed with 2 v 2 for B - S minutes from stage 1.
nice -n 10 taskset -c 0 "$elevens" train 11v11 $(resume_flag "$runs/22p") --no-progress \
  --run.init-from "$runs/2v2_start" --run.max-minutes "$((budget - switch))" \
  --run.run-dir "$runs/22p" --env.mix 2v2 --env.mix-shares 0.5 \
  --games-per-iteration 16 \
  --ppo.minibatch-size 44 --ppo.learning-rate 3e-4 --ppo.gamma 0.99 \
  --ppo.advantage-estimator gae --ppo.normalize-advantages --ppo.entropy-weight 1e-3 \
  --opponent.polyak-tau 0.05 --env.no-shaping-schedule --env.approach-shaping-weight 0 \
  --run.eval-every 20 \
  --run.eval-games 50 --run.eval-teams naive teamwork
wait "$four"

"$elevens" export-team "$runs/2v2_start" --out "$runs/export/elevens-2v2"
"$elevens" export-team "$runs/4p" --out "$runs/export/4p-equal-budget"
"$elevens" export-team "$runs/22p" --out "$runs/export/elevens-11v11"
