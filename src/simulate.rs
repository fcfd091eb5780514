//! `tessera simulate`: scaling experiments in virtual time on a cost trace (see the `sim` crate).
//!
//! Thin: it parses lists and units, loads (or makes) the trace, runs the sweep through `sim`,
//! writes its files and prints one line per run. Each run's balancer comes from
//! `balancer::Config::with_tiles`, so `--tiles M` means here exactly what it means to `tessera
//! render`. With `--validate STATS` it instead simulates the render a `--stats` file describes
//! and compares the two, frame by frame (`sim::validate`).

use crate::cli::DealOrder;
use anyhow::{Context, bail};
use balancer::motion::MotionSearch;
use runtime_core::stats::StatsFile;
use sim::knobs::PieceFactor;
use sim::scenario::{DEFAULT_WORK_PER_SECOND, Scenario};
use sim::synthetic::HotSpot;
use sim::{Crash, GanttChoice, Network, OwnerCosts, Policy, Sweep, Trace};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// A cost trace (`tessera render --trace FILE`), or `synthetic[:WIDTHxHEIGHT[:FRAMES]]`: a
    /// hot spot orbiting the image (default 1024x1024, 100 frames).
    pub trace: String,
    /// Peer counts (the owner included), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16,32,64")]
    pub peers: Vec<usize>,
    /// Policies, comma-separated: regular, regular+steal, pbt, pbt+steal (default: all four).
    #[arg(long, value_delimiter = ',')]
    pub policy: Vec<Policy>,
    /// Tile counts requested (PBT leaves; the grid is the nearest k x k), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "256")]
    pub tiles: Vec<usize>,
    /// How tiles are dealt to peers at the start of each frame (both balancers).
    #[arg(long, value_enum, default_value_t = DealOrder::Interleaved)]
    pub deal: DealOrder,
    /// Motion-compensated prediction: the largest shift of the cost landscape between frames
    /// searched, in blocks per frame, or `off` (as `tessera render --motion`; with --validate,
    /// the render's).
    #[arg(long, default_value_t = MotionSearch::default())]
    pub motion: MotionSearch,
    /// Simulate only this frame of the trace, over and over: a static scene, every frame of
    /// which after the first is predicted exactly (isolates motion from unevenness).
    #[arg(long)]
    pub hold: Option<usize>,
    /// Frames to simulate (default: the trace's; more repeat it).
    #[arg(long, value_parser = crate::cli::at_least_one)]
    pub frames: Option<usize>,
    /// Rendering slots (threads) per peer (default 1; with --validate, the render's).
    #[arg(long)]
    pub slots: Option<usize>,
    /// One-way latency of every link, in milliseconds. The simulated peers are told each
    /// link's round trip, as QUIC tells real ones, so links of any length work.
    #[arg(long, default_value_t = 0.0)]
    pub latency: f64,
    /// Extra delay of each message, uniform up to this many milliseconds.
    #[arg(long, default_value_t = 0.0)]
    pub jitter: f64,
    /// Links' latencies differ from --latency by up to this fraction either way.
    #[arg(long, default_value_t = 0.0)]
    pub link_spread: f64,
    /// Bandwidth of each peer's link, each way, in megabits per second; 0 for unlimited.
    #[arg(long, default_value_t = 10_000.0)]
    pub bandwidth: f64,
    /// What the frame owner's control loop spends per tile result received and per tile dealt:
    /// `measured` (on the real runtime; see docs/results.md) or `none` (an idealised owner).
    #[arg(long, value_enum, default_value_t = OwnerCostsChoice::Measured)]
    pub owner_costs: OwnerCostsChoice,
    /// Probability that a transmission is lost (QUIC resends it after a probe timeout).
    #[arg(long, default_value_t = 0.0)]
    pub loss: f64,
    /// Milliseconds after a crash until the others notice.
    #[arg(long, default_value_t = 100.0)]
    pub loss_detection: f64,
    /// Speed factors dealt to peers in turn, comma-separated (e.g. 1,1,1,0.5).
    #[arg(long, value_delimiter = ',')]
    pub speeds: Vec<f64>,
    /// Crashes, comma-separated: PEER@SECONDS (virtual time since the run began) or
    /// PEER@tile:N (as the peer starts its N-th tile of the run).
    #[arg(long, value_delimiter = ',')]
    pub crash: Vec<String>,
    /// Counted work per second of one slot of a speed-1 peer (default: this project's
    /// development machine; with --validate, measured from the render's statistics).
    #[arg(long)]
    pub rate: Option<f64>,
    /// Milliseconds each tile costs a slot besides its counted work (ray setup, encoding and
    /// sending the result). Default 0.
    #[arg(long, default_value_t = 0.0)]
    pub tile_overhead: f64,
    /// Tiles a peer keeps committed to its renderer beyond its slots (the core's prefetch).
    #[arg(long, default_value_t = 1)]
    pub prefetch: usize,
    /// Peers render pieces of at most this many times the frame's mean tile area, so that the
    /// unrendered part of a large tile can still be stolen; `off` renders tiles whole.
    #[arg(long, default_value = "2")]
    pub render_pieces: PieceFactor,
    /// Whether a victim cuts a tile too large to give whole and gives its far half.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub split_on_steal: bool,
    /// Whether a peer re-predicts the rest of a tile from the pieces of it it has rendered.
    #[arg(long, default_value_t = runtime_core::peer::Config::default().relearn_pieces,
          action = clap::ArgAction::Set)]
    pub relearn_pieces: bool,
    /// Whether the owner backs up an overdue peer's work on idle peers (speculation).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub backups: bool,
    /// Frames dealt before the last is measured, at most: 1 puts a barrier between frames; 2
    /// deals the next frame when the running one wanes.
    #[arg(long, default_value_t = runtime_core::director::Config::default().frames_in_flight as u64,
          value_parser = clap::value_parser!(u64).range(1..=64))]
    pub frames_in_flight: u64,
    /// How far a frame's tiles may miss their predicted costs (relative, summed) before the
    /// director doubts the prediction: the next frame is then not overlapped and renders in
    /// small pieces.
    #[arg(long, default_value_t = runtime_core::director::Config::default().doubt_error,
          value_parser = crate::cli::finite_non_negative::<f64>)]
    pub doubt_error: f64,
    /// While the prediction is doubted, peers render pieces of at most this many times the
    /// frame's mean tile area; `off` uses `--render-pieces`.
    #[arg(long, default_value = "0.125")]
    pub doubtful_pieces: PieceFactor,
    /// The share of a frame's predicted cost still missing when the next frame is dealt (if
    /// frames may overlap; also dealt when the first peer runs out of work).
    #[arg(long, default_value_t = runtime_core::peer::Config::default().waning)]
    pub waning: f64,
    /// Seed of victim choice, jitter, link latencies and loss.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The run drawn as gantt.svg, as PEERS:POLICY:TILES or PEERS:POLICY:TILES:FRAME (default:
    /// at most 16 peers, pbt+steal, the first tile count, the middle frame).
    #[arg(long)]
    pub gantt: Option<String>,
    /// Line charts to draw: efficiency against peers (one per tile count), against tiles (one
    /// per peer count), or both.
    #[arg(long, value_delimiter = ',', default_value = "peers,tiles")]
    pub charts: Vec<ChartAxis>,
    /// Output folder (created if missing).
    #[arg(long, default_value = "sim-out")]
    pub out: PathBuf,
    /// Also write the trace to this file (for synthetic traces).
    #[arg(long)]
    pub save_trace: Option<PathBuf>,
    /// Simulate the render a `tessera render --stats` file describes (its peers, threads,
    /// balancer and tiles) and compare frame times and initial tile sets with it.
    #[arg(long)]
    pub validate: Option<PathBuf>,
}

