#!/usr/bin/env bash
# Regenerates docs/TRADEOFFS.md, docs/tradeoffs.csv and docs/tradeoffs.svg:
# fetches the real head CT into target/ct (tools/fetch-ct.sh), builds the
# release binary and runs `cdvol experiment tradeoffs` on the sphere
# phantom and the CT. Extra arguments go to the command (--size, --runs).
# Takes about 3 minutes on 2 cores with the defaults below.
#
# usage: tools/tradeoffs.sh [--size 512] [--runs 7]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
bash tools/fetch-ct.sh target/ct >&2
cargo build --profile release-lto --quiet
./target/release-lto/cdvol experiment tradeoffs --ct target/ct/cranium.json \
    --size 512 --runs 7 "$@"
