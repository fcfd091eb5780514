//! Many runs at once: every combination of peer count, policy and tile count on one trace, run
//! in parallel (each run is single-threaded and independent, so the results do not depend on
//! the thread count), and written out as tables, charts and a summary.
//!
//! A [`Policy`] names the two knobs the seed's claims are about: how frames are cut (the PBT or
//! a regular grid) and whether peers steal. Everything else is the sweep's base [`Scenario`].

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use balancer::{Kind, Partitioner};
use rayon::prelude::*;
use runtime_core::peer::Config;
use serde::{Deserialize, Serialize};

use crate::plot::{self, Series};
use crate::report::{self, RunReport};
use crate::{Error, Scenario, Trace, scenario, summary};

/// How frames are cut, and whether peers steal: `regular`, `regular+steal`, `pbt`,
/// `pbt+steal`. Without stealing a peer renders what the owner dealt it (and what the owner
/// re-issues after a failure); with it, the core's prefetch and stealing run as configured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub struct Policy {
    /// How frames are cut: PBT or regular grid.
    pub kind: Kind,
    /// Whether peers steal work from each other.
    pub steal: bool,
}

impl Policy {
    /// The four policies, baseline first.
    pub const ALL: [Policy; 4] = [
        Policy {
            kind: Kind::Regular,
            steal: false,
        },
        Policy {
            kind: Kind::Regular,
            steal: true,
        },
        Policy {
            kind: Kind::Pbt,
            steal: false,
        },
        Policy {
            kind: Kind::Pbt,
            steal: true,
        },
    ];

    /// The policy a run with this balancer and core configuration follows.
    pub fn of(partitioner: &Partitioner, core: &Config) -> Self {
        let kind = match partitioner {
            Partitioner::Pbt(_) => Kind::Pbt,
            Partitioner::Regular(_) => Kind::Regular,
        };
        Self {
            kind,
            steal: core.steal,
        }
    }

    /// Sets a core's policy to this one. A policy without stealing is a fixed assignment, the
    /// baseline dynamic balancing is measured against: it backs up no stragglers either (the
    /// owner still re-issues the work of peers that fail).
    pub fn apply(self, core: &mut Config) {
        core.steal = self.steal;
        if !self.steal {
            core.speculation = None;
        }
    }

    /// Its position in [`Policy::ALL`]: a stable colour and order in charts and tables.
    pub fn index(self) -> usize {
        Self::ALL
            .iter()
            .position(|p| *p == self)
            .expect("ALL lists every policy")
    }
}

impl fmt::Display for Policy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = match self.kind {
            Kind::Pbt => "pbt",
            Kind::Regular => "regular",
        };
        write!(f, "{kind}{}", if self.steal { "+steal" } else { "" })
    }
}

impl FromStr for Policy {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|p| p.to_string() == text.trim())
            .ok_or_else(|| {
                format!("unknown policy {text:?}: use regular, regular+steal, pbt or pbt+steal")
            })
    }
}

impl From<Policy> for String {
    fn from(policy: Policy) -> Self {
        policy.to_string()
    }
}

impl TryFrom<String> for Policy {
    type Error = String;

    fn try_from(text: String) -> Result<Self, String> {
        text.parse()
    }
}

/// The runs of an experiment: the cross product of `peers`, `policies` and `tiles`.
#[derive(Clone, Debug)]
pub struct Sweep {
    /// Peer counts to run, the owner included.
    pub peers: Vec<usize>,
    /// Policies to run.
    pub policies: Vec<Policy>,
    /// Tile counts of the first frame to run.
    pub tiles: Vec<usize>,
    /// Everything else; its `peers` and `core.steal` are set per run.
    pub base: Scenario,
}

/// Which run to draw as a Gantt chart, and which of its frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GanttChoice {
    /// The run's peer count.
    pub peers: usize,
    /// The run's policy.
    pub policy: Policy,
    /// The run's tile count.
    pub tiles: usize,
    /// The frame of the run to draw.
    pub frame: u32,
}