/// The x axis of a line chart.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ChartAxis {
    Peers,
    Tiles,
}

pub fn run(args: &SimulateArgs) -> anyhow::Result<()> {
    let mut trace = load_trace(&args.trace)?;
    if let Some(hold) = args.hold {
        let Some(frame) = trace.frames.get(hold) else {
            bail!(
                "--hold {hold}: the trace has frames 0 to {}",
                trace.frames.len() - 1
            );
        };
        let blocks = frame.blocks.clone();
        trace.header.source = format!("{}, frame {hold} held", trace.header.source);
        trace.frames.clear();
        trace.push(blocks)?;
    }
    if let Some(path) = &args.save_trace {
        trace.write(path)?;
    }
    crate::job::check_out_folder("--out", &args.out)?;
    if let Some(stats) = &args.validate {
        return validate(args, &trace, stats);
    }
    let policies = if args.policy.is_empty() {
        Policy::ALL.to_vec()
    } else {
        args.policy.clone()
    };
    anyhow::ensure!(
        !args.peers.is_empty() && !args.tiles.is_empty(),
        "--peers and --tiles need at least one value"
    );
    // Runs go one after another, so the largest is the peak; past the machine's memory it would
    // abort allocating, naming no flag (`--peers 100000000` did).
    let most = args.peers.iter().copied().max().unwrap_or(0);
    let needed = sim::scenario::memory_estimate(most);
    if let Some(available) = runtime::node::limits::available_memory() {
        anyhow::ensure!(
            needed <= available,
            "--peers {most}: a run of {most} peers needs about {} MiB (each keeps what it knows of \
             every other), and this machine has {} MiB free",
            needed >> 20,
            available >> 20
        );
    }
    let base = base_scenario(
        args,
        args.slots.unwrap_or(1),
        args.rate.unwrap_or(DEFAULT_WORK_PER_SECOND),
    )?;
    let frames = base.frames.unwrap_or(trace.frames.len());
    let sweep = Sweep {
        peers: args.peers.clone(),
        policies,
        tiles: args.tiles.clone(),
        base,
    };
    let gantt = GanttChoice::pick(args.gantt.as_deref(), &sweep, frames)?;
    let (width, height) = (trace.width(), trace.height());
    let started = Instant::now();
    let runs = sweep.run(
        &trace,
        |kind, tiles| {
            let config = balancer::Config::with_tiles(kind, tiles, args.deal.into(), args.motion.0);
            Ok(balancer::Partitioner::new(width, height, &config)?)
        },
        gantt,
    )?;
    let elapsed = started.elapsed().as_secs_f64();
    print!("{}", sim::report::table(&runs));
    let title = format!(
        "{} ({}x{}, {frames} frames, tiles dealt {})",
        trace.header.source,
        width,
        height,
        crate::cli::flag_name(&args.deal)
    );
    let charts = sim::Charts {
        peers: args.charts.contains(&ChartAxis::Peers),
        tiles: args.charts.contains(&ChartAxis::Tiles),
    };
    let written = sim::sweep::write_outputs(&args.out, &title, &sweep, &runs, charts)?;
    println!(
        "{} runs in {elapsed:.1} s; wrote {} in {}",
        runs.len(),
        written.join(", "),
        args.out.display()
    );
    Ok(())
}

