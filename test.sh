#!/usr/bin/env bash
# Installs anything missing, then runs the full test suite.
set -euo pipefail
cd "$(dirname "$0")"
.ci/install-deps
cargo test --workspace --release "$@"
