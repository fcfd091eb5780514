#!/usr/bin/env python3
"""What a dying or frozen peer costs a real cluster: the slowest frame against the median frame.

Why: the tail issue's target is that a peer SIGKILLed mid-frame, and a peer stopped for 6 s and
then resumed, each add at most 15% to the slowest frame against the median frame, with frames
bit-identical to a 1-peer render. Before backups of overdue work, the owner waited out its 10 s
silence timeout for the dead peer's tiles.

Set-up (the issue's): `tessera serve` plus three `tessera peer` processes, one rendering thread
each, on loopback with mutual TLS; the Cornell box, 4 frames of 160x120 at 256 spp. Three runs:

  calm     nobody is disturbed
  kill     peer 3 gets SIGKILL during frame 1 (as soon as the owner prints that frame 0 is done)
  stop     peer 3 gets SIGSTOP during frame 1, and SIGCONT 6 s later
  term     peer 3 gets SIGTERM during frame 1 (preemption): it hands back what it has not started
           and leaves

For each run the script prints each frame's seconds from stats.json (what it added to the render:
from the frame before it completing to its own completion, the first frame from being dealt),
the slowest frame over the median, and whether every frame is bit-identical
to a 1-peer render of the same frames (the EXR files compared byte for byte).

Usage (from the repository root, after `cargo build --release`):
    python3 scripts/faults_bench.py --out out/bench/faults
"""

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

SIZE = ["--width", "160", "--height", "120", "--spp", "256", "--frames", "4"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="scenes/cornell-box/cornell-box.toml")
    parser.add_argument("--tessera", default="target/release/tessera")
    parser.add_argument("--out", default="out/bench/faults", type=Path)
    parser.add_argument("--port", type=int, default=47331)
    parser.add_argument("--runs", default="calm,kill,stop,term")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    certs = args.out / "certs"
    if not (certs / "ca.pem").exists():
        subprocess.run([args.tessera, "keygen", "--out", str(certs), "--peers", "4"], check=True, capture_output=True)
    reference = args.out / "reference"
    if not (reference / "frame-0003.exr").exists():
        subprocess.run([args.tessera, "render", args.scene, *SIZE, "--peers", "1", "--threads", "1", "--out", str(reference)],
                       check=True, capture_output=True)
    print(f"load average {os.getloadavg()[0]:.2f}")
    for name in args.runs.split(","):
        out = args.out / name
        seconds, identical = run(name, out, certs, reference, args)
        median = statistics.median(seconds)
        print(f"{name:<5} frames {', '.join(f'{s:.2f}' for s in seconds)} s; slowest / median {max(seconds) / median:.3f}; "
              f"bit-identical to 1 peer: {identical}; load {os.getloadavg()[0]:.2f}")


def run(name, out, certs, reference, args):
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("frame-*"):
        old.unlink()
    serve = subprocess.Popen(
        [args.tessera, "serve", args.scene, *SIZE, "--listen", f"127.0.0.1:{args.port}", "--expect", "3",
         "--threads", "1", "--certs", str(certs), "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env={**os.environ, "NO_COLOR": "1"})
    peers = [
        subprocess.Popen([args.tessera, "peer", "--join", f"127.0.0.1:{args.port}", "--listen", "127.0.0.1:0",
                          "--threads", "1", "--index", str(index), "--certs", str(certs)],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for index in (1, 2, 3)
    ]
    victim = peers[2]
    frame0 = threading.Event()

    def read():
        for line in serve.stderr:
            if "frame 0 done" in line:
                frame0.set()

    threading.Thread(target=read, daemon=True).start()
    if name != "calm":
        frame0.wait(timeout=300)
        time.sleep(0.5)
        if name == "kill":
            victim.send_signal(signal.SIGKILL)
        elif name == "term":
            victim.send_signal(signal.SIGTERM)
        else:
            victim.send_signal(signal.SIGSTOP)
            time.sleep(6.0)
            victim.send_signal(signal.SIGCONT)
    serve.wait(timeout=600)
    for peer in peers:
        try:
            peer.wait(timeout=30)
        except subprocess.TimeoutExpired:
            peer.kill()
    stats = json.loads((out / "stats.json").read_text())
    # Frames overlap (the next is dealt before the last ends), so what a frame adds to the
    # render is the time from the frame before it completing to its own completion; the first
    # frame's is its own time from being dealt.
    frames = stats["frames"]
    seconds = [frames[0]["seconds"]] + [
        b["completed_at"] - a["completed_at"] for a, b in zip(frames, frames[1:])
    ]
    identical = all((out / f.name).read_bytes() == f.read_bytes() for f in sorted(reference.glob("frame-*.exr")))
    return seconds, identical


if __name__ == "__main__":
    sys.exit(main())
