#!/usr/bin/env bash
# toolchain/check-tree against throwaway git repositories: one laid out like this
# repository (its tracked top-level entries and its .gitignore) must pass, and
# the same with a stray file, a stray folder or an untracked stray must fail;
# ignored build trees must not count. Exit 77 (skip) without git.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
check="$root/toolchain/check-tree"
command -v git >/dev/null || { echo "SKIP: git is not installed"; exit 77; }
git -C "$root" rev-parse --is-inside-work-tree >/dev/null 2>&1 \
  || { echo "SKIP: $root is not a git work tree (an exported source tree)"; exit 77; }

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
failures=0
expect() {  # expect pass|fail DESCRIPTION
  local want="$1" what="$2" out rc
  out="$("$check" "$tmp/repo" 2>&1)"; rc=$?
  if { [ "$want" = pass ] && [ $rc -eq 0 ]; } || { [ "$want" = fail ] && [ $rc -ne 0 ]; }; then
    echo "ok: $what ($want)"
  else
    echo "FAILED: $what: expected $want, check-tree exited $rc:"; echo "$out"
    failures=$((failures + 1))
  fi
}

# A repository with this one's top-level entries, tracked, and its .gitignore.
mkdir "$tmp/repo"
git -C "$tmp/repo" init -q
cp "$root/.gitignore" "$tmp/repo/.gitignore"
# One line per top-level entry (a folder: "NAME/"), not per tracked file: a
# process or two per file of the repository took most of this test's minute.
while IFS= read -r top; do
  case "$top" in
    */) mkdir -p "$tmp/repo/$top" && touch "$tmp/repo/${top}file" ;;
    *) touch "$tmp/repo/$top" ;;
  esac
done < <(git -C "$root" ls-files | sed -E 's|^([^/]*/).*|\1|' | sort -u)
git -C "$tmp/repo" add -A
git -C "$tmp/repo" -c user.name=t -c user.email=t@t commit -qm layout
expect pass "this repository's tracked layout"

mkdir -p "$tmp/repo/build-aarch64" "$tmp/repo/out"; touch "$tmp/repo/build-aarch64/x" "$tmp/repo/out/fovea.deb"
expect pass "ignored build-aarch64/ and out/"

touch "$tmp/repo/3,2.25,1.35"
expect fail "an untracked stray file '3,2.25,1.35'"
git -C "$tmp/repo" add "3,2.25,1.35"
expect fail "the same file tracked"
git -C "$tmp/repo" rm -q --cached "3,2.25,1.35" && rm "$tmp/repo/3,2.25,1.35"
expect pass "after removing it"

mkdir "$tmp/repo/scratch" && touch "$tmp/repo/scratch/notes.txt"
expect fail "an untracked stray folder"
rm -r "$tmp/repo/scratch"

touch "$tmp/repo/build-package-amd64.configure.log"
expect fail "a log file at the root (ignored are folders /build*/, not files)"
rm "$tmp/repo/build-package-amd64.configure.log"

mkdir "$tmp/notgit"
if "$check" "$tmp/notgit" >/dev/null 2>&1; then echo "FAILED: a directory outside git passed"; failures=$((failures + 1)); else echo "ok: a directory outside git (fail)"; fi

[ $failures -eq 0 ] && echo "check-tree: all cases passed" || echo "check-tree: $failures cases failed"
exit $((failures != 0))
