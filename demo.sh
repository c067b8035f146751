#!/usr/bin/env bash
# Installs anything missing, then renders the default scene to out/demo.exr and out/demo.png.
set -euo pipefail
cd "$(dirname "$0")"
.ci/install-deps libembree-dev
cargo run --release -q -p tress-cli -- render scenes/demo.ron --out out/demo.exr "$@"
