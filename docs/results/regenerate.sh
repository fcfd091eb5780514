#!/bin/sh
# Regenerates every table and chart docs/results.md quotes. From the repository root:
#
#     sh docs/results/regenerate.sh
#
# Each `tessera simulate` below writes runs.csv, frames.csv, runs.json, summary.md and SVG
# charts into its folder. The runs are deterministic (same inputs and seed, same numbers);
# only the wall-time columns change from one run of this script to the next.
set -eu
cargo build --release --bin tessera
T=target/release/tessera
R=docs/results
PEERS=1,2,4,8,16,32,64,128,256,512,1024

# The shipped uneven scene's cost trace is committed: counted work is deterministic, so
# recording it again gives the same file. To re-record it (about a minute):
#     cargo run --release -p sim --example record_trace -- \
#         scenes/glass-cluster-pan/glass-cluster-pan.toml $R/glass-cluster-pan.jsonl
# (`tessera render ... --trace FILE` records the same costs during a real render.)
GLASS=$R/glass-cluster-pan.jsonl

# Peer counts are swept at tile counts of at least the largest peer count, and tile counts
# at a few peer counts: with fewer tiles than peers the efficiency is at most tiles / peers,
# and the idle peers' stealing only costs simulation time.

# 1. The shipped scene on a LAN (0.1 ms one way).
$T simulate $GLASS --peers $PEERS --tiles 1024,4096,16384 --latency 0.1 \
    --charts peers --gantt 16:pbt+steal:1024:12 --out $R/glass-peers
$T simulate $GLASS --peers 4,16,64 --tiles 16,64,256,1024,4096,16384 --latency 0.1 \
    --charts tiles --gantt 16:pbt+steal:256:12 --out $R/glass-tiles

# 2. The synthetic trace: a hot spot orbiting a 1024x1024 image (the first 20 of 100 frames).
$T simulate synthetic --frames 20 --peers $PEERS --tiles 4096,16384 --latency 0.1 \
    --charts peers --gantt 64:pbt+steal:4096:10 --out $R/synthetic-peers
$T simulate synthetic --frames 20 --peers 16,64,256 --tiles 256,1024,4096,16384 \
    --latency 0.1 --charts tiles --out $R/synthetic-tiles

# 3. The shipped scene behind gigabit links: where the owner's link becomes the limit.
$T simulate $GLASS --peers $PEERS --tiles 4096 --latency 0.1 --bandwidth 1000 \
    --charts peers --out $R/glass-gigabit
