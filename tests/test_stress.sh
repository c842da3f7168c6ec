#!/usr/bin/env bash
# `vkrt stress --quick` on the Vulkan device with the validation layer on. The table is checked
# here, not only by the program's own verdict: every case on both backends with the watertight
# intersector, 0 leaks, mismatches within the row's limit, BVH depth within 64; on lavapipe the
# GPU's watertight rays of the one-eye cases (eye-icosphere ...) through the binned traversal's
# lists. The checker is first shown doctored tables (one leak, one mismatch over the limit, one
# binned note gone), which it must reject.
set -u
vkrt=${1:?usage: test_stress.sh path/to/vkrt}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export VKRT_VALIDATION=1

# check_table FILE: prints each violation; exit status 0 when there is none.
check_table() {
  awk -v lavapipe="$(grep -c "^vkrt stress.*llvmpipe" "$1")" '
    /^  note: gpu watertight: [0-9]+ rays through the binned traversal/ && last == "gpu watertight" {
      binned[last_case] = 1
    }
    NF == 11 && ($4 == "watertight" || $4 == "mt") && $5 ~ /^[0-9]+$/ {
      rows++
      last = $3 " " $4
      last_case = $1
      if ($4 != "watertight") next
      seen[$1 " " $2 " " $3] = 1
      cases[$1] = 1
      if ($6 != 0) { print "leaks: " $0; bad++ }
      if ($8 != "-" && $7 + 0 > $8 + 0) { print "mismatches over the limit: " $0; bad++ }
      if ($10 + 0 > 64) { print "BVH depth over 64: " $0; bad++ }
      if ($11 != "ok") { print "verdict " $11 ": " $0; bad++ }
    }
    END {
      n = split("leak-icosphere leak-torus leak-cube leak-slivers scale1e-6@0 scale1e6@0 scale1e3@1e6 " \
                "zero-area slivers-1e6 fan-100000 identical-10000 flat zero-dir on-surface-cube " \
                "on-surface-sphere grazing eye-in-torus eye-in-box eye-icosphere eye-slivers " \
                "eye-scale1e-6@0 eye-scale1e6@0 eye-scale1e3@1e6", want, " ")
      for (i = 1; i <= n; i++) {
        found = 0
        for (c in cases) if (index(c, want[i]) == 1) {
          found = 1
          if (lavapipe && c ~ /^eye-/ && c !~ /^eye-in-/ && !(c in binned)) {
            print "no gpu rays through the binned traversal in " c; bad++
          }
          for (b = 0; b < 2; b++) {
            back = b ? "cpu" : "gpu"
            if (!(c " sah " back in seen)) { print "no watertight " back " row for " c; bad++ }
            if (c ~ /^(zero-area|slivers-1e6|fan|identical|flat)/ && !(c " midpoint " back in seen)) {
              print "no midpoint " back " row for " c; bad++
            }
            if (c ~ /^(zero-area|slivers-1e6|fan|identical|flat)/ && !(c " sbvh " back in seen)) {
              print "no sbvh " back " row for " c; bad++
            }
          }
        }
        if (!found) { print "case missing: " want[i]; bad++ }
      }
      if (rows == 0) { print "no table rows"; bad++ }
      exit bad > 0
    }' "$1"
}

"$vkrt" stress --quick >"$tmp/table" 2>"$tmp/err"
code=$?
cat "$tmp/table"
[ -s "$tmp/err" ] && sed 's/^/stderr | /' "$tmp/err"
failed=0

# The checker must be able to fail: one leak in a watertight GPU row, one mismatch over a limit.
awk 'NF == 11 && $3 == "gpu" && $4 == "watertight" && !done { $6 = 1; done = 1 } { print }' "$tmp/table" >"$tmp/leak"
awk 'NF == 11 && $4 == "watertight" && $8 ~ /^[0-9]+$/ && !done { $7 = $8 + 1; done = 1 } { print }' "$tmp/table" >"$tmp/over"
if check_table "$tmp/leak" >/dev/null || check_table "$tmp/over" >/dev/null; then
  echo "FAIL the table checker accepts a doctored table"; failed=1
else echo "ok   the table checker rejects a leak and a mismatch over the limit"; fi
if grep -q "^vkrt stress.*llvmpipe" "$tmp/table"; then
  awk '/^  note: gpu watertight: [0-9]+ rays through the binned/ && !done { done = 1; next } { print }' "$tmp/table" >"$tmp/unbinned"
  if check_table "$tmp/unbinned" >/dev/null; then echo "FAIL the table checker accepts a one-eye case the BVH took"; failed=1
  else echo "ok   the table checker rejects a one-eye case without the binned traversal"; fi
fi

if [ "$code" -ne 0 ]; then echo "FAIL vkrt stress --quick exited $code"; failed=1; else echo "ok   vkrt stress --quick exited 0"; fi
if check_table "$tmp/table" >"$tmp/violations"; then
  echo "ok   every watertight row: both backends, 0 leaks, mismatches within the limit"
else
  echo "FAIL watertight rows:"; sed 's/^/     | /' "$tmp/violations"; failed=1
fi

"$vkrt" stress some.obj >/dev/null 2>&1
code=$?
if [ "$code" -eq 2 ]; then echo "ok   stress with a FILE is a usage error"; else echo "FAIL stress with a FILE exited $code, wanted 2"; failed=1; fi
exit $failed
