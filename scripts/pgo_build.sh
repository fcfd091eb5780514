#!/bin/bash
# A profile-guided (PGO) build of the tessera binary, for speed comparisons and for users who want
# the fastest binary: instrument, train on the scenes the repository ships, merge, rebuild.
#
# Usage (from the repository root): scripts/pgo_build.sh
# Leaves the binary at target/pgo/release/tessera; the plain `cargo build --release` is untouched.
#
# Why it is safe for determinism: a profile changes which code LLVM inlines, how it lays out
# blocks and which branch it makes the fall-through, never the floating-point operations a
# function performs (Rust enables neither fast-math nor FMA contraction, with or without a
# profile), so a PGO binary renders the same bytes; `scripts/same_bits.sh` checks that.
#
# Why it trains on the shipped scenes only: the comparisons with Mitsuba 3 render the scenes in
# `scenes/shared/`, and a profile taken from the very scenes it is measured on would flatter it.
# The shipped scenes cover every effect and both the primary and the path passes.
#
# Needs `llvm-profdata` of the LLVM that rustc uses: `rustup component add llvm-tools`.
set -euo pipefail
llvm_version=$(rustc -vV | sed -n 's/^LLVM version: //p')
profdata=$(find "$(rustc --print sysroot)" -name llvm-profdata -type f | head -n 1)
if [ -z "$profdata" ]; then
  echo "error: llvm-profdata not found in rustc's sysroot (LLVM $llvm_version);" \
       "install it with: rustup component add llvm-tools" >&2
  exit 1
fi
# A fixed folder, so that the flags below stay the same from one run to the next and cargo
# rebuilds only what changed; the raw counts of an earlier run are removed first.
data=$PWD/target/pgo-data
rm -rf "$data"
mkdir -p "$data/raw"

echo "1/4: instrumented build (target/pgo-generate)"
RUSTFLAGS="-Cprofile-generate=$data/raw" \
  cargo build --release --bin tessera --target-dir target/pgo-generate

echo "2/4: training on the shipped scenes"
# Small images, a few samples: the profile counts which branches are taken, not how long the
# render takes, and these counts settle within a few thousand paths per scene.
# `scenes/shared/*.toml` (the scenes the comparisons measure) are left out: see above.
shipped=$(ls scenes/*/*.toml | grep -v '^scenes/shared/')
# shellcheck disable=SC2086 # one argument per scene file; no scene path has spaces.
LLVM_PROFILE_FILE="$data/raw/tessera-%m-%p.profraw" target/pgo-generate/release/tessera bench \
  $shipped --width 96 --height 96 --spp 4 --threads 2 > /dev/null
# A short render through the peers, so the scheduling and output paths are in the profile too.
LLVM_PROFILE_FILE="$data/raw/tessera-%m-%p.profraw" \
  target/pgo-generate/release/tessera render scenes/cornell-box/cornell-box.toml \
  --width 64 --height 64 --spp 2 --peers 2 --out "$data/render" > /dev/null

echo "3/4: merging the profile"
"$profdata" merge -o "$data/tessera.profdata" "$data/raw"
# cargo does not see a profile's contents change, only the flags: the profile's checksum in the
# flags rebuilds the crates when the counts differ, and only then.
sum=$(cksum < "$data/tessera.profdata" | cut -d' ' -f1)

echo "4/4: optimised build (target/pgo)"
mv "$data/tessera.profdata" "$data/tessera-$sum.profdata"
RUSTFLAGS="-Cprofile-use=$data/tessera-$sum.profdata" \
  cargo build --release --bin tessera --target-dir target/pgo
echo "done: target/pgo/release/tessera"
