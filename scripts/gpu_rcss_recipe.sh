#!/bin/bash
# 11 v 11 in the simulator with rcssserver's bodies (env.physics rcss) for a fixed number of
# minutes, sized for one GPU (issue 18; docs/results/robocup.md, session 19). Starts from INIT
# (a run, a checkpoint or an exported team with helios-ft12's networks), plays half of its
# games against rcss_naive (MIX=0 for self-play only, which also allows MIX2V2) and the rest
# against itself, with the server's see timing (SEE=3) or fresh observations (SEE=1), and the
# server's stamina and the elevens goalie routine (RULES=1; RULES=0 leaves both out), and a
# reward for having the ball (POSSESSION=w_p, EnvParams.possession_shaping_weight; 0: off),
# by the last touch (POSSESSION_BY=touch) or by nearness (near, the default).
# KIND=league plays past snapshots instead of the Polyak-averaged copy (opponent.kind).
# MIXED names the handcrafted team of the MIX share (rcss_naive; rcss_passer keeps the ball).
# APPROACH sets the approach shaping weight (each player paid for running at the ball; the
# game's default, 0.05, when unset; 0 stops paying the whole team to crowd the ball).
#   R=/tmp/gpuruns INIT=docs/results/robocup_teams/rcss-gpu MIN=8 bash scripts/gpu_rcss_recipe.sh
# With OUT set (the device tool's output folder), the run directory is packed into
# $OUT/rcss.tgz. Then, here: elevens robocup match --team0 $R/rcss --team1-cmd "$H ..."
set -eu
PY=${PY:-python3}
R=${R:-/tmp/gpuruns}
MIX=${MIX:-0.5}
rules=""
if [ "${RULES:-1}" = "1" ]; then rules="--env.stamina --env.goalie"; fi
if [ "$MIX" = "0" ]; then
  opponents="${MIX2V2:+--env.mix 2v2 --env.mix-shares $MIX2V2}"
else
  opponents="--opponent.mix ${MIXED:-rcss_naive}=$MIX"
fi
$PY -m elevens train 11v11 --env.physics rcss --network.actions 12 --network.features 64 \
  --network.num-heads 4 --network.lstm-features 32 --network.lstm-layers 2 \
  --env.field-length 105 --env.field-width 68 --env.goal-width 14.02 --env.ball-friction 0.94 \
  --env.ball-max-speed 3 --env.see-period "${SEE:-3}" $rules \
  --env.possession-shaping-weight "${POSSESSION:-0}" --env.possession-by "${POSSESSION_BY:-near}" \
  ${APPROACH:+--env.approach-shaping-weight $APPROACH} \
  --run.init-from "${INIT:-docs/results/robocup_teams/rcss-gpu}" $opponents \
  --games-per-iteration "${G:-128}" --ppo.minibatch-size "${MB:-352}" \
  --ppo.learning-rate 3e-4 --ppo.advantage-estimator gae --ppo.normalize-advantages \
  --ppo.entropy-weight 1e-3 --opponent.kind "${KIND:-polyak}" --opponent.polyak-tau 0.05 \
  --env.no-shaping-schedule \
  --iterations-per-chunk "${CHUNK:-5}" --run.checkpoint-every 20 --run.keep-checkpoints 6 \
  --run.iterations 1000000 --run.eval-teams --run.no-write-gif \
  --run.max-minutes "${MIN:-8}" --run.run-dir "$R/rcss"
# Only the newest checkpoint comes back: the device tool refuses large files (a league run's
# six checkpoints came to 55 MB).
if [ -n "${OUT:-}" ]; then
  newest=$(ls "$R/rcss/checkpoints" | sort -n | tail -1)
  (cd "$R" && tar czf "$OUT/rcss.tgz" $(find rcss -mindepth 1 -maxdepth 1 ! -name checkpoints) \
    "rcss/checkpoints/$newest")
fi
