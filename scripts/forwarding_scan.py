#!/usr/bin/env python3
"""Where a binary's hot code may read back, at once, a value that narrower stores just wrote.

A load that spans two stores still in the store buffer (or is wider than the one store it
overlaps) cannot be forwarded from them: it waits until they reach the cache, some ten to
twenty cycles. In tessera the pattern has come from structs returned through memory (a ray, a
light sample, a BSDF) and read back whole by the caller, and from arrays filled a float at a
time and read as vectors (docs/bench.md, issue 12, nineteenth, twenty-second and twenty-sixth
rounds). This lists candidates for a look with `perf annotate`; it proves nothing by itself.

Two scans over `objdump -d` of the functions whose demangled names contain a pattern:
- after a call whose return slot is on the stack (`lea OFF(%rsp),%rdi` just before it), the
  loads of 8 bytes or more from that slot among the next few instructions: compare them with
  the callee's stores to its return pointer;
- within straight-line code, a load from the stack that overlaps stores made shortly before
  and lies within none of them.

Usage: scripts/forwarding_scan.py BINARY PATTERN... (e.g. target/release/tessera
radiance_from render_tile traverse_avx packet_avx)
"""

import re
import subprocess
import sys

FOUR = ('movss', 'vmovss', 'movd', 'vmovd', 'movl')
EIGHT = ('movsd', 'vmovsd', 'movq', 'vmovq', 'movlps', 'vmovlps', 'movhps', 'vmovhps')
SIXTEEN = ('movups', 'movaps', 'vmovups', 'vmovaps', 'movdqu', 'movdqa', 'vmovdqu', 'vmovdqa')
# The loads of eight bytes or more that the scan after calls looks for.
WIDE_LOADS = EIGHT + SIXTEEN + ('vinsertf128',)
STACK = re.compile(r'(-?0x[0-9a-f]+|)\(%rsp\)')


def functions(binary, patterns):
    """(start, size, name) of the defined functions whose names contain a pattern."""
    listing = subprocess.run(['nm', '-C', '--defined-only', '-S', binary],
                             capture_output=True, text=True, check=True).stdout
    for line in listing.splitlines():
        parts = line.split(None, 3)
        if len(parts) == 4 and parts[2] in 'tT' and any(p in parts[3] for p in patterns):
            yield int(parts[0], 16), int(parts[1], 16), parts[3]


def instructions(binary, start, size):
    text = subprocess.run(['objdump', '-d', '--no-show-raw-insn', '--start-address=%#x' % start,
                           '--stop-address=%#x' % (start + size), binary],
                          capture_output=True, text=True, check=True).stdout
    for line in text.splitlines():
        m = re.match(r'^\s*([0-9a-f]+):\s+(\S+)\s*(.*)', line)
        if m:
            yield m.groups()


def width(op, args):
    """Bytes a vector or plain move reads or writes; None where this scan does not know."""
    if op in ('vinsertf128', 'vbroadcastf128'):
        return 16
    if op.startswith('v') and '%ymm' in args:
        return 32
    for names, size in ((FOUR, 4), (EIGHT, 8), (SIXTEEN, 16)):
        if op in names:
            return size
    if op == 'mov':
        registers = [r for r in re.findall(r'%(\w+)', args) if r not in ('rsp', 'rip')]
        if not registers:
            return None
        r = registers[0]
        if re.match(r'r(\d+|[a-d]x|[sd]i|bp)$', r):
            return 8
        if r.startswith('e') or re.match(r'r\d+d$', r):
            return 4
    return None


def callee_names(binary):
    """What each GOT slot calls, by name: the binary is position-independent, so its calls
    between functions go through slots that relocations fill."""
    relocations = subprocess.run(['readelf', '-rW', binary], capture_output=True, text=True,
                                 check=True).stdout
    slots = {}
    for line in relocations.splitlines():
        parts = line.split()
        if len(parts) >= 4 and re.fullmatch(r'[0-9a-f]{16}', parts[0]) and 'RELATIVE' in line:
            slots[int(parts[0], 16)] = int(parts[-1], 16)
    targets = sorted(set(slots.values()))
    names = subprocess.run(['addr2line', '-f', '-C', '-e', binary] + [hex(t) for t in targets],
                           capture_output=True, text=True).stdout.splitlines()[::2]
    by_target = dict(zip(targets, names))
    return {slot: by_target.get(target, hex(target)) for slot, target in slots.items()}


def after_calls(code, name, callees):
    for i, (addr, op, args) in enumerate(code):
        if not op.startswith('call'):
            continue
        slot = None
        for _, op0, args0 in code[max(0, i - 10):i]:
            m = re.match(r'(0x[0-9a-f]+)\(%rsp\),%rdi', args0)
            if op0 == 'lea' and m:
                slot = int(m.group(1), 16)
        if slot is None:
            continue
        for addr2, op2, args2 in code[i + 1:i + 8]:
            if op2.startswith(('call', 'j', 'ret')):
                break
            m = STACK.search(args2)
            if op2 in WIDE_LOADS and m and m.group(1) and 0 <= int(m.group(1), 16) - slot < 64:
                got = re.search(r'# ([0-9a-f]+) <', args)
                callee = callees.get(int(got.group(1), 16)) if got else None
                callee = callee or args.split('<')[-1].rstrip('>')
                print(f'{name[:60]}: {addr2} {op2} {args2}  (after {addr} call {callee[:70]})')


def within_blocks(code, name):
    stores = []
    for index, (addr, op, args) in enumerate(code):
        if op.startswith(('call', 'ret')):
            stores = []
            continue
        m = STACK.search(args)
        size = width(op, args)
        if not m or size is None or op.startswith('j'):
            continue
        offset = int(m.group(1), 16) if m.group(1) else 0
        if STACK.search(args.split(',')[-1]):
            stores = (stores + [(index, offset, size)])[-40:]
            continue
        overlapping = [s for s in stores
                       if s[1] < offset + size and offset < s[1] + s[2] and index - s[0] < 40]
        if overlapping and not any(s[1] <= offset and offset + size <= s[1] + s[2]
                                   for s in overlapping):
            spans = ', '.join(f'{s[2]} bytes at {s[1]:#x}' for s in overlapping)
            print(f'{name[:60]}: {addr} {op} {args}  (over stores of {spans})')


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    binary, patterns = sys.argv[1], sys.argv[2:]
    callees = callee_names(binary)
    for start, size, name in functions(binary, patterns):
        code = list(instructions(binary, start, size))
        after_calls(code, name, callees)
        within_blocks(code, name)


if __name__ == '__main__':
    main()
