#!/usr/bin/env bash
# Answer call NNN of a file pilot (vln-pilot run ... --pilot files:DIR), then wait for what comes next.
# usage: scripts/files-answer.sh [--no-wait] DIR NNN 'JSON'
# Writes DIR/NNN.answer.json atomically, waits (FILES_ANSWER_WAIT_S, default 120 s) for the next prompt
# (a re-ask is a next prompt too) or for done.txt (the episode ended), and prints its path and text.
# --no-wait: write the answer and stop (a stateless pilot answers one call and is done: docs/pilot-memory.md).
set -euo pipefail
wait=1
if [ "${1:-}" = "--no-wait" ]; then wait=0; shift; fi
[ $# -eq 3 ] || { echo "usage: $0 [--no-wait] DIR NNN 'JSON'" >&2; exit 2; }
dir=${1%/} call=$2 json=$3
[ -d "$dir" ] || { echo "not a directory: $dir" >&2; exit 2; }
[[ $call =~ ^[0-9]{3,}$ ]] || { echo "NNN must be a call number like 001, got '$call'" >&2; exit 2; }
printf '%s\n' "$json" > "$dir/.$call.answer.json.tmp"
mv -f "$dir/.$call.answer.json.tmp" "$dir/$call.answer.json"
[ $wait -eq 1 ] || { echo "$dir/$call.answer.json"; exit 0; }
next=$(printf '%03d' $((10#$call + 1)))
exec "$(dirname "$0")/files-wait.sh" "$dir" "$next"
