#!/usr/bin/env bash
# LeakSanitizer against OpenNI2 (ASan tree only): with toolchain/lsan.supp, a
# clean use of OpenNI2 through fovea's runtime reports nothing, and a stream that
# is created and forgotten is reported (tests/unit/hal/openni2_leak_probe.cpp).
# usage: test_openni2_leaks.sh PROBE LSAN_SUPP
set -uo pipefail
probe="$1" supp="$2"
export LSAN_OPTIONS="suppressions=$supp:print_suppressions=0"
# As fovea_add_test(... OPENNI2 ...): the slow unwinder, so stacks reach fovea through libOpenNI2.
export ASAN_OPTIONS="${ASAN_OPTIONS:-}:detect_leaks=1:fast_unwind_on_malloc=0"
failures=0

out="$("$probe" clean 2>&1)"; rc=$?
if [ $rc -eq 0 ] && ! grep -q "ERROR: LeakSanitizer" <<<"$out" && grep -q "clean: done" <<<"$out"; then
  echo "ok: a clean use of OpenNI2 reports no leak"
else
  echo "FAILED: a clean use of OpenNI2 (exit $rc) did not finish or reported a leak:"; tail -n 40 <<<"$out"
  failures=$((failures + 1))
fi

out="$("$probe" forget 2>&1)"; rc=$?
if [ $rc -ne 0 ] && grep -q "ERROR: LeakSanitizer" <<<"$out" && grep -q "libOpenNI2.so" <<<"$out" \
   && grep -q "forget: done" <<<"$out"; then
  echo "ok: a forgotten OpenNI2 stream is reported: $(grep -m1 '^SUMMARY' <<<"$out")"
else
  echo "FAILED: a forgotten OpenNI2 stream was not reported (exit $rc):"; tail -n 40 <<<"$out"
  failures=$((failures + 1))
fi
[ $failures -eq 0 ] && echo "test_openni2_leaks: all passed"
exit $((failures > 0))
