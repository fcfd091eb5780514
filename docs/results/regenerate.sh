#!/bin/sh
# Regenerates every table and chart docs/results.md quotes. From the repository root:
#
#     sh docs/results/regenerate.sh
#
# Each `tessera simulate` below writes runs.csv, frames.csv, runs.json, summary.md and SVG
# charts into its folder. The runs are deterministic (same inputs and seed, same numbers);
# only the wall-time columns change from one run of this script to the next. A few minutes on
# the 2-core development machine, most of it in the runs of 512 and 1024 stealing peers (see
# "Speed" in docs/results.md).
set -eu
cargo build --release --bin tessera
T=target/release/tessera
R=docs/results
PEERS=1,2,4,8,16,32,64,128,256,512,1024
# Every run: links of 0.1 ms one way (a LAN), one rendering slot per peer, the renderer's
# measured per-tile overhead (30 us), the default work rate (1.17e8 units/s per slot).
NET="--latency 0.1 --tile-overhead 0.03"
# STATIC: pieces keep their tile's prediction, shared by area (before section 10's re-predicting
# pieces, the default since): what sections 1 to 9 were measured with.
STATIC="--relearn-pieces false"
# Sections 1 to 6 study the seed's two mechanisms, the PBT and stealing, as they were first
# studied: every tile rendered and moved whole, no backups of stragglers (UNCUT). Section 7
# measures what cutting tiles and backups add. Sections 1 to 4 deal each peer one contiguous
# run of tiles; section 6 deals interleaved, the default since.
# STILL: each tile predicted from where the costs were (before motion compensation, section 9).
STILL="--motion off"
# BARRIER: one frame at a time, every frame cut and rendered alike (before frames in flight),
# and predicted STILL: the defaults sections 1 to 7 were measured with.
BARRIER="--frames-in-flight 1 --doubtful-pieces off $STILL"
UNCUT="--render-pieces off --split-on-steal false --backups false $BARRIER"
RUNS="--deal contiguous $UNCUT"

# The shipped uneven scene's cost trace is committed: counted work is deterministic, so
# recording it again gives the same file. To re-record it (about a minute):
#     cargo run --release -p sim --example record_trace -- \
#         scenes/glass-cluster-pan/glass-cluster-pan.toml $R/glass-cluster-pan.jsonl
# (`tessera render ... --trace FILE` records the same costs during a real render.)
GLASS=$R/glass-cluster-pan.jsonl

# Peer counts are swept at tile counts of at least the largest peer count, and tile counts
# at a few peer counts: with fewer tiles than peers the efficiency is at most tiles / peers,
# and the idle peers' stealing only costs simulation time.

# 1. The shipped scene.
$T simulate $GLASS $NET $STATIC $RUNS --peers $PEERS --tiles 1024,4096,16384 \
    --charts peers --gantt 16:pbt+steal:1024:12 --out $R/glass-peers
$T simulate $GLASS $NET $STATIC $RUNS --peers 4,16,64 --tiles 16,64,256,1024,4096,16384 \
    --charts tiles --gantt 16:pbt+steal:256:12 --out $R/glass-tiles

# 2. The synthetic trace: a hot spot orbiting a 1024x1024 image, 100 frames.
$T simulate synthetic $NET $STATIC $RUNS --peers $PEERS --tiles 4096,16384 \
    --charts peers --gantt 64:pbt+steal:4096:10 --out $R/synthetic-peers
$T simulate synthetic $NET $STATIC $RUNS --peers 16,64,256 --tiles 256,1024,4096,16384 \
    --charts tiles --out $R/synthetic-tiles

# 3. Control: the shipped scene's frame 12 held still, so that every frame after the first
#    is predicted exactly: what is left of the gaps is unevenness, not motion.
$T simulate $GLASS --hold 12 --frames 8 $NET $STATIC $RUNS --peers $PEERS --tiles 4096 \
    --charts peers --out $R/glass-still

# The same control on the synthetic trace: its frame 50 held still.
$T simulate synthetic --hold 50 --frames 10 $NET $STATIC $RUNS --peers $PEERS --tiles 4096 \
    --charts peers --out $R/synthetic-still

# 4. The shipped scene behind gigabit links: where the owner's link becomes the limit.
$T simulate $GLASS $NET $STATIC $RUNS --bandwidth 1000 --peers $PEERS --tiles 4096 \
    --charts peers --out $R/glass-gigabit

# 5. The classic static baseline: a regular grid dealt round-robin, blind to predicted cost
#    (every other run deals contiguous runs of equal predicted cost, which is already a use
#    of the PBT's predictor).
$T simulate $GLASS $NET $STATIC $UNCUT --deal round-robin --policy regular,regular+steal --peers $PEERS \
    --tiles 1024,4096 --charts peers --out $R/glass-round-robin
$T simulate synthetic $NET $STATIC $UNCUT --deal round-robin --policy regular,regular+steal \
    --peers $PEERS --tiles 4096 --charts peers --out $R/synthetic-round-robin

# 6. Dealing interleaved (the default): each tile to the peer with the least predicted work,
#    so that every peer's share is spread over the image.
$T simulate $GLASS $NET $STATIC $UNCUT --deal interleaved --peers $PEERS --tiles 1024,4096,16384 \
    --charts peers --gantt 16:pbt+steal:1024:12 --out $R/glass-interleaved
$T simulate synthetic $NET $STATIC $UNCUT --deal interleaved --peers $PEERS --tiles 4096,16384 \
    --charts peers --gantt 64:pbt+steal:4096:10 --out $R/synthetic-interleaved

