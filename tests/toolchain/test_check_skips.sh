#!/usr/bin/env bash
# toolchain/check-skips against made-up reports in the formats CTest 3.25
# (--output-junit) and GoogleTest 1.12 (--gtest_output=xml) write: each CTest
# test a case ("case" mode) or a whole binary whose cases come from its own
# report ("binary" mode, FOVEA_TEST_GRANULARITY). With CI=true a skip passes
# only when toolchain/ci-allowed-skips lists the test with the reason it gave,
# and a binary that passed without a report fails. The allowed skip used is the
# real list's GPIO line (test_gpio.GpiodGpio.RealLineRequestSetAndReadBack).
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
check="$root/toolchain/check-skips"
command -v python3 >/dev/null || { echo "SKIP: python3 is not installed"; exit 77; }

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
failures=0
# expect CI-VALUE EXIT-CODE DESCRIPTION ARGS...: check-skips ARGS with CI set so.
expect() {
  local ci="$1" want="$2" what="$3" out rc
  shift 3
  out="$(CI="$ci" "$check" "$@" 2>&1)"; rc=$?
  last_out="$out"
  if [ "$rc" -eq "$want" ]; then
    echo "ok: $what (exit $rc)"
  else
    echo "FAILED: $what: expected exit $want, check-skips exited $rc:"; echo "$out"
    failures=$((failures + 1))
  fi
}
# contains TEXT DESCRIPTION: the last check-skips output has TEXT.
contains() {
  if grep -qF -- "$1" <<<"$last_out"; then echo "ok: $2"; else
    echo "FAILED: $2: no '$1' in:"; echo "$last_out"; failures=$((failures + 1)); fi
}

# junit FILE "NAME|STATUS|OUTPUT" ...: a CTest JUnit report.
junit() {
  local file="$1" row name status out
  shift
  {
    echo '<?xml version="1.0" encoding="UTF-8"?>'
    echo "<testsuite name=\"Linux\" tests=\"$#\">"
    for row in "$@"; do
      IFS='|' read -r name status out <<<"$row"
      echo "  <testcase name=\"$name\" classname=\"$name\" time=\"0.1\" status=\"$status\">"
      [ "$status" != notrun ] || echo "    <skipped message=\"SKIP_REGULAR_EXPRESSION_MATCHED\"/>"
      echo "    <system-out>$out</system-out>"
      echo "  </testcase>"
    done
    echo "</testsuite>"
  } >"$file"
}
# gtest FILE "SUITE.NAME|completed|skipped|failed|REASON" ...: a GoogleTest report.
gtest() {
  local file="$1" row full result reason suite name
  shift
  {
    echo '<?xml version="1.0" encoding="UTF-8"?>'
    echo '<testsuites name="AllTests">'
    for row in "$@"; do
      IFS='|' read -r full result reason <<<"$row"
      suite="${full%%.*}" name="${full#*.}"
      echo "  <testsuite name=\"$suite\">"
      case "$result" in
        completed) echo "    <testcase name=\"$name\" status=\"run\" result=\"completed\" classname=\"$suite\" />" ;;
        skipped) echo "    <testcase name=\"$name\" status=\"run\" result=\"skipped\" classname=\"$suite\">"
                 echo "      <skipped message=\"test.cpp:12&#x0A;$reason\"><![CDATA[test.cpp:12
$reason]]></skipped>"
                 echo "    </testcase>" ;;
        failed) echo "    <testcase name=\"$name\" status=\"run\" result=\"completed\" classname=\"$suite\">"
                echo "      <failure message=\"test.cpp:9&#x0A;Expected equality\" type=\"\"/>"
                echo "    </testcase>" ;;
      esac
      echo "  </testsuite>"
    done
    echo '</testsuites>'
  } >"$file"
}

gpio=test_gpio.GpiodGpio.RealLineRequestSetAndReadBack
gpio_reason="no /dev/gpiochip* on this machine"

