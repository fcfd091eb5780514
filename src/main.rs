//! `tessera`: the command line. Thin: it parses arguments, sets up logging and calls the crates.
//!
//! - `cli`: the argument definitions (clap); `--help` is generated from their doc comments.
//! - `render`: `tessera render`, peers in this process: frames balanced by the PBT or a grid,
//!   stolen between peers.
//! - `cluster`: `tessera serve` (the frame owner of a cluster of processes), `tessera peer`,
//!   `tessera slurm` (one task of a SLURM step) and `tessera keygen`.
//! - `job`: what the commands that render frames share (no command of its own): the scene and
//!   its overrides, the limits refused before rendering, the stats file and charts.
//! - `progress`: progress on a terminal, log lines elsewhere.
//! - `compare`: `tessera compare`, the error metrics of one image against another
//!   ([`lab::compare`]).
//! - `accuracy`: `tessera accuracy`, what accuracy costs in time, as a table and a plot
//!   ([`lab::accuracy`]).
//! - `bench`: `tessera bench`, rays per second of the tracer alone, and the steal round trip
//!   ([`lab::bench`]).
//! - `meshes`: `tessera meshes`, a scene's still triangles as PLY files for another renderer
//!   ([`lab::meshes`]).
//! - `simulate`: `tessera simulate`, scaling experiments in virtual time on a cost trace.

mod accuracy;
mod bench;
mod cli;
mod cluster;
mod compare;
mod job;
mod meshes;
mod progress;
mod render;
mod simulate;

use clap::Parser;
use std::process::ExitCode;

/// Runs the command; a failure prints its message and each cause on a line of its own and exits
/// with status 1. Never a backtrace, even with `RUST_BACKTRACE` set (common among Rust users):
/// errors here are the user's to read, not ours to debug. Panics keep theirs.
fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error}");
            for cause in error.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::FAILURE
        }
    }
}

fn run() -> anyhow::Result<()> {
    let cli = cli::Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    match cli.command {
        cli::Command::Render(args) => render::run(&args),
        cli::Command::Serve(args) => cluster::serve(&args),
        cli::Command::Peer(args) => cluster::peer(&args),
        cli::Command::Slurm(args) => cluster::slurm(args),
        cli::Command::Keygen(args) => cluster::keygen(&args),
        cli::Command::Compare(args) => compare::run(&args),
        cli::Command::Accuracy(args) => accuracy::run(&args),
        cli::Command::Bench(args) => bench::run(&args),
        cli::Command::Meshes(args) => meshes::run(&args),
        cli::Command::Simulate(args) => simulate::run(&args),
    }
}