impl GanttChoice {
    /// The run `spec` names as `PEERS:POLICY:TILES[:FRAME]` (the frame defaults to the middle
    /// of `frames`); without a spec, the sweep's largest peer count up to 16 (else its
    /// smallest), `pbt+steal` if swept (else the last policy), the first tile count and the
    /// middle frame. A spec must name a run the sweep makes.
    pub fn pick(spec: Option<&str>, sweep: &Sweep, frames: usize) -> Result<Option<Self>, Error> {
        let middle = (frames / 2) as u32;
        let Some(spec) = spec else {
            let peers = sweep
                .peers
                .iter()
                .copied()
                .filter(|&p| p <= 16)
                .max()
                .or(sweep.peers.iter().copied().min());
            let both = Policy {
                kind: Kind::Pbt,
                steal: true,
            };
            let policy = if sweep.policies.contains(&both) {
                Some(both)
            } else {
                sweep.policies.last().copied()
            };
            return Ok(match (peers, policy, sweep.tiles.first()) {
                (Some(peers), Some(policy), Some(&tiles)) => Some(GanttChoice {
                    peers,
                    policy,
                    tiles,
                    frame: middle,
                }),
                _ => None,
            });
        };
        let bad = |why: &str| Error::Scenario(format!("--gantt {spec:?}: {why}"));
        let expected = "expected PEERS:POLICY:TILES[:FRAME], e.g. 16:pbt+steal:256";
        let parts: Vec<&str> = spec.split(':').collect();
        let (peers, policy, tiles) = match parts.as_slice() {
            [peers, policy, tiles] | [peers, policy, tiles, _] => (
                peers.parse().map_err(|_| bad(expected))?,
                policy.parse().map_err(|_| bad(expected))?,
                tiles.parse().map_err(|_| bad(expected))?,
            ),
            _ => return Err(bad(expected)),
        };
        let frame = match parts.get(3) {
            Some(frame) => frame.parse().map_err(|_| bad(expected))?,
            None => middle,
        };
        if !sweep.combinations().contains(&(tiles, policy, peers)) {
            return Err(bad(
                "names a run the sweep does not make (check --peers, --policy and --tiles)",
            ));
        }
        Ok(Some(GanttChoice {
            peers,
            policy,
            tiles,
            frame,
        }))
    }
}

impl Sweep {
    /// Every (tiles, policy, peers) combination, in that nesting order.
    pub fn combinations(&self) -> Vec<(usize, Policy, usize)> {
        let mut all = Vec::new();
        for &tiles in &self.tiles {
            for &policy in &self.policies {
                for &peers in &self.peers {
                    all.push((tiles, policy, peers));
                }
            }
        }
        all
    }

    /// Runs every combination; `partitioner(policy kind, tiles)` makes each run's balancer.
    /// The Gantt frame is recorded for the run `gantt` names.
    pub fn run(
        &self,
        trace: &Trace,
        partitioner: impl Fn(Kind, usize) -> Result<Partitioner, Error> + Sync,
        gantt: Option<GanttChoice>,
    ) -> Result<Vec<RunReport>, Error> {
        let combinations = self.combinations();
        // Big runs first, so that the last thread to finish is not left with the biggest.
        let mut order: Vec<usize> = (0..combinations.len()).collect();
        order.sort_by_key(|&i| std::cmp::Reverse(combinations[i].2 * combinations[i].0.max(1)));
        let mut results: Vec<(usize, RunReport)> = order
            .into_par_iter()
            .map(|i| {
                let (tiles, policy, peers) = combinations[i];
                let mut scenario = self.base.clone();
                scenario.peers = peers;
                policy.apply(&mut scenario.core);
                scenario.gantt_frame = gantt
                    .filter(|g| (g.peers, g.policy, g.tiles) == (peers, policy, tiles))
                    .map(|g| g.frame);
                let run = scenario::run(trace, partitioner(policy.kind, tiles)?, &scenario)?;
                tracing::info!(
                    "simulated {policy}, {peers} peers, {tiles} tiles: efficiency {:.3}, {:.1} s",
                    run.efficiency,
                    run.wall_seconds
                );
                Ok((i, run))
            })
            .collect::<Result<_, Error>>()?;
        results.sort_by_key(|(i, _)| *i);
        Ok(results.into_iter().map(|(_, run)| run).collect())
    }
}

/// Which line charts [`write_outputs`] draws: a sweep over peers at a few tile counts wants
/// the first, a sweep over tiles at a few peer counts the second.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Charts {
    /// `efficiency-vs-peers-M.svg` for each tile count `M`.
    pub peers: bool,
    /// `efficiency-vs-tiles-P.svg` for each peer count `P`.
    pub tiles: bool,
}

