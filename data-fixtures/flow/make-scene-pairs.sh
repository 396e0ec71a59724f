#!/usr/bin/env bash
# Renders the 44 scenes whose frame pairs trained the shipped flow weights' run 4
# (data-fixtures/flow/README.md): the synthetic benchmark's generator with seeds 101-144 (the
# benchmark itself is seed 0, texture seed 0, so it stays held out), 50 frames of 256x256, 8
# sub-frames per exposure, no event-only flow; speed, camera distance and camera height vary with
# the scene number i: speed = (slow, medium, fast)[i mod 3], distance = 2.0 + 0.12 * (7i mod 11) m,
# height = 1.0 + 0.1 * (5i mod 7) m. Scenes 101-140 are the training pairs, 141-144 validation.
# About 5 minutes and 4.4 GB (the event streams are most of it and are not used).
#
# Usage: data-fixtures/flow/make-scene-pairs.sh OUT_DIR   (from the repository root)
set -euo pipefail
out=${1:?usage: make-scene-pairs.sh OUT_DIR}
speeds=(slow medium fast)
cargo build --release -p xtask
for i in $(seq 1 44); do
  seed=$((100 + i))
  dist=$(awk -v i="$i" 'BEGIN { printf "%.2f", 2.0 + 0.12 * ((7 * i) % 11) }')
  height=$(awk -v i="$i" 'BEGIN { printf "%.2f", 1.0 + 0.1 * ((5 * i) % 7) }')
  target/release/xtask synth --out "$out/s$seed" --seed "$seed" --texture-seed "$seed" \
    --frames 50 --subframes 8 --event-flow false --speed "${speeds[$((i % 3))]}" \
    --camera-distance "$dist" --camera-height "$height" > "$out/s$seed.log"
  echo "scene $seed done"
done