# "case" mode: each CTest test one case, its output in the JUnit report.
junit "$tmp/allowed.xml" "test_a.S.Ran|run|[  PASSED  ]" "$gpio|notrun|[  SKIPPED ] $gpio_reason"
expect true 0 "case mode: a listed skip with its reason" "$tmp/allowed.xml" stage
contains "check-skips: allowed stage: $gpio: $gpio_reason" "the allowed skip is named"
junit "$tmp/other.xml" "test_a.S.Ran|run|" "$gpio|notrun|[  SKIPPED ] the chip was busy"
expect true 1 "case mode: a listed test skipped for another reason" "$tmp/other.xml" stage
contains "REFUSED stage: $gpio" "the refused skip is named"
expect false 0 "case mode: the same without CI only lists it" "$tmp/other.xml" stage
junit "$tmp/unlisted.xml" "test_a.S.Ran|run|" "vm.suites|notrun|qemu-system-aarch64 is missing"
expect true 1 "case mode: an unlisted test skipped" "$tmp/unlisted.xml" stage
junit "$tmp/none.xml" "$gpio|notrun|[  SKIPPED ] $gpio_reason"
expect true 1 "no test ran at all" "$tmp/none.xml" stage

# "binary" mode: CTest runs test_gpio whole; its cases come from its own report.
printf 'test_gpio %s\n' "$tmp/reports/test_gpio.xml" >"$tmp/binaries.txt"
mkdir "$tmp/reports"
junit "$tmp/binary.xml" "test_gpio|run|[==========] 2 tests ran" "toolchain.check_tree|run|ok"
gtest "$tmp/reports/test_gpio.xml" "GpiodGpio.AMissingChip|completed|" "GpiodGpio.RealLineRequestSetAndReadBack|skipped|$gpio_reason"
expect true 0 "binary mode: a listed case skipped with its reason" "$tmp/binary.xml" stage \
  --binaries "$tmp/binaries.txt" --cases "$tmp/cases.txt"
contains "check-skips: allowed stage: $gpio: $gpio_reason" "the case is named as in case mode"
contains "stage: 2 ran, 1 skipped, 1 of them allowed" "the binary's cases are counted, and the script"
if diff <(printf 'ran test_gpio.GpiodGpio.AMissingChip\nskipped %s\nran toolchain.check_tree\n' "$gpio") "$tmp/cases.txt" >/dev/null; then
  echo "ok: --cases lists every case with its outcome"
else
  echo "FAILED: --cases wrote:"; cat "$tmp/cases.txt"; failures=$((failures + 1))
fi
gtest "$tmp/reports/test_gpio.xml" "GpiodGpio.AMissingChip|completed|" "GpiodGpio.RealLineRequestSetAndReadBack|skipped|the chip was busy"
expect true 1 "binary mode: a listed case skipped for another reason" "$tmp/binary.xml" stage --binaries "$tmp/binaries.txt"
contains "REFUSED stage: $gpio (the chip was busy)" "the refused case and its reason are named"
gtest "$tmp/reports/test_gpio.xml" "GpiodGpio.AMissingChip|failed|" "GpiodGpio.Other|completed|"
expect true 0 "binary mode: a failed case counts as run (CTest fails the binary)" "$tmp/binary.xml" stage \
  --binaries "$tmp/binaries.txt" --cases "$tmp/cases.txt"
grep -qx "failed test_gpio.GpiodGpio.AMissingChip" "$tmp/cases.txt" && echo "ok: the failed case is listed" ||
  { echo "FAILED: no failed case in:"; cat "$tmp/cases.txt"; failures=$((failures + 1)); }
rm "$tmp/reports/test_gpio.xml"
expect true 1 "binary mode: a binary that passed without its report" "$tmp/binary.xml" stage --binaries "$tmp/binaries.txt"
contains "GoogleTest report is unreadable" "the missing report is named"
junit "$tmp/binary-failed.xml" "test_gpio|fail|Segmentation fault" "toolchain.check_tree|run|ok"
expect true 0 "binary mode: a binary that died before its report is CTest's failure" "$tmp/binary-failed.xml" stage \
  --binaries "$tmp/binaries.txt"
expect true 2 "an unknown option" "$tmp/binary.xml" stage --bogus

[ "$failures" -eq 0 ] || { echo "$failures checks failed"; exit 1; }
echo "all check-skips checks passed"
