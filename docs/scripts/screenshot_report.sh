#!/usr/bin/env bash
# Screenshot a run's report.html in headless Chromium (Debian's `chromium` package:
# `apt-get install chromium`), to check that the page renders as a browser shows it.
#
#   docs/scripts/screenshot_report.sh target/reconstruct/default-quick/report.html report.png [WIDTH HEIGHT]
#
# Prints the PNG's path. Runs as root without a sandbox (a container has none to offer).
set -euo pipefail
page="$(realpath "$1")"
out="$(realpath -m "$2")"
width="${3:-1280}"
height="${4:-4000}"
browser="$(command -v chromium || command -v chromium-browser || true)"
if [[ -z "$browser" ]]; then
  echo "no chromium on PATH: apt-get install chromium" >&2
  exit 1
fi
"$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars \
  --window-size="${width},${height}" --screenshot="$out" "file://${page}" >/dev/null 2>&1
test -s "$out"
echo "$out"
