//! Command-line arguments.

use balancer::motion::MotionSearch;
use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

/// A distributed parallel ray tracer: tiles from a Prediction Binary Tree, work stealing over QUIC.
#[derive(Debug, Parser)]
#[command(name = "tessera", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Render a scene (all frames of its animation) with peers in this process.
    Render(RenderArgs),
    /// Own the frames of a render whose peers are other processes or machines (`tessera peer`).
    Serve(ServeArgs),
    /// Join a render served by `tessera serve`, and render until it is over.
    Peer(PeerArgs),
    /// Run one task of a SLURM step (`srun tessera slurm ...`): task 0 serves, the others join
    /// it; rank, task count, owner node, port and threads (`SLURM_CPUS_PER_TASK`) come from
    /// SLURM's environment.
    Slurm(SlurmArgs),
    /// Make a cluster certificate authority and peer certificates for `serve` and `peer`.
    Keygen(KeygenArgs),
    /// Compare two OpenEXR images (B is the reference): RMSE, relative MSE, FLIP, ...
    Compare(crate::compare::CompareArgs),
    /// Measure what accuracy costs in time: error against time for each accuracy knob.
    Accuracy(crate::accuracy::AccuracyArgs),
    /// Measure the tracer: rays per second (camera rays, full paths), BVH build, CPU-seconds.
    Bench(crate::bench::BenchArgs),
    /// Write a scene's still triangles as PLY files, with an index of their materials, for
    /// another renderer to trace the same geometry (the Mitsuba 3 comparison scripts).
    Meshes(crate::meshes::MeshesArgs),
    /// Simulate a cluster in virtual time on a cost trace: efficiency against peers, policies
    /// and tile counts, as CSV, JSON and SVG charts.
    Simulate(crate::simulate::SimulateArgs),
}

#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub job: FrameArgs,
    /// Peers in this process, each with its own rendering threads, talking QUIC on loopback
    /// with certificates made in memory. Peer 0 owns the frames. `--peers 1` renders alone.
    #[arg(long, default_value_t = 2, value_parser = at_least_one)]
    pub peers: usize,
}

#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    #[command(flatten)]
    pub job: FrameArgs,
    /// The address to listen on for peers, e.g. 0.0.0.0:4433.
    #[arg(long)]
    pub listen: std::net::SocketAddr,
    /// The folder `tessera keygen` wrote (this node uses peer 0's certificate).
    #[arg(long)]
    pub certs: PathBuf,
    /// Peers to wait for before the first frame: a minimum, since peers may join at any time
    /// (each with a certificate of its own from `tessera keygen`) and take part from then on.
    /// 0 starts at once, rendering alone until someone joins.
    #[arg(long, default_value_t = 1)]
    pub expect: usize,
}

#[derive(Debug, clap::Args)]
pub struct PeerArgs {
    /// The address of `tessera serve`.
    #[arg(long)]
    pub join: std::net::SocketAddr,
    /// The folder holding `ca.pem` and this peer's `peer-K.pem` / `peer-K-key.pem`.
    #[arg(long)]
    pub certs: PathBuf,
    /// Which peer certificate to use (default: the only `peer-K-key.pem` in the folder, K >= 1).
    #[arg(long)]
    pub index: Option<u32>,
    /// Rendering threads (default: all cores).
    #[arg(long, value_parser = threads)]
    pub threads: Option<usize>,
    /// The address to listen on for other peers (default: any port on all interfaces).
    #[arg(long, default_value = "0.0.0.0:0")]
    pub listen: std::net::SocketAddr,
}

/// Every task of a step runs the same command line: the render flags take effect on task 0,
/// which ships them to the others with the scene.
#[derive(Debug, clap::Args)]
pub struct SlurmArgs {
    #[command(flatten)]
    pub job: FrameArgs,
    /// The job's `tessera keygen` folder on the shared file system, with a certificate for
    /// every task (`--peers` at least the task count): task K uses `peer-K`.
    #[arg(long)]
    pub certs: PathBuf,
    /// The owner's port (default: 20000 + 10 * (job id mod 2000) + step id mod 10, the same in
    /// every task of the step; see docs/cluster.md).
    #[arg(long)]
    pub port: Option<u16>,
    /// The owner's host name, where task 0 is not on the step's first node (e.g. with
    /// `--distribution=arbitrary`) or the node's SLURM name is not its host name.
    #[arg(long)]
    pub owner: Option<String>,
    /// Seconds a peer keeps knocking while the owner is not yet listening (it loads the scene
    /// first); each try waits for the transport's 10 s handshake timeout.
    #[arg(long, default_value_t = 120.0)]
    pub join_timeout: f64,
    /// Peers task 0 waits for before the first frame (default: every other task of the step).
    /// Tasks that come later join the running render, so a step whose tasks start unevenly, or
    /// one of which never starts, need not hold the first frame for the last.
    #[arg(long)]
    pub expect: Option<usize>,
}

