# Sourced by the replay tests, whose first two arguments are AGVLOC and WORKDIR. AGVLOC may be
# "EMULATOR ARGS... BINARY"; the simulator (DESK) is agvloc-desk beside BINARY, or AGV_DESK when
# set (a native desk under AGV_HOST_DESK). WORK is emptied.
read -r -a AGVLOC <<< "$1"
DESK=("${AGVLOC[@]}")
DESK[-1]="$(dirname "${AGVLOC[-1]}")/agvloc-desk"
if [ -n "${AGV_DESK:-}" ]; then read -r -a DESK <<< "$AGV_DESK"; fi
WORK="$2"
rm -rf "$WORK"
mkdir -p "$WORK"
