#!/usr/bin/env bash
# Regenerates docs/EXPERIMENTS.md and docs/experiments/ (the paper's
# section 5: Figs. 16, 17, 18, 20, 22, Tables 1, 2) from a release build.
# Usage: tools/experiments.sh [extra `cdvol experiment all` options]
set -euo pipefail
cd "$(dirname "$0")/.."
ct_dir=target/ct
[ -f "$ct_dir/cranium.json" ] || tools/fetch-ct.sh "$ct_dir"
cargo build --profile release-lto --quiet
exec target/release-lto/cdvol experiment all --ct "$ct_dir/cranium.json" --out docs/EXPERIMENTS.md "$@"
