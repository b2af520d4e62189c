#!/usr/bin/env bash
# fovea-eval's reduced run (tests/eval/CMakeLists.txt): the three datasets and
# every condition, 10 frames at 2 HMD positions, then the report's files and the
# figures that must hold whatever the machine: every run present, foveation
# sending fewer points than FREF, FREF's images identical to themselves.
# usage: run_reduced.sh FOVEA_EVAL OUT_DIR TUM_DIR
set -euo pipefail
eval_bin="$1" out="$2" tum="$3"
fail() { echo "run_reduced: $*" >&2; exit 1; }

# The TUM sequence is one of the experiment's three datasets: without it (no
# ../shared) the run would be a different experiment, so it skips, saying why
# (CTest: SKIP_RETURN_CODE 77; in CI that skip is a failure, toolchain/check-skips).
if [ ! -f "$tum/associations.txt" ]; then
  echo "SKIP: no TUM sequence at $tum (the recorded frames of ../shared/data)"
  exit 77
fi
frames=10
args=(--out-dir "$out" --frames "$frames" --positions 2 --quality-positions 1 --fresh --tum "$tum")
datasets=3
"$eval_bin" "${args[@]}" || fail "fovea-eval failed"

for f in report.md runs.csv table2.csv stages.csv quality.csv bandwidth.gp stages.gp; do
  [ -s "$out/$f" ] || fail "no $f"
done
runs=$(($(wc -l < "$out/runs.csv") - 1))
conditions=7  # F1, F2, F3, FREF, ACUITY, ACUITY-2MM, ACUITY-REFINED
[ "$runs" -eq $((datasets * conditions * 2)) ] || fail "runs.csv has $runs runs, expected $((datasets * conditions * 2))"
# Every run's figures are numbers, every run decoded its frames.
awk -F, -v frames="$frames" 'NR > 1 && ($4 != frames || $7 + 0 <= 0 || $10 + 0 <= 0) { print "bad run: " $0; bad = 1 } END { exit bad }' \
  "$out/runs.csv" || fail "a run without its frames, bandwidth or latency"
# Every run counted its datagrams. How many were lost is reported, not asserted: on a
# loaded machine (CI runs qemu beside this) the operator falls behind FREF's 39 MB/s,
# and that is timing, which tests do not bound.
awk -F, 'NR > 1 && !($12 + 0 > 0 && $13 != "" && $13 + 0 >= 0) { print "no datagram counts: " $0; bad = 1 }
         NR > 1 { sent += $12; lost += $13 }
         END { printf "run_reduced: %d of %d datagrams lost\n", lost, sent + lost; exit bad }' \
  "$out/runs.csv" || fail "a run without its datagram counts"
# F1, F2, F3, ACUITY, ACUITY-2MM and ACUITY-REFINED send fewer points than FREF on every
# dataset: at most 80 % of FREF's points per frame (table2.csv column 14, counted by the
# service). Not the MB/s of column 7: on a loaded machine FREF's frames arrive incomplete
# (a local CI run measured FREF on TUM at 9.2 MB/s, below F3), and that is timing again.
awk -F, 'NR > 1 && $2 == "FREF" { fref[$1] = $14 }
         NR > 1 && $2 != "FREF" { row[NR] = $0; dataset[NR] = $1; points[NR] = $14 }
         END { for (k in row) if (!(fref[dataset[k]] > 0 && points[k] + 0 > 0 && points[k] < 0.8 * fref[dataset[k]])) {
                 print "no reduction against FREF: " row[k]; bad = 1 }
               exit bad }' \
  "$out/table2.csv" || fail "a condition that does not send fewer points than FREF"
# Quality: FREF against itself is perfect; every other condition is measured and below it.
awk -F, 'NR > 1 && $2 == "FREF" && ($8 != "inf" || $9 != "1.00000") { print "FREF not identical: " $0; bad = 1 }
         NR > 1 && $2 != "FREF" && !($7 + 0 > 0 && $7 + 0 < 1) { print "quality not measured: " $0; bad = 1 }
         END { exit bad }' "$out/quality.csv" || fail "quality rows wrong"
images=$(ls "$out"/images/*.png 2>/dev/null | wc -l)
[ "$images" -eq $((datasets * (conditions - 1))) ] ||
  fail "$images side-by-side images, expected $((datasets * (conditions - 1)))"
grep -q "Table II" "$out/report.md" || fail "report.md has no table"
# Every image the report links to was written, and no link is empty.
! grep -q '\]()' "$out/report.md" || fail "report.md has an empty link"
grep -o '](images/[^)]*)' "$out/report.md" | sed 's/^](//; s/)$//' | while read -r f; do
  [ -s "$out/$f" ] || fail "report.md links to $f, which is not there"
done
grep -q "not a user study" "$out/report.md" || fail "report.md does not say the quality figures are proxies"
echo "run_reduced: $runs runs, $images images, report in $out"