fn load_trace(spec: &str) -> anyhow::Result<Trace> {
    if spec.starts_with("synthetic") && !Path::new(spec).exists() {
        return Ok(HotSpot::parse(spec)?.trace()?);
    }
    Trace::read(Path::new(spec)).with_context(|| format!("reading the trace {spec}"))
}

/// Everything but peers and policy, from the flags.
fn base_scenario(args: &SimulateArgs, slots: usize, rate: f64) -> anyhow::Result<Scenario> {
    // Up to a million seconds (eleven days): far past any study, and inside `Duration`'s
    // range with room for the sums the simulator makes of them (1e300 panicked).
    let millis = |ms: f64, what: &str| -> anyhow::Result<Duration> {
        anyhow::ensure!(
            (0.0..=1e9).contains(&ms),
            "--{what} must be a number of milliseconds from 0 to 1e9"
        );
        Ok(Duration::from_secs_f64(ms / 1e3))
    };
    let crashes = args
        .crash
        .iter()
        .map(|spec| spec.parse().map_err(|e| anyhow::anyhow!("--crash {e}")))
        .collect::<anyhow::Result<Vec<Crash>>>()?;
    let mut scenario = Scenario {
        slots,
        network: Network {
            latency: millis(args.latency, "latency")?,
            jitter: millis(args.jitter, "jitter")?,
            link_spread: args.link_spread,
            bandwidth: if args.bandwidth == 0.0 {
                None
            } else if (1e-3..=1e9).contains(&args.bandwidth) {
                // At least a kilobit a second, so that a tile's transfer time stays a
                // `Duration` (1e-300 panicked).
                Some(args.bandwidth * 1e6 / 8.0)
            } else {
                bail!("--bandwidth must be a number of megabits per second from 0.001 to 1e9, or 0")
            },
            loss: args.loss,
            loss_detection: millis(args.loss_detection, "loss-detection")?,
        },
        speeds: args.speeds.clone(),
        crashes,
        seed: args.seed,
        work_per_second: rate,
        tile_overhead: millis(args.tile_overhead, "tile-overhead")?,
        owner: match args.owner_costs {
            OwnerCostsChoice::Measured => OwnerCosts::MEASURED,
            OwnerCostsChoice::None => OwnerCosts::NONE,
        },
        frames: args.frames,
        ..Scenario::default()
    };
    scenario.core.prefetch_depth = args.prefetch;
    scenario.core.split_on_steal = args.split_on_steal;
    scenario.core.relearn_pieces = args.relearn_pieces;
    if !args.backups {
        scenario.core.speculation = None;
    }
    scenario.render_piece_factor = args.render_pieces.0;
    scenario.frames_in_flight = args.frames_in_flight as usize;
    scenario.doubt_error = args.doubt_error;
    scenario.doubtful_piece_factor = args.doubtful_pieces.0;
    if !(0.0..=1.0).contains(&args.waning) {
        anyhow::bail!("--waning {}: give a share from 0 to 1", args.waning);
    }
    scenario.core.waning = args.waning;
    Ok(scenario)
}

