#!/usr/bin/env bash
# agvloc-desk site check / draw end to end (tests/site/model.cmake).
#   site_check_command.sh AGVLOC_DESK SOURCE_DIR WORK_DIR
set -euo pipefail
desk="$1" src="$2" work="$3"
rm -rf "$work" && mkdir -p "$work"
fail() { echo "FAIL: $*" >&2; exit 1; }

out=$("$desk" site check "$src/tools/maps/example_site.yaml")
echo "$out"
[[ "$out" == *"site OK: 5 obstacles, 7 wall landmarks, 2 cameras, 3 AGVs, floor map 25 landmarks"* ]] ||
  fail "example site not OK"

rc=0
"$desk" site check "$src/tests/site/data/broken_site.yaml" >"$work/out" 2>"$work/err" || rc=$?
cat "$work/err"
[ "$rc" -eq 2 ] || fail "broken site: exit $rc, expected 2"
grep -q "obstacles\[1\].outline_mm (line 6): obstacle 'rack-B' overlaps obstacle 'rack-A'" \
  "$work/err" || fail "overlap not named"
grep -q "fleet\[0\].radius_mm (line 8): " "$work/err" || fail "radius not named"
[ "$(wc -l <"$work/err")" -eq 2 ] || fail "expected exactly 2 error lines"
[ ! -s "$work/out" ] || fail "nothing on stdout for a broken site"

rc=0
"$desk" site check "$work/missing.yaml" 2>"$work/err" || rc=$?
[ "$rc" -eq 2 ] && grep -q "missing.yaml" "$work/err" || fail "missing file: exit $rc"

"$desk" site draw "$src/tools/maps/example_site.yaml" --out "$work/site.svg" --png "$work/site.png" \
  --px-per-m 20
grep -q "<svg" "$work/site.svg" || fail "no SVG"
grep -q "rack-B" "$work/site.svg" || fail "SVG without the obstacle ids"
[ "$(head -c 4 "$work/site.png" | tail -c 3)" = "PNG" ] || fail "no PNG"
echo "site check/draw: OK"
