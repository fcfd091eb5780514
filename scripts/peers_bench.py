#!/usr/bin/env python3
"""One process against two peers on one machine: what splitting the cores between peers costs.

Why: the runtime issue's target is that peers cost almost nothing when there is no imbalance to
fix, i.e. that on a 2-core machine two peers of one thread each finish within 5% of one process
with two threads. The three set-ups render the same scene and frames:

  one      tessera render SCENE --peers 1 --threads 2            (no network at all)
  inproc   tessera render SCENE --peers 2 --threads 2            (2 peers x 1 thread, QUIC on loopback)
  procs    tessera serve SCENE --expect 1 --threads 1  +  tessera peer --threads 1
           (2 processes, mutual TLS with certificates from `tessera keygen`)

Runs are interleaved (one, inproc, procs, one, ...) so that a change in the machine's load hits all
three alike, and each figure is the median over the repeats. For every run the script records the
render time tessera prints, the sum of the per-frame times in its stats.json (from the first
tile handed out to the last received, so without start-up), the whole command's wall time, the
CPU-seconds of the processes, and the load average. The stats of the last run of each set-up
are summarised per peer (busy/idle time, tiles rendered/stolen/given, steal requests, bytes).

Usage (from the repository root, after `cargo build --release`):
    python3 scripts/peers_bench.py --out out/bench/peers
"""

import argparse
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