/// The owner's modelled costs, as `--owner-costs` names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OwnerCostsChoice {
    /// Measured on the real runtime (`cargo run --release -p runtime --example owner_costs`).
    Measured,
    /// An owner that spends nothing: the idealised cluster of earlier studies.
    None,
}

/// Simulates the render `stats_path` describes and compares: frame times (simulated over
/// measured) and the tiles each peer started each frame with.
fn validate(args: &SimulateArgs, trace: &Trace, stats_path: &Path) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(stats_path)
        .with_context(|| format!("reading {}", stats_path.display()))?;
    let stats: StatsFile = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a tessera stats file", stats_path.display()))?;
    let steal = match args.policy.as_slice() {
        [] => true,
        [policy] => policy.steal,
        _ => bail!(
            "--validate simulates one run: give at most one --policy (its balancer must be the render's)"
        ),
    };
    let given = sim::validate::Given {
        steal,
        rate: args.rate,
        slots: args.slots,
        frames: args.frames,
    };
    // Slots and rate are the validation's to choose: the base's are placeholders.
    let base = base_scenario(args, 1, DEFAULT_WORK_PER_SECOND)?;
    let validation = sim::validate::validate(trace, &stats, base, given)
        .with_context(|| format!("simulating the render {} describes", stats_path.display()))?;
    print!("{}", validation.table());
    let path = args.out.join("validation.csv");
    std::fs::write(&path, validation.csv())
        .with_context(|| format!("writing {}", path.display()))?;
    println!("{}; wrote {}", validation.totals(), path.display());
    Ok(())
}
