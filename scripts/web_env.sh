#!/usr/bin/env bash
# The browser test's environment, idempotent: Debian's Chromium (apt, as root, when
# /usr/bin/chromium is missing) and web/node_modules (npm ci, when missing or older than
# web/package-lock.json). Nothing here downloads a browser build.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ ! -x /usr/bin/chromium ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >/dev/null
    apt-get install -y -qq --no-install-recommends chromium >/dev/null
  else
    echo "web_env: /usr/bin/chromium is missing (install Debian's chromium as root)" >&2
  fi
fi

if ! command -v npm >/dev/null 2>&1; then
  echo "web_env: npm is missing (install Node.js 18 or newer)" >&2
  exit 0
fi
stamp=web/node_modules/.package-lock.json
if [ ! -f "$stamp" ] || [ web/package-lock.json -nt "$stamp" ] || [ web/package.json -nt "$stamp" ]; then
  # PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD: playwright-core downloads nothing, but make sure.
  (cd web && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi
