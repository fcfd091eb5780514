#!/bin/bash
# Whether two tessera binaries render the same bits: each scene at 96x96, 4 spp, with
# `--effects auto` and `--effects all`, by both, and the EXR files compared byte for byte (the
# header carries the render hash of scene and parameters, the same for both binaries).
#
# Usage (from the repository root): scripts/same_bits.sh BASE_TESSERA NEW_TESSERA SCENE.toml...
# A scene named glass-cluster-pan renders its first three frames (its camera moves), others one.
set -e
base=$1; new=$2; shift 2
out=$(mktemp -d)
for scene in "$@"; do
  name=$(basename "$scene" .toml)
  frames=1; [ "$name" = glass-cluster-pan ] && frames=3
  for mode in auto all; do
    for which in base new; do
      bin=$base; [ $which = new ] && bin=$new
      "$bin" render "$scene" --effects $mode --width 96 --height 96 --spp 4 --frames $frames \
        --threads 2 --out "$out/$name-$mode-$which" > /dev/null 2>&1
    done
    for f in "$out/$name-$mode-base"/frame-*.exr; do
      if cmp -s "$f" "$out/$name-$mode-new/$(basename "$f")"; then same="same bytes"; else same="DIFFERENT"; fi
      echo "$name --effects $mode $(basename "$f"): $same"
    done
  done
done
rm -rf "$out"
