#!/usr/bin/env bash
# toolchain/check-layers on this tree (its includes, the library graph this
# build's configure wrote and, when given, the graph in docs/architecture.md)
# must pass; on throwaway trees an include that goes up a layer, a library
# that links a higher layer and a cycle of libraries must each fail.
#   test_check_layers.sh GRAPH_FILE [ARCHITECTURE_DOC]
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
graph="${1:?usage: test_check_layers.sh GRAPH_FILE [ARCHITECTURE_DOC]}"
doc="${2:-}"
failures=0
expect() {  # expect pass|fail DESCRIPTION COMMAND...
  local want="$1" what="$2" out rc
  shift 2
  out="$("$@" 2>&1)"; rc=$?
  if { [ "$want" = pass ] && [ $rc -eq 0 ]; } || { [ "$want" = fail ] && [ $rc -eq 1 ]; }; then
    echo "ok: $what ($want)"
  else
    echo "FAILED: $what: expected $want, check-layers exited $rc:"
    failures=$((failures + 1))
  fi
  echo "$out" | sed 's/^/    /'
}

if [ -n "$doc" ]; then
  expect pass "this tree, its library graph and $doc" "$root/toolchain/check-layers" --graph-file "$graph" --doc "$doc"
else
  expect pass "this tree and its library graph" "$root/toolchain/check-layers" --graph-file "$graph"
fi

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/toolchain" "$tmp/core" "$tmp/pipeline" "$tmp/net"
cp "$root/toolchain/check-layers" "$tmp/toolchain/"
printf '#pragma once\n#include "core/result.h"\n' >"$tmp/pipeline/foveator.h"
printf '#pragma once\n#include "pipeline/foveator.h"\n' >"$tmp/net/codec.h"
expect pass "includes that go down" "$tmp/toolchain/check-layers"
printf '#include "net/codec.h"\n' >"$tmp/pipeline/up.cpp"
expect fail "pipeline/ including net/" "$tmp/toolchain/check-layers"
rm "$tmp/pipeline/up.cpp"

printf '%s\n' "fovea_core STATIC_LIBRARY core: " "fovea_pipeline STATIC_LIBRARY pipeline: fovea_core" \
  "fovea_net STATIC_LIBRARY net: fovea_pipeline fovea_core" >"$tmp/good.txt"
expect pass "a graph that goes down" "$tmp/toolchain/check-layers" --graph-file "$tmp/good.txt"
printf '%s\n' "fovea_core STATIC_LIBRARY core: " "fovea_pipeline STATIC_LIBRARY pipeline: fovea_core fovea_net" \
  "fovea_net STATIC_LIBRARY net: fovea_core" >"$tmp/up.txt"
expect fail "a pipeline library linking a net one" "$tmp/toolchain/check-layers" --graph-file "$tmp/up.txt"
printf '%s\n' "fovea_hal STATIC_LIBRARY hal: fovea_hal_x" "fovea_hal_x STATIC_LIBRARY hal/camera/x: fovea_hal" \
  >"$tmp/cycle.txt"
expect fail "two hal libraries linking each other" "$tmp/toolchain/check-layers" --graph-file "$tmp/cycle.txt"

[ "$failures" -eq 0 ] || { echo "test_check_layers: $failures failed"; exit 1; }
echo "test_check_layers: all passed"