#[derive(Debug, clap::Args)]
pub struct KeygenArgs {
    /// Folder to write `ca.pem`, `ca-key.pem` and `peer-K.pem` / `peer-K-key.pem` to. Existing
    /// files are never overwritten.
    #[arg(long)]
    pub out: PathBuf,
    /// Certificates to make: peer 0 is the frame owner (`serve`), peers 1.. join it; 2 to
    /// 257 (an owner accepts at most 256 peers).
    #[arg(long, default_value_t = 8)]
    pub peers: u32,
}

/// Overrides of a scene's image and sampling settings, shared by every command that renders a
/// scene as it is (`render`, `serve`, `bench`); applied by [`ImageArgs::apply`].
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ImageArgs {
    /// Samples per pixel (default: the scene's).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Image width in pixels (default: the scene's).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (default: the scene's).
    #[arg(long)]
    pub height: Option<u32>,
    /// Seed of the pixel sampler (default: the scene's); a render's peers also seed their
    /// choice of whom to steal from with it.
    #[arg(long)]
    pub seed: Option<u64>,
}

impl ImageArgs {
    /// Overrides `settings` with the flags given, then checks the image is not empty.
    pub fn apply(&self, settings: &mut tracer::scene::RenderSettings) -> anyhow::Result<()> {
        settings.samples_per_pixel = self.spp.unwrap_or(settings.samples_per_pixel);
        settings.width = self.width.unwrap_or(settings.width);
        settings.height = self.height.unwrap_or(settings.height);
        settings.seed = self.seed.unwrap_or(settings.seed);
        anyhow::ensure!(
            settings.width > 0 && settings.height > 0,
            "the image must be at least 1x1 pixels"
        );
        anyhow::ensure!(
            settings.samples_per_pixel > 0,
            "samples per pixel must be at least 1"
        );
        Ok(())
    }
}

/// What to render and how; shared by `render` and `serve`.
#[derive(Debug, clap::Args)]
pub struct FrameArgs {
    /// The scene file (TOML; see scenes/README.md).
    pub scene: PathBuf,
    /// Output folder for frame-NNNN.exr and frame-NNNN.png (created if missing).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Number of frames to render (default: the scene's `frames`).
    #[arg(long, value_parser = frames)]
    pub frames: Option<u32>,
    #[command(flatten)]
    pub image: ImageArgs,
    /// Rendering threads of this process, shared evenly by its peers (default: all cores).
    #[arg(long, value_parser = threads)]
    pub threads: Option<usize>,
    /// Seconds a peer may stay silent before the owner gives its tiles to others, and at least
    /// three round trips of its link (also the transport's idle timeout, which QUIC keeps at
    /// least three probe timeouts long); 0.1 to 1000000.
    #[arg(long, default_value_t = 10.0, value_parser = peer_timeout)]
    pub peer_timeout: f64,
    /// Turn work stealing between peers off (each renders its initial set only).
    #[arg(long)]
    pub no_steal: bool,
    /// Where to write the run's chart (SVG; default: OUT/gantt.svg): frames' spans, one
    /// utilisation strip per peer, the cluster's busy share. Beside it, in a folder of the
    /// same name (OUT/gantt/), one chart per frame: every tile or piece a bar, coloured by
    /// whether it was the peer's own, taken over, a piece of a cut tile, or a duplicate.
    #[arg(long)]
    pub gantt: Option<PathBuf>,
    /// How frames are cut into tiles.
    #[arg(long, value_enum, default_value_t = BalancerKind::Pbt)]
    pub balancer: BalancerKind,
    /// Number of tiles per frame (PBT leaves, or grid cells rounded to a k x k grid); at most
    /// one per pixel. Default: the balancer's (256), or one per pixel on smaller images.
    #[arg(long, value_parser = at_least_one)]
    pub tiles: Option<usize>,
    /// How each frame's tiles are dealt to peers before stealing starts.
    #[arg(long, value_enum, default_value_t = DealOrder::Interleaved)]
    pub deal: DealOrder,
    /// Motion-compensated prediction: the largest shift of the cost landscape between frames
    /// searched, in 8-pixel blocks per frame, or `off` to predict each tile from where the
    /// costs were (see balancer::Config::motion).
    #[arg(long, default_value_t = MotionSearch::default())]
    pub motion: MotionSearch,
    /// Which light-transport effects to pay for: those the scene calls for, or all of them.
    #[arg(long, value_enum, default_value_t = EffectsChoice::Auto)]
    pub effects: EffectsChoice,
    /// Where to write per-frame statistics (tiles, costs, times, per-peer accounts) as JSON
    /// (default: OUT/stats.json).
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Write OUT/tiles-NNNN.png per frame: the image dimmed, tile borders, tiles tinted by cost.
    #[arg(long)]
    pub tile_map: bool,
    /// Record every frame's per-block cost map (counted work) to this file, for
    /// `tessera simulate`.
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Exposure of the PNG previews (the EXR files are always linear and unscaled); a finite
    /// number, 0 or more.
    #[arg(long, default_value_t = 1.0, value_parser = finite_non_negative::<f32>)]
    pub exposure: f32,
    /// Keep the frames OUT already holds from a render of the same scene files and settings
    /// (each frame-NNNN.exr records their hash) and render from the first one missing. A frame
    /// of other settings counts as missing, so changed settings re-render every frame. The
    /// first missing frame goes on from its checkpoint (OUT/checkpoint.bin) if there is one.
    #[arg(long)]
    pub resume: bool,
    /// Seconds between checkpoints of the frame in progress (OUT/checkpoint.bin: every tile
    /// the owner has of it, written atomically, only when some came in since), so that
    /// `--resume` after a stop goes on within a long frame. 0 writes none.
    #[arg(long, default_value_t = 30.0)]
    pub checkpoint_every: f64,
}

