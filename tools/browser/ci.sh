#!/usr/bin/env bash
# The `cdvol serve` page in headless Chromium (issue 18), for .ci/run:
# installs Debian's chromium and the script's one npm package
# (playwright-core, which drives the installed browser and downloads
# none), prepares the real CT, and runs view-test.mjs twice: one client
# at 1024^2 (the refined frame must equal `cdvol render`; latency and
# drag fps reported), and four clients at once (peak RSS reported); then
# page-test.mjs: refusals over the image with the image kept, a refused
# value marked and not sticking, the command following the controls, the
# preset menu following the file (issue 51, item 10).
#
# usage: tools/browser/ci.sh [CDVOL] [CT_SIDECAR]   (defaults:
#        target/debug/cdvol as `cargo test` left it, target/ct/cranium.json)
#        tools/browser/ci.sh --install   only installs chromium and the npm
#        package (.ci/run does it in the background while cargo builds)
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
install() {
    if ! command -v chromium >/dev/null; then
        as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
        as_root apt-get -o DPkg::Lock::Timeout=600 update -qq
        DEBIAN_FRONTEND=noninteractive as_root apt-get -o DPkg::Lock::Timeout=600 install -y -q chromium >/dev/null
    fi
    (cd "$root/tools/browser" && npm ci --no-audit --no-fund --silent)
}
if [ "${1:-}" = --install ]; then
    install
    exit 0
fi
cdvol=$(realpath "${1:-$root/target/debug/cdvol}")
ct=$(realpath "${2:-$root/target/ct/cranium.json}")
install
cd "$root/tools/browser"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$cdvol" -q prep "$ct" --iso 300 -o "$work/ct.cdv" >/dev/null
node view-test.mjs --cdvol "$cdvol" --file "$work/ct.cdv" --size 1024 --out "$work/one"
node view-test.mjs --cdvol "$cdvol" --file "$work/ct.cdv" --size 512 --clients 4 \
    --drags 2 --cache-mb 64 --out "$work/four"
# Issue 55: the real CT cut open by a plane and cropped, dragged and
# checked against `cdvol render --crop --clip` like the views above.
node view-test.mjs --cdvol "$cdvol" --file "$work/ct.cdv" --size 512 --drags 1 \
    --query "crop=20:220,30:230,10:150&clip=0,1,0,125" --out "$work/cut"
# The CT is prepared at iso 300: page-test's refused iso is 200. Its
# second file is the MR phantom prepared with the MR preset mr-default
# (the file's look), so switching files switches the preset menu's
# modality; the CT again where the binary has no MR phantom.
second=$work/ct.cdv
if "$cdvol" phantom mr --help >/dev/null 2>&1; then
    "$cdvol" -q phantom mr -o "$work/mr.json" --dims 96,96,72 >/dev/null
    "$cdvol" -q prep "$work/mr.json" --preset mr-default -o "$work/mr.cdv" >/dev/null
    second=$work/mr.cdv
fi
node page-test.mjs --cdvol "$cdvol" --file "$work/ct.cdv" --file2 "$second" --out "$work/page"