SETUPS = ["one", "inproc", "procs"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="scenes/glass-cluster-pan/glass-cluster-pan.toml")
    parser.add_argument("--tessera", default="target/release/tessera")
    parser.add_argument("--out", default="out/bench/peers", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--port", type=int, default=47311, help="loopback port of `tessera serve`")
    parser.add_argument("--frames", type=int, help="render only this many frames (default: the scene's)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    certs = args.out / "certs"
    if not (certs / "ca.pem").exists():
        subprocess.run([args.tessera, "keygen", "--out", str(certs), "--peers", "2"], check=True, capture_output=True)

    runs = {setup: [] for setup in SETUPS}
    for repeat in range(args.repeats):
        for setup in SETUPS:
            out = args.out / f"{setup}-{repeat}"
            run = run_setup(setup, out, certs, args)
            runs[setup].append(run)
            print(
                f"{setup:<6} run {repeat}: {run['render_seconds']:.2f} s render, {run['frame_seconds']:.2f} s in frames, "
                f"{run['wall_seconds']:.2f} s wall, {run['cpu_seconds']:.2f} CPU-s, load {run['load_before'][0]:.2f}",
                file=sys.stderr,
            )
    summary = {}
    for setup in SETUPS:
        summary[setup] = {
            key: statistics.median(r[key] for r in runs[setup])
            for key in ("render_seconds", "frame_seconds", "wall_seconds", "cpu_seconds", "idle_share")
        }
        # How many of the machine's cores the set-up got: under other load, this is the scheduler's
        # doing, and wall times of set-ups that got different shares are not comparable.
        summary[setup]["cores_used"] = statistics.median(r["cpu_seconds"] / r["wall_seconds"] for r in runs[setup])
    base = summary["one"]
    for setup in SETUPS:
        summary[setup]["render_ratio"] = summary[setup]["render_seconds"] / base["render_seconds"]
        summary[setup]["frame_ratio"] = summary[setup]["frame_seconds"] / base["frame_seconds"]
        summary[setup]["cpu_ratio"] = summary[setup]["cpu_seconds"] / base["cpu_seconds"]
    report = {
        "scene": args.scene,
        "cores": os.cpu_count(),
        "repeats": args.repeats,
        "summary": summary,
        "runs": runs,
        "peer_stats": {setup: peer_totals(runs[setup][-1]["stats"]) for setup in SETUPS},
        "frames_of_one_run": frame_table(runs["procs"][-1]["stats"]),
    }
    (args.out / "peers.json").write_text(json.dumps(report, indent=2) + "\n")
    text = markdown(report)
    (args.out / "peers.md").write_text(text)
    print(text)


def run_setup(setup, out, certs, args):
    stats = out / "stats.json"
    common = ["--out", str(out), "--stats", str(stats)]
    if args.frames:
        common += ["--frames", str(args.frames)]
    load_before = os.getloadavg()
    cpu_before = children_cpu()
    started = time.perf_counter()
    if setup == "one":
        summary = run([args.tessera, "render", args.scene, "--peers", "1", "--threads", "2", *common])
    elif setup == "inproc":
        summary = run([args.tessera, "render", args.scene, "--peers", "2", "--threads", "2", *common])
    else:
        summary = run_cluster(out, certs, common, args)
    wall = time.perf_counter() - started
    data = json.loads(stats.read_text())
    match = re.search(r"rendered (\d+) frames .* in ([0-9.]+) s \(", summary)
    if not match:
        raise SystemExit(f"{setup}: no summary line in: {summary!r}")
    slots = [p for f in data["frames"] for p in f["peers"]]
    busy, idle = sum(p["busy_seconds"] for p in slots), sum(p["idle_seconds"] for p in slots)
    return {
        "setup": setup,
        "frames": int(match.group(1)),
        "render_seconds": float(match.group(2)),
        "frame_seconds": sum(f["seconds"] for f in data["frames"]),
        "wall_seconds": wall,
        "cpu_seconds": children_cpu() - cpu_before,
        # Of the rendering threads' slot-time within frames, the share spent waiting for work.
        "idle_share": idle / (busy + idle) if busy + idle > 0 else 0.0,
        "load_before": load_before,
        "load_after": os.getloadavg(),
        "summary": summary.strip(),
        "stats": data,
    }


def run_cluster(out, certs, common, args):
    """`tessera serve` and one `tessera peer`, each with one rendering thread."""
    out.mkdir(parents=True, exist_ok=True)
    log = open(out / "serve.log", "w")
    address = f"127.0.0.1:{args.port}"
    serve = subprocess.Popen(
        [args.tessera, "serve", args.scene, "--listen", address, "--certs", str(certs), "--expect", "1",
         "--threads", "1", *common],
        stdout=subprocess.PIPE, stderr=log, text=True,
    )
    deadline = time.monotonic() + 60
    while "listening on" not in (out / "serve.log").read_text():
        if serve.poll() is not None or time.monotonic() > deadline:
            serve.kill()
            raise SystemExit(f"tessera serve did not start listening; see {out / 'serve.log'}")
        time.sleep(0.02)
    peer = subprocess.Popen(
        [args.tessera, "peer", "--join", address, "--certs", str(certs), "--index", "1", "--threads", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    summary, _ = serve.communicate(timeout=600)
    peer_out, peer_err = peer.communicate(timeout=60)
    log.close()
    if serve.returncode != 0 or peer.returncode != 0:
        raise SystemExit(f"cluster run failed: serve {serve.returncode}, peer {peer.returncode}: {peer_err[-2000:]}")
    return summary


def run(command):
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed: {done.stderr[-2000:]}")
    return done.stdout


def children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def peer_totals(stats):
    """Per peer, summed over the frames of one run."""
    keys = ["busy_seconds", "idle_seconds", "tiles_rendered", "tiles_stolen", "tiles_given",
            "steal_requests_sent", "steal_requests_refused", "bytes_sent", "bytes_received"]
    totals = {}
    for frame in stats["frames"]:
        for p in frame["peers"]:
            entry = totals.setdefault(p["peer"], {"peer": p["peer"], "threads": p["threads"], **{k: 0 for k in keys}})
            for k in keys:
                entry[k] += p[k]
    return [totals[k] for k in sorted(totals)]


def frame_table(stats):
    rows = []
    for frame in stats["frames"]:
        peers = {p["peer"]: p for p in frame["peers"]}
        rows.append({
            "frame": frame["frame"],
            "seconds": frame["seconds"],
            "tiles": len(frame["tiles"]),
            "max_over_mean": frame["leaf_cost_max_over_mean"],
            "rendered": [peers[k]["tiles_rendered"] for k in sorted(peers)],
            "stolen": [peers[k]["tiles_stolen"] for k in sorted(peers)],
            "idle": [peers[k]["idle_seconds"] for k in sorted(peers)],
        })
    return rows


def markdown(report):
    s = report["summary"]
    names = {
        "one": "1 process, `--peers 1 --threads 2`",
        "inproc": "2 in-process peers, `--peers 2 --threads 2`",
        "procs": "2 processes, `serve --threads 1` + `peer --threads 1`",
    }
    lines = [
        f"Scene `{report['scene']}`, {report['cores']} cores, median of {report['repeats']} interleaved runs.",
        "",
        "| set-up | render s (tessera's summary) | vs 1 process | sum of frame s | vs 1 process | command wall s "
        "| CPU-s | vs 1 process | cores used | idle share | load avg (1 min) at start |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for setup in SETUPS:
        r = s[setup]
        loads = ", ".join(f"{run['load_before'][0]:.2f}" for run in report["runs"][setup])
        lines.append(
            f"| {names[setup]} | {r['render_seconds']:.2f} | {100 * (r['render_ratio'] - 1):+.1f}% | "
            f"{r['frame_seconds']:.2f} | {100 * (r['frame_ratio'] - 1):+.1f}% | {r['wall_seconds']:.2f} | "
            f"{r['cpu_seconds']:.2f} | {100 * (r['cpu_ratio'] - 1):+.1f}% | {r['cores_used']:.2f} | "
            f"{100 * r['idle_share']:.1f}% | {loads} |"
        )
    lines += ["", "Per-peer totals over all frames of the last run of each set-up:", "",
              "| set-up | peer | threads | busy s | idle s | tiles rendered | stolen | given | steal requests | refused | MB sent | MB received |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for setup in SETUPS:
        for p in report["peer_stats"][setup]:
            lines.append(
                f"| {setup} | {p['peer']} | {p['threads']} | {p['busy_seconds']:.2f} | {p['idle_seconds']:.2f} | "
                f"{p['tiles_rendered']} | {p['tiles_stolen']} | {p['tiles_given']} | {p['steal_requests_sent']} | "
                f"{p['steal_requests_refused']} | {p['bytes_sent'] / 1e6:.2f} | {p['bytes_received'] / 1e6:.2f} |"
            )
    lines += ["", "Frames of the last 2-process run (per peer: 0, 1):", "",
              "| frame | s | tiles | leaf max/mean | tiles rendered | stolen | idle s |", "|---|---|---|---|---|---|---|"]
    for f in report["frames_of_one_run"]:
        lines.append(
            f"| {f['frame']} | {f['seconds']:.3f} | {f['tiles']} | {f['max_over_mean']:.2f} | "
            f"{' / '.join(map(str, f['rendered']))} | {' / '.join(map(str, f['stolen']))} | "
            f"{' / '.join(f'{v:.3f}' for v in f['idle'])} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
