#!/usr/bin/env bash
# Wait for call NNN of a file pilot (its DIR/NNN.prompt.md) or for DIR/done.txt, and print the file's path and text.
# usage: scripts/files-wait.sh DIR NNN        (FILES_ANSWER_WAIT_S, default 120 s; exit 1 when neither came)
set -euo pipefail
[ $# -eq 2 ] || { echo "usage: $0 DIR NNN" >&2; exit 2; }
dir=${1%/} next=$2
[ -d "$dir" ] || { echo "not a directory: $dir" >&2; exit 2; }
[[ $next =~ ^[0-9]{3,}$ ]] || { echo "NNN must be a call number like 002, got '$next'" >&2; exit 2; }
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