/// `--threads`: 1 to [`runtime::node::limits::MAX_THREADS`].
pub fn threads(text: &str) -> Result<usize, String> {
    let most = runtime::node::limits::MAX_THREADS;
    match text.parse::<usize>() {
        Ok(n) if (1..=most).contains(&n) => Ok(n),
        _ => Err(format!("a whole number of threads from 1 to {most}")),
    }
}

/// `--frames`: 1 to [`tracer::scene::MAX_FRAMES`].
fn frames(text: &str) -> Result<u32, String> {
    let most = tracer::scene::MAX_FRAMES;
    match text.parse::<u32>() {
        Ok(n) if (1..=most).contains(&n) => Ok(n),
        _ => Err(format!("a whole number of frames from 1 to {most}")),
    }
}

/// `--peer-timeout`: seconds in [`runtime::node::limits::PEER_TIMEOUT_SECONDS`].
fn peer_timeout(text: &str) -> Result<f64, String> {
    let range = runtime::node::limits::PEER_TIMEOUT_SECONDS;
    match text.parse::<f64>() {
        Ok(s) if range.contains(&s) => Ok(s),
        _ => Err(format!(
            "a number of seconds from {} to {}",
            range.start(),
            range.end()
        )),
    }
}

/// `--exposure`, `simulate --doubt-error`: a finite number, 0 or more, in the flag's own type
/// (a NaN exposure would have written black previews, an infinite one white; a NaN doubt
/// threshold would never be crossed). A number too large for the type is not finite.
pub fn finite_non_negative<T: std::str::FromStr + Into<f64> + Copy>(
    text: &str,
) -> Result<T, String> {
    match text.parse::<T>() {
        Ok(v) if v.into().is_finite() && v.into() >= 0.0 => Ok(v),
        _ => Err("a finite number, 0 or more".to_string()),
    }
}

/// `--peers`, `--tiles`, `simulate --frames`: a count of at least one (zero would render
/// nothing, or fail later under another name).
pub fn at_least_one(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err("a whole number, 1 or more".to_string()),
    }
}

/// A value as the command line spells it (`round-robin`), which is also how files record it.
pub fn flag_name<T: ValueEnum>(value: &T) -> String {
    value
        .to_possible_value()
        .expect("invariant: no value of ours is skipped by clap")
        .get_name()
        .to_string()
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BalancerKind {
    /// The Prediction Binary Tree: tiles sized by last frame's measured cost.
    Pbt,
    /// A regular grid of equal tiles.
    Regular,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DealOrder {
    /// One run of neighbouring tiles per peer, the runs of equal predicted cost.
    Contiguous,
    /// Tiles dealt to peers in turn, blind to predicted cost (the classic static baseline).
    RoundRobin,
    /// Tiles dealt in turn to the peer with the least predicted work: shares spread over the
    /// image and balanced in cost.
    Interleaved,
}

impl From<BalancerKind> for balancer::Kind {
    fn from(kind: BalancerKind) -> Self {
        match kind {
            BalancerKind::Pbt => balancer::Kind::Pbt,
            BalancerKind::Regular => balancer::Kind::Regular,
        }
    }
}

impl From<DealOrder> for balancer::Order {
    fn from(deal: DealOrder) -> Self {
        match deal {
            DealOrder::Contiguous => balancer::Order::Contiguous,
            DealOrder::RoundRobin => balancer::Order::RoundRobin,
            DealOrder::Interleaved => balancer::Order::Interleaved,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum EffectsChoice {
    /// Only the effects the scene calls for.
    Auto,
    /// Every effect forced on (bit-identical images; for checking and timing).
    All,
}

impl EffectsChoice {
    /// The effect set forced on the world, or `None` for the scene's own.
    pub fn forced(self) -> Option<tracer::Effects> {
        match self {
            EffectsChoice::Auto => None,
            EffectsChoice::All => Some(tracer::Effects::ALL),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deal and a balancer have one name each: the flag's spelling is the one the
    /// balancer's files use, which `simulate --validate` reads back from `stats.json`.
    #[test]
    fn deal_and_balancer_flags_are_spelled_as_the_balancer_serialises_them() {
        for deal in DealOrder::value_variants() {
            let serde =
                serde_json::to_string(&balancer::Order::from(*deal)).expect("an enum serialises");
            assert_eq!(format!("\"{}\"", flag_name(deal)), serde);
        }
        for kind in BalancerKind::value_variants() {
            let serde =
                serde_json::to_string(&balancer::Kind::from(*kind)).expect("an enum serialises");
            assert_eq!(format!("\"{}\"", flag_name(kind)), serde);
        }
    }
}
