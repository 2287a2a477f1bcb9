#!/bin/bash
# One side of a diagnostic match (docs/results/robocup.md, session 17): the elevens goalie (the
# naive team's player 1 with every elevens rule) and helios-base's 10 outfield players and coach,
# under one team name. The elevens goalie connects first, so it gets unum 1.
#   elevens robocup match --team0-cmd "scripts/robocup_mixed_goalie.sh {port} {coach_port} {team}" \
#     --team0-name MIXED --team1-cmd "$ELEVENS_HELIOS_START -p {port} -P {coach_port} -t {team}" \
#     --team1-name HELIOS_base --matches 2
# ELEVENS_HELIOS_START names helios-base's start.sh (docs/results/robocup.md: building it).
set -eu
PORT=$1; COACH_PORT=$2; TEAM=$3
PYTHON=${PYTHON:-python3}
HELIOS_DIR=$(dirname "${ELEVENS_HELIOS_START:?set it to the start.sh of helios-base}")
"$PYTHON" -m elevens robocup team --team naive --host localhost --port "$PORT" \
  --team-name "$TEAM" --players 1 &
sleep 4
cd "$HELIOS_DIR"
options="--player-config ./player.conf --config_dir ./formations-dt -h localhost -p $PORT -t $TEAM"
for _ in 2 3 4 5 6 7 8 9 10 11; do
  ./sample_player $options > /dev/null 2>&1 &
  sleep 0.2
done
./sample_coach --coach-config ./coach.conf -h localhost -p "$COACH_PORT" -t "$TEAM" > /dev/null 2>&1 &
wait