/// What a chart's caption calls the trace: the title up to its first detail, and of a path
/// only the file name, so that the caption fits the chart.
fn short_name(title: &str) -> &str {
    let end = title.find([':', ',', '(']).unwrap_or(title.len());
    let head = title[..end].trim_end();
    head.rsplit('/').next().unwrap_or(head)
}

/// Writes everything an experiment yields into `dir`: `runs.csv`, `frames.csv`, `runs.json`,
/// `summary.md`, the `charts` asked for (each where its axis has more than one value), and
/// `gantt.svg` if a run recorded its Gantt frame. Returns the files written.
pub fn write_outputs(
    dir: &Path,
    title: &str,
    sweep: &Sweep,
    runs: &[RunReport],
    charts: Charts,
) -> Result<Vec<String>, Error> {
    report::write_runs(dir, runs)?;
    let name_of = short_name(title);
    let mut written = vec![
        "runs.csv".to_string(),
        "frames.csv".into(),
        "runs.json".into(),
    ];
    report::write(
        &dir.join("summary.md"),
        &summary::markdown(title, sweep, runs),
    )?;
    written.push("summary.md".into());
    let combinations = sweep.combinations();
    let find = |tiles: usize, policy: Policy, peers: usize| {
        let i = combinations
            .iter()
            .position(|c| *c == (tiles, policy, peers))
            .expect("the runs follow the sweep's combinations");
        &runs[i]
    };
    if charts.peers && sweep.peers.len() > 1 {
        for &tiles in &sweep.tiles {
            let line = |policy: Policy, bound: bool| Series {
                label: match bound {
                    true => format!(
                        "{} bound",
                        Policy {
                            steal: false,
                            ..policy
                        }
                    ),
                    false => policy.to_string(),
                },
                points: sweep
                    .peers
                    .iter()
                    .map(|&p| {
                        let run = find(tiles, policy, p);
                        let y = if bound {
                            run.bound_efficiency
                        } else {
                            run.efficiency
                        };
                        (p as f64, y)
                    })
                    .collect(),
                color: policy.index(),
                dashed: bound,
            };
            let mut series: Vec<Series> = sweep.policies.iter().map(|&p| line(p, false)).collect();
            // The bound depends on the partition alone, which stealing does not change: one
            // dashed line per balancer, in the colour of its policy without stealing.
            let mut kinds: Vec<Policy> = Vec::new();
            for &policy in &sweep.policies {
                let plain = Policy {
                    steal: false,
                    ..policy
                };
                if !kinds.contains(&plain) {
                    kinds.push(plain);
                    series.push(Series {
                        color: plain.index(),
                        ..line(policy, true)
                    });
                }
            }
            let name = format!("efficiency-vs-peers-{tiles}.svg");
            let caption = format!("{name_of}: efficiency vs peers, {tiles} tiles");
            plot::lines_svg(
                &dir.join(&name),
                &caption,
                ("peers", "efficiency"),
                1.05,
                &series,
            )?;
            written.push(name);
        }
    }
    if charts.tiles && sweep.tiles.len() > 1 {
        for &peers in &sweep.peers {
            let series: Vec<Series> = sweep
                .policies
                .iter()
                .map(|&policy| Series {
                    label: policy.to_string(),
                    points: sweep
                        .tiles
                        .iter()
                        .map(|&m| {
                            (
                                find(m, policy, peers).tiles as f64,
                                find(m, policy, peers).efficiency,
                            )
                        })
                        .collect(),
                    color: policy.index(),
                    dashed: false,
                })
                .collect();
            let name = format!("efficiency-vs-tiles-{peers}.svg");
            let caption = format!("{name_of}: efficiency vs tiles, {peers} peers");
            plot::lines_svg(
                &dir.join(&name),
                &caption,
                ("tiles", "efficiency"),
                1.05,
                &series,
            )?;
            written.push(name);
        }
    }
    if let Some(run) = runs.iter().find(|r| !r.gantt.is_empty()) {
        let frame = run.gantt_frame.unwrap_or(0);
        let caption = format!(
            "{name_of}: frame {frame}, {} peers, {}, {} tiles",
            run.peers, run.policy, run.tiles
        );
        let rows = run.peers as u32;
        plot::gantt_svg(&dir.join("gantt.svg"), &caption, rows, &run.gantt, frame)?;
        written.push("gantt.svg".into());
    }
    Ok(written)
}