# 7. The end of a frame (the defaults since): tiles rendered half by half above twice the mean
#    tile area, halved for thieves, stragglers backed up; each mechanism off in turn, both off
#    (UNCUT), and pieces of a quarter of the mean tile area. The tail issue's four set-ups.
for variant in "all:$BARRIER" "no-render-pieces:--render-pieces off $BARRIER" \
    "no-steal-split:--split-on-steal false $BARRIER" "uncut:$UNCUT" \
    "quarter-pieces:--render-pieces 0.25 $BARRIER"; do
    name=${variant%%:*}
    flags=${variant#*:}
    $T simulate synthetic $NET $STATIC $flags --policy pbt+steal --peers 64,256,1024 --tiles 4096 \
        --charts peers --out $R/tails/synthetic-$name
    $T simulate synthetic $NET $STATIC $flags --policy pbt+steal --peers 1024 --tiles 16384 \
        --charts peers --out $R/tails/synthetic-16384-$name
    $T simulate synthetic:1024x1024:20 $NET $STATIC $flags --policy pbt+steal --peers 256 --tiles 4096 \
        --charts peers --gantt 256:pbt+steal:4096:12 --out $R/tails/fast-orbit-$name
    $T simulate $GLASS $NET $STATIC $flags --policy pbt+steal --peers 64 --tiles 1024 \
        --charts peers --gantt 64:pbt+steal:1024:12 --out $R/tails/glass-$name
done
# The synthetic runs' default Gantt charts (a thousand peers' bars, megabytes each) are not kept.
rm -f $R/tails/synthetic-*/gantt.svg

# 8. Frames in flight (the defaults since): the next frame dealt when the running one wanes,
#    the prediction doubted (no overlap, pieces of 1/8 mean area) where it missed by more than
#    half; against one frame at a time (section 7's defaults), no doubting, three in flight.
for variant in "in-flight:$STILL" "barrier:$BARRIER" \
    "never-doubt:--doubt-error 2 --doubtful-pieces off $STILL" \
    "three:--frames-in-flight 3 $STILL"; do
    name=${variant%%:*}
    flags=${variant#*:}
    $T simulate synthetic $NET $STATIC $flags --policy pbt+steal --peers 64,256,1024 --tiles 4096 \
        --charts peers --out $R/frames/synthetic-$name
    $T simulate synthetic:1024x1024:20 $NET $STATIC $flags --policy pbt+steal --peers 256 --tiles 4096 \
        --charts peers --gantt 256:pbt+steal:4096:12 --out $R/frames/fast-orbit-$name
    $T simulate $GLASS $NET $STATIC $flags --policy pbt+steal --peers 64 --tiles 1024 \
        --charts peers --gantt 64:pbt+steal:1024:12 --out $R/frames/glass-$name
done
rm -f $R/frames/synthetic-*/gantt.svg

# 9. Motion-compensated prediction (the default since): the cost landscape's shift between the
#    last two measured frames carried on to the frame dealt; with frames in flight (all the
#    defaults) and with one frame at a time. Section 8's in-flight runs are the same without it.
for variant in "in-flight:" "barrier:--frames-in-flight 1 --doubtful-pieces off"; do
    name=${variant%%:*}
    flags=${variant#*:}
    $T simulate synthetic $NET $STATIC $flags --policy pbt+steal --peers 64,256,1024 --tiles 4096 \
        --charts peers --out $R/motion/synthetic-$name
    $T simulate synthetic $NET $STATIC $flags --policy pbt+steal --peers 1024 --tiles 16384 \
        --charts peers --out $R/motion/synthetic-16384-$name
    $T simulate synthetic:1024x1024:20 $NET $STATIC $flags --policy pbt+steal --peers 256 --tiles 4096 \
        --charts peers --gantt 256:pbt+steal:4096:12 --out $R/motion/fast-orbit-$name
    $T simulate $GLASS $NET $STATIC $flags --policy pbt+steal --peers 64 --tiles 1024 \
        --charts peers --gantt 64:pbt+steal:1024:12 --out $R/motion/glass-$name
done
rm -f $R/motion/synthetic-*/gantt.svg

# 10. Pieces that re-predict their tile (the default since): a peer scales the prediction of
#     the rest of a tile by what its first pieces took against their prediction, and renders a
#     tile found hot in finer pieces. All the defaults, with and without it.
for variant in "relearn:" "static:$STATIC"; do
    name=${variant%%:*}
    flags=${variant#*:}
    $T simulate synthetic $NET $flags --policy pbt+steal --peers 64,256,1024 --tiles 4096 \
        --charts peers --out $R/relearn/synthetic-$name
    $T simulate synthetic $NET $flags --policy pbt+steal --peers 1024 --tiles 16384 \
        --charts peers --out $R/relearn/synthetic-16384-$name
    $T simulate synthetic:1024x1024:20 $NET $flags --policy pbt+steal --peers 256 --tiles 4096 \
        --charts peers --gantt 256:pbt+steal:4096:0 --out $R/relearn/fast-orbit-$name
    $T simulate $GLASS $NET $flags --policy pbt+steal --peers 64 --tiles 1024 \
        --charts peers --gantt 64:pbt+steal:1024:12 --out $R/relearn/glass-$name
done
rm -f $R/relearn/synthetic-*/gantt.svg

# 11. The seed's claims (sections 1 to 3) again with every default of today: interleaved deal,
#     tiles cut on the way, backups, frames in flight, motion compensation, re-predicting
#     pieces; every policy.
$T simulate $GLASS $NET --peers 4,16,64,256 --tiles 1024,4096 --charts peers \
    --out $R/defaults/glass
$T simulate synthetic $NET --peers 16,64,256 --tiles 4096 --charts peers \
    --out $R/defaults/synthetic
$T simulate $GLASS $NET --peers 4,16,64 --tiles 16,64,256,1024,4096,16384 --charts tiles \
    --out $R/defaults/glass-tiles
