#!/usr/bin/env bash
# Installs anything missing, then runs the full test suite with clippy's lints (warnings are errors).
set -euo pipefail
cd "$(dirname "$0")"
target_dir="${CARGO_TARGET_DIR:-$PWD/target}"
# Whatever stops this script early stops the jobs it started in the background too.
trap 'jobs -p | xargs -r kill 2>/dev/null' EXIT

# mdBook, to build the book below, has no Debian package: cargo installs it into the target folder,
# in the background while apt and the workspace's build run, so its build overlaps theirs.
# Unoptimised and without debug info it compiles in a fraction of the time and still builds this
# book in a second.
mdbook_root="$target_dir/tools"
export PATH="$mdbook_root/bin:$PATH"
mdbook_install=""
if ! command -v mdbook >/dev/null 2>&1; then
    CARGO_PROFILE_RELEASE_OPT_LEVEL=0 CARGO_PROFILE_RELEASE_DEBUG=0 \
        cargo install --quiet --locked --no-default-features --version 0.5.4 --root "$mdbook_root" \
        --target-dir "$target_dir/tools-build" mdbook &
    mdbook_install=$!
fi
.ci/install-deps
# Clippy lints the workspace's crates as they are compiled for the tests and the Python package:
# cargo hands each of them to clippy-driver (as `cargo clippy` does, but with code generation),
# so the dependencies are compiled once instead of checked for clippy and then built again.
# Every target `cargo clippy --all-targets` lints is compiled below: libraries, binaries, unit
# and integration tests, examples (the workspace has no benches).
if clippy-driver --version >/dev/null 2>&1; then
    export RUSTC_WORKSPACE_WRAPPER="$PWD/.ci/clippy-rustc"
else
    echo "test.sh: clippy is not installed (rustup component add clippy): lints skipped" >&2
fi
# The tests run in the background while maturin builds the Python package below, reusing the
# crates built here. .ci/run-tests runs the test binaries themselves (cargo's build folder stays
# free for maturin), two at a time, then the doc tests; this script's arguments go to every
# test binary (a name filter, --ignored, ...).
artifacts="$target_dir/test-binaries.json"
mkdir -p "$target_dir"
cargo test --workspace --release --no-run --message-format=json-render-diagnostics >"$artifacts"
.ci/run-tests "$artifacts" "$@" &
tests=$!

# The Python package (python/): maturin builds the extension module into a virtualenv kept in
# the target folder, and pytest runs its suite once the tests are done.
venv="$target_dir/python-venv"
if [ ! -x "$venv/bin/pip" ]; then
    rm -rf "$venv"
    if ! python3 -m venv "$venv" >/dev/null 2>&1; then
        # Debian's python3 leaves venv's pip bootstrap to the python3-venv package.
        SUDO=""
        if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
        echo "installing python3-venv with apt-get" >&2
        $SUDO apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq python3-venv >/dev/null
        rm -rf "$venv"
        python3 -m venv "$venv"
    fi
fi
"$venv/bin/pip" install --quiet --disable-pip-version-check "maturin>=1.9.4,<2" numpy pytest
rm -rf "$target_dir/python-wheels"
maturin_log="$target_dir/maturin.log"
if ! "$venv/bin/maturin" build --release --manifest-path python/Cargo.toml \
    --interpreter "$venv/bin/python" --out "$target_dir/python-wheels" >"$maturin_log" 2>&1; then
    wait "$tests" || true
    cat "$maturin_log" >&2
    echo "test.sh: maturin could not build the Python package (above)" >&2
    exit 1
fi
wait "$tests"
tail -n 1 "$maturin_log"

# The book (docs/): cargo test has checked its links (tests/tests/docs_links.rs); mdBook builds
# it outside the source tree. mdBook exits 0 on a broken include or unclosed HTML, so any warning
# or error it prints fails the run.
if [ -n "$mdbook_install" ]; then wait "$mdbook_install"; fi
book_dir="$target_dir/book"
mdbook build docs --dest-dir "$book_dir" 2>&1 | tee "$book_dir.log"
if grep -qE 'WARN|ERROR' "$book_dir.log"; then
    echo "test.sh: mdbook build docs printed warnings or errors (above)" >&2
    exit 1
fi

"$venv/bin/pip" install --quiet --disable-pip-version-check --force-reinstall --no-deps \
    "$target_dir"/python-wheels/tress-*.whl
"$venv/bin/pytest" -q python/tests
