#!/usr/bin/env bash
# Answer call NNN of a file pilot (vln-pilot run ... --pilot files:DIR), then wait for what comes next.
# usage: scripts/files-answer.sh DIR NNN 'JSON'
# Writes DIR/NNN.answer.json atomically, waits (FILES_ANSWER_WAIT_S, default 120 s) for the next prompt
# (a re-ask is a next prompt too) or for done.txt (the episode ended), and prints its path and text.
set -euo pipefail
[ $# -eq 3 ] || { echo "usage: $0 DIR NNN 'JSON'" >&2; exit 2; }
dir=${1%/} call=$2 json=$3
[ -d "$dir" ] || { echo "not a directory: $dir" >&2; exit 2; }
[[ $call =~ ^[0-9]{3,}$ ]] || { echo "NNN must be a call number like 001, got '$call'" >&2; exit 2; }
printf '%s\n' "$json" > "$dir/.$call.answer.json.tmp"
mv -f "$dir/.$call.answer.json.tmp" "$dir/$call.answer.json"
next=$(printf '%03d' $((10#$call + 1)))
wait_s=${FILES_ANSWER_WAIT_S:-120}
end=$((SECONDS + wait_s))
while :; do
  for f in "$dir/$next.prompt.md" "$dir/done.txt"; do
    if [ -f "$f" ]; then echo "$f"; cat "$f"; exit 0; fi
  done
  [ $SECONDS -lt $end ] || break
  sleep 0.1
done
echo "no new prompt ($next.prompt.md) nor done.txt in $dir within $wait_s s" >&2
exit 1
