#!/usr/bin/env python3
"""What kinds of instructions a run of one binary executes: loads, stores, integer and vector
arithmetic, shuffles, branches, counted by callgrind and classified from the disassembly.

Why this script exists: these machines have no hardware counters, so whether a render is bound
by the processor's width (instructions per cycle near what it can issue), by one kind of port,
or by waiting (latencies, misses) cannot be read from `perf stat`. callgrind counts every
instruction exactly, and its per-instruction counts (`--dump-instr=yes`) together with the
disassembly give the mix; with the run's time and the clock (`--clock`) the script prints
instructions per cycle and the lower bounds that the issue width and each class of ports put on
the cycles. docs/bench.md (issue 12, twenty-seventh round) reads them.

The port model is Intel's Golden Cove / Raptor Cove (Sapphire and Emerald Rapids, the Xeons of
docs/bench.md): six micro-operations renamed per cycle, five ALU ports of which three also run
vector work, three loads and two stores per cycle. A bound is only a bound: an instruction is
counted as one operation, and the classes share ports.

Usage (from the repository root):
    valgrind --tool=callgrind --dump-instr=yes --callgrind-out-file=OUT \\
        target/release/tessera bench SCENE.toml --width 64 --height 64 --threads 1 --spp 12
    python3 scripts/instruction_mix.py OUT target/release/tessera [--per N] [--cycles C]
`--per N` divides the counts by N (samples, say); `--cycles C` is the measured cycles per
that unit, for instructions per cycle and the share of each bound.
"""

import argparse
import collections
import re
import subprocess

# Per-cycle throughput of each class of ports (see the module's comment).
ISSUE_WIDTH = 6
ALU_PORTS = 5
VECTOR_PORTS = 3
LOADS_PER_CYCLE = 3
STORES_PER_CYCLE = 2


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("callgrind_out")
    parser.add_argument("binary")
    parser.add_argument("--per", type=float, default=1.0, help="divide the counts by this (e.g. samples)")
    parser.add_argument("--cycles", type=float, help="measured cycles per unit of --per")
    args = parser.parse_args()
    counts = executed(args.callgrind_out, args.binary)
    code = disassembly(args.binary)
    classes = collections.Counter()
    total = 0
    for address, n in counts.items():
        if address in code:
            total += n
            for c in classify(*code[address]):
                classes[c] += n
    per = args.per
    print(f"instructions: {total / per:,.1f} per unit")
    for name, n in classes.most_common():
        print(f"  {name:14s} {n / per:12,.1f}  {n / total * 100:5.1f} %")
    alu = classes["integer"] + classes["branch"] + classes["vector"] + classes["vector shuffle"] + classes["vector move"]
    bounds = {
        "issue width": total / ISSUE_WIDTH,
        "ALU ports": alu / ALU_PORTS,
        "vector ports": (classes["vector"] + classes["vector shuffle"] + classes["vector move"]) / VECTOR_PORTS,
        "loads": classes["load"] / LOADS_PER_CYCLE,
        "stores": classes["store"] / STORES_PER_CYCLE,
    }
    print("lower bounds on cycles:")
    for name, cycles in bounds.items():
        share = f"  {cycles / per / args.cycles * 100:5.1f} % of the measured cycles" if args.cycles else ""
        print(f"  {name:14s} {cycles / per:12,.1f}{share}")
    if args.cycles:
        print(f"instructions per cycle: {total / per / args.cycles:.2f}")


def executed(path, binary):
    """{instruction address: times executed} of `binary`'s own code in a callgrind output
    written with `--dump-instr=yes` (the cost lines' first position is the instruction)."""
    counts = collections.Counter()
    names, current, position, call_line = {}, None, 0, False
    with open(path) as f:
        for line in f:
            named = re.match(r"c?ob=\((\d+)\) (.*)", line.strip())
            if named:
                names[named.group(1)] = named.group(2)
            if line.startswith("ob="):
                current = names.get(re.match(r"ob=\((\d+)\)", line).group(1))
                continue
            if line.startswith("calls="):
                # The next cost line is the call's inclusive cost, not this code's own.
                call_line = True
                continue
            if not line[:1] or line[0] not in "0123456789+-*":
                continue
            fields = line.split()
            step = fields[0]
            if step.startswith("0x"):
                position = int(step, 16)
            elif step[0] in "+-":
                position += int(step)
            if call_line:
                call_line = False
                continue
            if current and current.endswith(binary.split("/")[-1]) and len(fields) >= 3:
                counts[position] += int(fields[2])
    return counts


def disassembly(binary):
    """{address: (mnemonic, operands)} from `objdump -d` (AT&T syntax)."""
    text = subprocess.run(["objdump", "-d", "--no-show-raw-insn", binary], capture_output=True, text=True, check=True).stdout
    code = {}
    for line in text.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s+(\S+)\s*(.*)", line)
        if m:
            code[int(m.group(1), 16)] = (m.group(2), m.group(3))
    return code


def classify(mnemonic, operands):
    """The classes one instruction counts in: a load or a store where it touches memory, and
    the kind of work it does (an instruction that only moves a value to or from memory does
    none beyond that)."""
    memory = "(" in operands and not mnemonic.startswith(("lea", "nop"))
    destination = operands.split(",")[-1]
    classes = []
    if mnemonic == "push" or (memory and "(" in destination and mnemonic.startswith(("mov", "vmov"))):
        classes.append("store")
    elif mnemonic == "pop" or (memory and not mnemonic.startswith("prefetch")):
        classes.append("load")
    vector = mnemonic.startswith("v") or "xmm" in operands or "ymm" in operands or "zmm" in operands
    base = mnemonic[1:] if mnemonic.startswith("v") else mnemonic
    if mnemonic.startswith("j") or mnemonic in ("call", "ret"):
        classes.append("branch")
    elif mnemonic.startswith("prefetch"):
        classes.append("prefetch")
    elif vector:
        if re.match(r"(div|sqrt)", base):
            classes.append("vector divide")
        elif re.match(r"(shuf|unpck|perm|insert|extract|blend|broadcast|movlhps|movhlps|movs[lh]dup|movddup|pshuf|punpck|palignr|pextr|pinsr)", base):
            classes.append("vector shuffle")
        elif base.startswith("mov") and not memory:
            classes.append("vector move")
        elif not base.startswith("mov"):
            classes.append("vector")
    elif not (mnemonic.startswith(("mov", "push", "pop")) and memory):
        classes.append("integer")
    return classes


if __name__ == "__main__":
    main()
