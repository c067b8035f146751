#!/bin/sh
# Peer benchmark: tress against Mitsuba 3 on the same hair scenes (README.md beside this file).
#   bench/peer/run.sh [--quick] [--rounds N] [--threads N]
# Makes a virtualenv with Mitsuba under the cargo target dir (not a test dependency), builds
# tress (release), renders, prints the tables and writes them to bench/peer/results/.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
target=${CARGO_TARGET_DIR:-$repo/target}
data=${TRESS_DATA:-$repo/../shared/data}
venv=$target/peer-venv

# Mitsuba's llvm variants JIT-compile through the system's libLLVM; 3.9.1 needs LLVM ≥ 16
# (older ones abort on the `llvm.minimum` intrinsic). Debian 12 ships libllvm19.
llvm=$(ls /usr/lib/*-linux-gnu/libLLVM.so.19* /usr/lib/*-linux-gnu/libLLVM-19.so 2>/dev/null | head -n 1 || true)
if [ -z "$llvm" ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q libllvm19 >/dev/null
        llvm=$(ls /usr/lib/*-linux-gnu/libLLVM.so.19* | head -n 1)
    else
        echo "run.sh: needs libLLVM 19 (Debian: apt-get install libllvm19), or set DRJIT_LIBLLVM_PATH" >&2
        [ -n "${DRJIT_LIBLLVM_PATH:-}" ] || exit 1
    fi
fi
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-$llvm}

if ! "$venv/bin/python" -c 'import mitsuba, numpy; assert mitsuba.__version__ == "3.9.1"' 2>/dev/null; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q mitsuba==3.9.1 numpy
fi

(cd "$repo" && cargo build --release -q -p tress-cli)

mode=full
for a in "$@"; do [ "$a" = --quick ] && mode=quick; done
exec "$venv/bin/python" "$here/peer.py" --tress "$target/release/tress" --work "$target/peer" \
    --data "$data" --log "$here/results/$mode.md" "$@"
