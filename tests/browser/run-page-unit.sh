#!/usr/bin/env bash
# run-page-unit.sh WEB_DIR: the page's own unit tests (web/viewer/tests/*.test.mjs) under Node's
# test runner; no browser. Exit 77 (skipped) without node, unless CI=true (then 1).
set -euo pipefail
web=$1
if ! command -v node >/dev/null; then
  echo "run-page-unit: missing node (./pmsc.sh build installs it)" >&2
  [ "${CI:-}" = true ] && exit 1
  exit 77
fi
exec node --test "$web"/tests/*.test.mjs
