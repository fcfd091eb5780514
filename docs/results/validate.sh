#!/bin/sh
# The simulator against the real runtime (docs/results.md, "Validation"): renders the shipped
# scene with 2 and 4 in-process peers, recording its cost trace, then simulates each render
# from its own trace and statistics and compares frame times and initial tile sets. Three
# configurations: the defaults (PBT, stealing, tiles dealt interleaved), a regular grid without
# stealing dealt interleaved, and the same grid dealt in contiguous runs.
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
    for CASE in default regular regular-contiguous; do
        case $CASE in
            default) POLICY=pbt+steal; FLAGS=""; DIR=$R/validation-$P ;;
            regular) POLICY=regular; FLAGS="--balancer regular --no-steal"; DIR=$R/validation-$P-regular ;;
            regular-contiguous) POLICY=regular; FLAGS="--balancer regular --no-steal --deal contiguous"
                DIR=$R/validation-$P-regular-contiguous ;;
        esac
        OUT=$(mktemp -d)
        mkdir -p $DIR/fixed-rate
        # shellcheck disable=SC2086
        $T render $SCENE --peers $P $FLAGS --out "$OUT" --stats "$OUT/stats.json" --trace "$OUT/trace.jsonl"
        # Counted work is deterministic: the render's trace is the committed one, block for block.
        tail -n +2 "$OUT/trace.jsonl" > "$OUT/costs"
        tail -n +2 $R/glass-cluster-pan.jsonl | cmp - "$OUT/costs" && echo "the render's costs equal the committed trace's"
        # First with the work rate measured in this very render (busy time over counted work),
        # so that only the schedule is predicted; then with the rate fixed beforehand (the
        # simulator's default, measured by record_trace with one thread per core), shared out
        # when there are more peers than cores, so that the frame times are predicted outright.
        $T simulate "$OUT/trace.jsonl" --validate "$OUT/stats.json" --policy $POLICY \
            --out $DIR | tee $DIR/validation.txt
        RATE=$(awk -v p=$P -v c="$(nproc)" 'BEGIN { s = c / p; if (s > 1) s = 1; printf "%.4g", 1.17e8 * s }')
        $T simulate "$OUT/trace.jsonl" --validate "$OUT/stats.json" --policy $POLICY --rate "$RATE" \
            --out $DIR/fixed-rate | tee $DIR/fixed-rate/validation.txt
        rm -r "$OUT"
    done
done
