//! The summary of a sweep, in Markdown, organised by the seed's three claims: how efficiency
//! scales with peers for each policy at equal tile counts, which tile count is best for each
//! policy at each peer count, and whether the PBT with stealing beats each alone.
//!
//! The numbers are the runs' totals over all frames (see [`crate::report`]); the tables say
//! what the runs measured and nothing else, so that `docs/results.md` can quote them whichever
//! way they come out.

use std::fmt::Write as _;

use balancer::Kind;

use crate::report::RunReport;
use crate::{Policy, Sweep};

/// Efficiency over the frames after the first: work over capacity-time, as for the whole run.
fn after_first(run: &RunReport) -> f64 {
    let later = run.frames.iter().skip(1);
    let work: f64 = later.clone().map(|f| f.work).sum();
    let time: f64 = later.map(|f| f.capacity * f.makespan).sum();
    if time > 0.0 { work / time } else { 0.0 }
}

/// The head of a table with one row per peer count and one column per policy.
fn policy_header(out: &mut String, policies: &[Policy]) {
    let _ = write!(out, "| peers |");
    for policy in policies {
        let _ = write!(out, " {policy} |");
    }
    let _ = writeln!(out, "\n|---:|{}", "---:|".repeat(policies.len()));
}

/// `summary.md` of a sweep whose runs follow [`Sweep::combinations`]; `title` says what was
/// simulated (the trace and the scenario).
pub fn markdown(title: &str, sweep: &Sweep, runs: &[RunReport]) -> String {
    let combinations = sweep.combinations();
    let find = |tiles: usize, policy: Policy, peers: usize| {
        combinations
            .iter()
            .position(|c| *c == (tiles, policy, peers))
            .map(|i| &runs[i])
    };
    let mut out = String::new();
    let _ = writeln!(out, "# {title}\n");
    let _ = writeln!(
        out,
        "Efficiency = work / (capacity x makespan) over all frames; in brackets, the efficiency a \
         schedule reaching the lower bound would have: work / capacity where tiles can be cut \
         on the way, else max(work / capacity, largest tile).\n"
    );

    let predicted = runs.iter().all(|r| r.frames.len() > 1);
    for &tiles in &sweep.tiles {
        let _ = writeln!(out, "## Efficiency vs peers, {tiles} tiles requested\n");
        if predicted {
            let _ = writeln!(
                out,
                "In each cell: all frames (bound), then the frames after the first, which every \
                 balancer deals from a measured prediction rather than from pixel area.\n"
            );
        }
        policy_header(&mut out, &sweep.policies);
        for &peers in &sweep.peers {
            let _ = write!(out, "| {peers} |");
            for &policy in &sweep.policies {
                if let Some(run) = find(tiles, policy, peers) {
                    let _ = write!(out, " {:.3} ({:.3})", run.efficiency, run.bound_efficiency);
                    if predicted {
                        let _ = write!(out, " · {:.3}", after_first(run));
                    }
                    let _ = write!(out, " |");
                }
            }
            let _ = writeln!(out);
        }
        let _ = writeln!(out);
    }

    if sweep.tiles.len() > 1 {
        let _ = writeln!(out, "## Best tile count per peer count\n");
        let _ = writeln!(
            out,
            "For each policy, the requested tile count with the highest efficiency (ties: the \
             fewest tiles), and that efficiency.\n"
        );
        policy_header(&mut out, &sweep.policies);
        for &peers in &sweep.peers {
            let _ = write!(out, "| {peers} |");
            for &policy in &sweep.policies {
                let best = sweep
                    .tiles
                    .iter()
                    .filter_map(|&m| find(m, policy, peers).map(|r| (m, r.efficiency)))
                    .fold(None, |best: Option<(usize, f64)>, (m, e)| match best {
                        Some((_, b)) if b >= e => best,
                        _ => Some((m, e)),
                    });
                if let Some((m, e)) = best {
                    let _ = write!(out, " {m} ({e:.3}) |");
                }
            }
            let _ = writeln!(out);
        }
        let _ = writeln!(out);
    }

    let both = Policy {
        kind: Kind::Pbt,
        steal: true,
    };
    let alone = [
        Policy {
            kind: Kind::Pbt,
            steal: false,
        },
        Policy {
            kind: Kind::Regular,
            steal: true,
        },
    ];
    if sweep.policies.contains(&both) && alone.iter().any(|p| sweep.policies.contains(p)) {
        let _ = writeln!(out, "## PBT with stealing against each alone\n");
        let _ = writeln!(
            out,
            "Gain = efficiency of pbt+steal minus the better of pbt and regular+steal.\n"
        );
        let _ = writeln!(
            out,
            "| tiles | peers | pbt+steal | pbt | regular+steal | gain |"
        );
        let _ = writeln!(out, "|---:|---:|---:|---:|---:|---:|");
        let (mut wins, mut total) = (0, 0);
        for &tiles in &sweep.tiles {
            for &peers in &sweep.peers {
                let Some(with) = find(tiles, both, peers) else {
                    continue;
                };
                let others: Vec<Option<f64>> = alone
                    .iter()
                    .map(|&p| find(tiles, p, peers).map(|r| r.efficiency))
                    .collect();
                let best = others.iter().flatten().fold(f64::MIN, |a, &b| a.max(b));
                let cell = |e: &Option<f64>| e.map_or("-".to_string(), |e| format!("{e:.3}"));
                let gain = with.efficiency - best;
                total += 1;
                wins += usize::from(gain > 0.0);
                let _ = writeln!(
                    out,
                    "| {tiles} | {peers} | {:.3} | {} | {} | {gain:+.3} |",
                    with.efficiency,
                    cell(&others[0]),
                    cell(&others[1])
                );
            }
        }
        let _ = writeln!(
            out,
            "\npbt+steal is ahead of both in {wins} of {total} configurations.\n"
        );
    }

    let _ = writeln!(out, "## Limits of one owner\n");
    let _ = writeln!(
        out,
        "Peers beyond which the owner, not rendering, sets the pace: the owner-link limit \
         P = T1 x B / S (one peer's frame time x bandwidth / bytes of a frame's results) and the \
         owner-CPU limit (T1 / the owner's control-loop time per frame), from the first run of \
         each tile count.\n"
    );
    let _ = writeln!(
        out,
        "| tiles | owner-link limit | owner-CPU limit |\n|---:|---:|---:|"
    );
    let limit = |p: Option<f64>| p.map_or("none".to_string(), |p| format!("{p:.0} peers"));
    for &tiles in &sweep.tiles {
        if let Some(run) = combinations
            .iter()
            .position(|c| c.0 == tiles)
            .map(|i| &runs[i])
        {
            let _ = writeln!(
                out,
                "| {tiles} | {} | {} |",
                limit(run.owner_link_limit),
                limit(run.owner_cpu_limit)
            );
        }
    }
    let _ = writeln!(out);

    let _ = writeln!(out, "## Cost of the simulation\n");
    if let Some(big) = runs.iter().max_by_key(|r| r.steps) {
        let _ = writeln!(
            out,
            "Largest run: {} peers, {}, {} tiles, {} frames: {} happenings in {:.2} s \
             ({:.2} million per second).",
            big.peers,
            big.policy,
            big.tiles,
            big.frames.len(),
            big.steps,
            big.wall_seconds,
            big.steps as f64 / big.wall_seconds.max(1e-9) / 1e6
        );
    }
    let total: f64 = runs.iter().map(|r| r.wall_seconds).sum();
    let _ = writeln!(
        out,
        "All {} runs: {total:.1} s of simulation (summed over threads).",
        runs.len()
    );
    out
}
