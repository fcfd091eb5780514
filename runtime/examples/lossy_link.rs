//! Measures what a lossy network costs a render: the same in-process cluster over clean links or
//! over links that drop 5% of datagrams, duplicate 1% and delay every one by 1-3 ms (so
//! reordering them), from `net::lossy`.
//!
//! `/usr/bin/time -f '%e s wall, %U + %S s CPU' cargo run -p runtime --example lossy_link -- MODE [SPP]`
//!
//! MODE is `clean`, `lossy` or `far`: links that lose nothing but hold every datagram 150 ms
//! (a 300 ms round trip) under a LAN's silence timeout, `--peer-timeout 0.1` as the CLI maps it.
//! Renders the shipped panning scene at 128x96, SPP samples (8 by default), 8 frames in 64
//! tiles with 3 peers of 1 thread each, and prints the render's wall time, the peers the owner
//! gave up on and the tiles it gave out again (summed over frames), and a blake3 hash of every
//! frame's pixel bits, which must be the same in every mode.

use runtime::net::lossy::Impairment;
use runtime::node::{self, CompletedFrame, FrameSink, Job};
use runtime_core::peer::Audit;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

const SCENE: &str = "../scenes/glass-cluster-pan/glass-cluster-pan.toml";
const PEERS: usize = 3;
const FRAMES: u32 = 8;

/// Hashes every frame's pixel bits as they arrive, and sums the owners' audits.
struct Hashing(blake3::Hasher, u32, Audit);

impl FrameSink for Hashing {
    fn frame(&mut self, frame: CompletedFrame) -> Result<(), String> {
        for c in frame.film.pixels.iter().flatten() {
            self.0.update(&c.to_bits().to_le_bytes());
        }
        self.1 += 1;
        self.2.failed += frame.audit.failed;
        self.2.reissued += frame.audit.reissued;
        self.2.backed_up += frame.audit.backed_up;
        Ok(())
    }
}

fn job(spp: u32) -> Result<Job, Box<dyn std::error::Error>> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(SCENE);
    let mut scene = tracer::scene::load(&path)?;
    let s = &mut scene.settings;
    (s.width, s.height, s.samples_per_pixel) = (128, 96, spp);
    let files = node::bundle::scene_files(&path, &scene)?;
    let params = node::bundle::params(&scene, false);
    let config = balancer::Config {
        leaves: 64,
        ..balancer::Config::default()
    };
    Ok(Job {
        partitioner: balancer::Partitioner::new(128, 96, &config)?,
        checkpoint: None,
        world: Arc::new(tracer::World::prepare(scene, None)),
        files,
        params,
        frames: FRAMES,
        first: 0,
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mode = std::env::args().nth(1).unwrap_or_default();
    let mut options = node::Options::default();
    match mode.as_str() {
        "clean" => {}
        "lossy" => options.net.impairment = Some(Impairment::default()),
        "far" => {
            options.set_peer_timeout(Duration::from_millis(100));
            options.net.impairment = Some(Impairment {
                drop: 0.0,
                duplicate: 0.0,
                delay: Duration::from_millis(150),
                ..Impairment::default()
            });
        }
        _ => return Err("usage: lossy_link clean|lossy|far [SPP]".into()),
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let mut sink = Hashing(blake3::Hasher::new(), 0, Audit::default());
    let spp = match std::env::args().nth(2) {
        Some(spp) => spp
            .parse()
            .map_err(|_| format!("{spp}: not a sample count"))?,
        None => 8,
    };
    let job = job(spp)?;
    let started = Instant::now();
    runtime.block_on(node::run_local(job, PEERS, options, &mut sink))?;
    let audit = sink.2;
    println!(
        "{mode}: {} frames with {PEERS} peers in {:.2} s; peers given up {}, tiles re-issued {}, \
         backed up {}; pixels {}",
        sink.1,
        started.elapsed().as_secs_f64(),
        audit.failed,
        audit.reissued,
        audit.backed_up,
        &sink.0.finalize().to_hex()[..16]
    );
    Ok(())
}
