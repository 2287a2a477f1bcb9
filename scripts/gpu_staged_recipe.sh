#!/bin/bash
# The staged 11 v 11 recipe from scratch for a fixed number of minutes, sized for one GPU
# (GPU checklist item 5; docs/results/scaling.md, session 14). Stage 1 plays 2 v 2 with large
# batches, stage 2 starts 11 v 11 from stage 1's networks. Both run directories go to $R.
#   R=/tmp/gpuruns G1=1024 MB1=512 MIN1=3.2 G2=128 MB2=352 MIN2=3.3 bash scripts/gpu_staged_recipe.sh
# MIX2=0.5 keeps half of stage 2's iterations in 2 v 2 (session 11's CPU recipe). With OUT set
# (the device tool's output folder), both run directories are packed into $OUT/runs.tgz.
# Then, on any machine:  elevens tournament naive teamwork elevens-11v11 stage1=$R/s1 stage2=$R/s2
#   --players 11 --games 500 --anchor naive
set -eu
PY=${PY:-python3}
R=${R:-/tmp/gpuruns}
common="--iterations-per-chunk 5 --run.no-write-gif --run.keep-checkpoints 1 --run.checkpoint-every 20"
$PY -m elevens train 2v2 --run.run-dir "$R/s1" --games-per-iteration "$G1" \
  --ppo.minibatch-size "$MB1" --run.max-minutes "$MIN1" \
  --run.eval-every 0 --run.eval-teams naive --run.eval-games 200 $common
$PY -m elevens train 11v11 --run.run-dir "$R/s2" --run.init-from "$R/s1" \
  --games-per-iteration "$G2" --ppo.minibatch-size "$MB2" \
  --run.max-minutes "$MIN2" --ppo.learning-rate 3e-4 --ppo.advantage-estimator gae \
  --ppo.gamma 0.99 --ppo.normalize-advantages --ppo.entropy-weight 1e-3 \
  --opponent.polyak-tau 0.05 --env.approach-shaping-weight 0 \
  ${MIX2:+--env.mix 2v2 --env.mix-shares $MIX2} \
  --run.eval-every 0 --run.eval-teams naive --run.eval-games 200 $common
if [ -n "${OUT:-}" ]; then (cd "$R" && tar czf "$OUT/runs.tgz" s1 s2); fi
