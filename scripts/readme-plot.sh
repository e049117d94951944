#!/usr/bin/env bash
# Makes docs/img/session.png, the plot in the README's "Record a session,
# design sound later": the simulator with behaviors and speech, recorded for
# 15 s by `sonibus record`, drawn by `sonibus plot`.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=.venv/bin
work=$(mktemp -d)
trap 'kill $robot 2>/dev/null || true; rm -rf "$work"' EXIT
cat > "$work/robot.toml" <<'TOML'
[nodes.robot]
adapter = "sim"
robot = "pepper"
rate_hz = 50
idle = true
TOML
$bin/sonibus run "$work/robot.toml" --no-multicast --listen tcp/127.0.0.1:7499 & robot=$!
bus=(--no-multicast --connect tcp/127.0.0.1:7499)
$bin/sonibus record "$work/session.mcap" "${bus[@]}" --duration 15 --status-every 100 & recorder=$!
sleep 2
$bin/sonibus send pepper behavior/run animations/Stand/Gestures/Hey_1 "${bus[@]}"
$bin/sonibus send pepper say "hello, I am Pepper" "${bus[@]}"
sleep 5
$bin/sonibus send pepper behavior/run animations/Stand/Gestures/Explain_1 "${bus[@]}"
wait $recorder
$bin/sonibus plot "$work/session.mcap" -o docs/img/session.png --title "sonibus plot session.mcap"
