#!/bin/sh
# The simulator against the real runtime (docs/results.md, "Validation"): renders the shipped
# scene with 2 and 4 in-process peers, recording its cost trace, then simulates each render
# from its own trace and statistics and compares frame times and initial tile sets.
# Wall-clock times differ from run to run and with whatever else the machine is doing; run
# it on an idle machine. From the repository root:
#
#     sh docs/results/validate.sh
set -eu
cargo build --release --bin tessera
T=target/release/tessera
R=docs/results
SCENE=scenes/glass-cluster-pan/glass-cluster-pan.toml
for P in 2 4; do
    OUT=$(mktemp -d)
    mkdir -p $R/validation-$P
    $T render $SCENE --peers $P --out "$OUT" --stats "$OUT/stats.json" --trace "$OUT/trace.jsonl"
    # Counted work is deterministic: the render's trace is the committed one, block for block.
    tail -n +2 "$OUT/trace.jsonl" > "$OUT/costs"
    tail -n +2 $R/glass-cluster-pan.jsonl | cmp - "$OUT/costs" && echo "the render's costs equal the committed trace's"
    $T simulate "$OUT/trace.jsonl" --validate "$OUT/stats.json" --out $R/validation-$P \
        | tee $R/validation-$P/validation.txt
    rm -r "$OUT"
done
