#!/usr/bin/env bash
# Installs anything missing, then runs clippy (warnings are errors) and the full test suite.
set -euo pipefail
cd "$(dirname "$0")"
.ci/install-deps
if cargo clippy --version >/dev/null 2>&1; then
    cargo clippy --workspace --all-targets --release -- -D warnings
else
    echo "test.sh: clippy is not installed (rustup component add clippy): lints skipped" >&2
fi
cargo test --workspace --release "$@"
