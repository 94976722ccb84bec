#!/usr/bin/env bash
# Builds the `cirrus` binary of another revision (for `cargo bench -- oak-bake`'s baseline):
# a git worktree under target/baseline/REV, its own target folder, release profile. Prints the
# binary's path; `CIRRUS_BENCH_BASELINE=$(tools/build_baseline.sh REV) cargo bench -- oak-bake`.
set -euo pipefail
cd "$(dirname "$0")/.."
revision=${1:?usage: tools/build_baseline.sh REVISION}
commit=$(git rev-parse --short "$revision^{commit}")
tree=target/baseline/$commit
if [ ! -d "$tree" ]; then
    git worktree add --detach "$tree" "$commit" >&2
fi
CARGO_TARGET_DIR="$PWD/target/baseline-target/$commit" cargo build --release --bin cirrus --manifest-path "$tree/Cargo.toml" >&2
echo "$PWD/target/baseline-target/$commit/release/cirrus"
