#!/usr/bin/env bash
# The recipe of the robust 22-player team (issue 37; docs/results/robustness.md): the shipped
# elevens-11v11's two stages and budget (670 iterations of 2 v 2, then 331 of 11 v 11 mixed half
# and half with 2 v 2: its 80 + 100 minutes on one core), with fixed opponents beside Polyak
# self-play in stage 2: each of the seven panel teams 5% of the games and the shipped
# elevens-11v11 6.25% (at 11 v 11, 16 games: one game each, 8 of self-play; at 2 v 2, 88 games:
# 4 each, 6 of elevens-11v11, 54 of self-play).
# Stage 1 is the shipped elevens-2v2 itself (the same 670 iterations of the 2v2 preset that began
# elevens-11v11), so only stage 2 runs here. The budget is iterations, not wall minutes, so that a
# run sharing a busy machine gets the same compute; the process's CPU time says how much of a core
# it had. Try 1 (docs/results/robustness.md) also randomised every game of both stages
# (--env.randomize.enabled) and ended near 0.66 against naive; RANDOMIZE=1 randomises stage 2 as it did.
# MIX="team=share ..." replaces the fixed opponents' shares (try 3: counter=0.10 and
# elevens-11v11=0.25, the other panel teams 0.05 each). SEED=N sets --run.seed (default 0; try 5
# is try 2 with SEED=1, to see how far two seeds of one recipe differ). MIX_GAMES=11v11 plays the
# fixed opponents in the 11 v 11 iterations only, the 2 v 2 ones all self-play (try 6).
# The stage resumes with --resume, so re-running the script after an interruption goes on where
# it stopped. One core (taskset -c CORE), niced, like the shipped team's recipe.
#
# Usage: scripts/train_robust_team.sh RUNS_DIR [CORE]
set -euo pipefail
runs=${1:?usage: scripts/train_robust_team.sh RUNS_DIR [CORE]}
core=${2:-1}
elevens=${ELEVENS:-elevens}
mkdir -p "$runs"

resume_flag() { [ -d "$1/checkpoints" ] && echo --resume || true; }
shares=${MIX:-man-marking=0.05 high-press=0.05 deep-block=0.05 long-ball=0.05 wing-play=0.05
counter=0.05 possession=0.05 elevens-11v11=0.0625}
read -r -a mix <<< "--opponent.mix $(echo $shares)"
run() { nice -n 10 taskset -c "$core" "$elevens" train "$@"; }

randomize=()
mix_games=()
[ -n "${MIX_GAMES:-}" ] && mix_games=(--opponent.mix-games $MIX_GAMES)
[ "${RANDOMIZE:-0}" = 1 ] && randomize=(--env.randomize.enabled)

# Stage 2: 11 v 11 mixed with 2 v 2, 331 iterations from elevens-2v2 (the shipped team's stage 2).
run 11v11 $(resume_flag "$runs/stage2") --no-progress \
  --run.init-from elevens-2v2 --run.iterations 331 --run.max-minutes 0 \
  --run.run-dir "$runs/stage2" --env.mix 2v2 --env.mix-shares 0.5 \
  --games-per-iteration 16 \
  --ppo.minibatch-size 44 --ppo.learning-rate 3e-4 --ppo.gamma 0.99 \
  --ppo.advantage-estimator gae --ppo.normalize-advantages --ppo.entropy-weight 1e-3 \
  --opponent.polyak-tau 0.05 --env.no-shaping-schedule --env.approach-shaping-weight 0 \
  "${randomize[@]}" "${mix[@]}" "${mix_games[@]}" \
  --run.seed "${SEED:-0}" \
  --run.eval-every 20 --run.eval-games 50 --run.eval-teams naive teamwork counter

"$elevens" export-team "$runs/stage2" --out "$runs/export/elevens-robust"
