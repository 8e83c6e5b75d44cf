#!/usr/bin/env bash
# run-relight.sh PMSC WEB_DIR WORK_DIR: the ctest driver of web/viewer/tests/relight.mjs.
# Exit 77 (skipped) when node, node_modules or chromium is missing, unless CI=true (then 1).
set -euo pipefail
pmsc=$1 web=$2 work=$3

missing=()
command -v node >/dev/null || missing+=(node)
[ -d "$web/node_modules/puppeteer-core" ] && [ -d "$web/node_modules/three" ] || missing+=("$web/node_modules (npm ci)")
[ -x "${CHROMIUM:-/usr/bin/chromium}" ] || missing+=("${CHROMIUM:-/usr/bin/chromium}")
if ((${#missing[@]})); then
  echo "run-relight: missing ${missing[*]} (./pmsc.sh build installs them)" >&2
  [ "${CI:-}" = true ] && exit 1
  exit 77
fi

rm -rf "$work"
mkdir -p "$work"
"$pmsc" demo volume --out "$work/model" --quick >"$work/demo.log" 2>&1 ||
  { tail -20 "$work/demo.log" >&2; echo "run-relight: pmsc demo volume --quick failed" >&2; exit 1; }
[ -f "$work/model/model.pmsc" ] && [ -f "$work/model/density.vdb" ] ||
  { echo "run-relight: pmsc demo volume wrote no model.pmsc/density.vdb in $work/model" >&2; exit 1; }
# The demo's scene.txt names the scene as it trained it (its sample count among others).
scene="volume:$work/model/density.vdb"
[ -s "$work/model/scene.txt" ] && scene=$(head -n 1 "$work/model/scene.txt")
exec node "$web/tests/relight.mjs" --bin "$pmsc" --model "$work/model/model.pmsc" \
  --scene "$scene" --short --out "$work/screenshots"
