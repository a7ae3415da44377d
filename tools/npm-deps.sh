#!/usr/bin/env bash
# Test-only Node packages for the independent MCAP reader check
# (tests/mcap/check.mjs: @mcap/core, @mcap/support, @foxglove/rosmsg,
# @foxglove/rosmsg2-serialization at the versions pinned in
# tests/mcap/package.json), installed into a project-local folder (default
# build/npm), never globally. Installs Debian's nodejs and npm first when
# there is no node or npm. Idempotent: does nothing when the installed
# package.json matches the pinned one and node_modules is there.
#   usage: npm-deps.sh [DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
DIR=${1:-build/npm}
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
    bash tools/deps.sh nodejs npm
fi
mkdir -p "$DIR"
cp tests/mcap/check.mjs "$DIR/check.mjs" # ESM resolves packages next to the script
if [ -d "$DIR/node_modules" ] && cmp -s tests/mcap/package.json "$DIR/package.json"; then
    exit 0
fi
cp tests/mcap/package.json "$DIR/package.json"
echo "npm-deps: installing the MCAP check's packages into $DIR"
# A registry that cannot be reached (no route, a TLS proxy whose CA this
# machine does not trust) fails within about a minute instead of npm's
# default retries of several minutes each; the reason is npm's own message.
if ! (cd "$DIR" && npm install --no-audit --no-fund --no-save --loglevel=error \
        --fetch-timeout=30000 --fetch-retries=1 --fetch-retry-maxtimeout=10000); then
    rm -rf "$DIR/node_modules" "$DIR/package.json"
    echo "npm-deps: npm install failed (above): the MCAP reader check cannot run." >&2
    echo "npm-deps: behind a TLS-intercepting proxy, add its CA to the system's store" >&2
    echo "npm-deps: (update-ca-certificates) or point npm's cafile at it, then rerun." >&2
    exit 1
fi
