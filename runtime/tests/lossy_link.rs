//! The link over a bad network: real QUIC with mutual TLS on loopback, every peer's datagrams
//! dropped (5%), duplicated (1%), delayed and reordered by `net::lossy` from a seed. QUIC must
//! hide all of it: a multi-peer render over such links gives the same bits as one peer alone.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

use runtime::net::{self, ClusterCerts, ConnectError, Expect, Link, lossy::Impairment};
use runtime::node::{self, CompletedFrame, FrameSink, Job};
use std::net::{Ipv4Addr, SocketAddr};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

const SCENE: &str = "../scenes/glass-cluster-pan/glass-cluster-pan.toml";

struct Frames(Vec<CompletedFrame>);

impl FrameSink for Frames {
    fn frame(&mut self, frame: CompletedFrame) -> Result<(), String> {
        self.0.push(frame);
        Ok(())
    }
}

/// The shipped panning scene, small: 64x48 at 4 spp, `frames` frames in 24 tiles.
fn job(frames: u32) -> Job {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(SCENE);
    let mut scene = tracer::scene::load(&path).unwrap();
    let s = &mut scene.settings;
    (s.width, s.height, s.samples_per_pixel) = (64, 48, 4);
    let files = node::bundle::scene_files(&path, &scene).unwrap();
    let params = node::bundle::params(&scene, false);
    let config = balancer::Config {
        leaves: 24,
        ..balancer::Config::default()
    };
    Job {
        partitioner: balancer::Partitioner::new(64, 48, &config).unwrap(),
        checkpoint: None,
        world: Arc::new(tracer::World::prepare(scene, None)),
        files,
        params,
        frames,
        first: 0,
    }
}

fn render(peers: usize, options: node::Options) -> Vec<CompletedFrame> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let mut frames = Frames(Vec::new());
    runtime
        .block_on(node::run_local(job(4), peers, options, &mut frames))
        .unwrap();
    frames.0
}

/// Some tile of `frames` was rendered by a peer other than the owner: the links were used.
fn assert_remote_peers_took_part(frames: &[CompletedFrame]) {
    let remote = frames
        .iter()
        .flat_map(|f| &f.tiles)
        .filter(|t| t.peer != 0)
        .count();
    assert!(remote > 0, "peers 1 and 2 rendered nothing");
}

fn bits(frame: &CompletedFrame) -> Vec<u32> {
    frame
        .film
        .pixels
        .iter()
        .flatten()
        .map(|c| c.to_bits())
        .collect()
}

#[test]
fn a_render_over_lossy_links_gives_the_bits_of_one_peer() {
    let reference = render(1, node::Options::default());
    let mut options = node::Options::default();
    options.net.impairment = Some(Impairment {
        seed: 14,
        ..Impairment::default()
    });
    let lossy = render(3, options);
    assert_eq!(lossy.len(), reference.len());
    for (a, b) in lossy.iter().zip(&reference) {
        assert_eq!(a.frame, b.frame);
        assert!(bits(a) == bits(b), "frame {} differs", a.frame);
    }
    // The other peers did take part: their tiles crossed the lossy links.
    assert_remote_peers_took_part(&lossy);
}

/// The impairment is really on the link's path: with every datagram dropped, no handshake
/// completes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_link_that_drops_everything_never_connects() {
    let certs = ClusterCerts::generate(2).unwrap();
    let loopback = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    let config = net::Config {
        idle_timeout: Duration::from_millis(500),
        keep_alive: Duration::from_millis(100),
        impairment: Some(Impairment {
            drop: 1.0,
            ..Impairment::default()
        }),
        ..net::Config::default()
    };
    let decode = |b: &[u8]| Ok::<_, String>(b.to_vec());
    let (server, _server_events) =
        Link::bind(loopback, &certs.peers()[0], net::Config::default(), decode).unwrap();
    let (client, _client_events) = Link::bind(loopback, &certs.peers()[1], config, decode).unwrap();
    let attempt = client.connect(server.local_addr().unwrap(), Expect::Peer(0));
    match tokio::time::timeout(Duration::from_secs(10), attempt).await {
        Ok(Err(ConnectError::Handshake(quinn::ConnectionError::TimedOut))) => {}
        other => panic!("a handshake through a dead link ended otherwise: {other:?}"),
    }
}

/// A LAN's silence timeout on a WAN's links: `--peer-timeout 0.1` (as the CLI maps it: the
/// owner's silence timeout, heartbeats at a fifth of it, the transport's idle timeout and
/// keep-alive likewise) over links that hold every datagram 150 ms, a 300 ms round trip. No
/// peer is given up (none of its tiles re-issued): the owner keeps a peer's silence timeout at
/// least three of its measured round trips long, as QUIC keeps its idle timeout, and counts it
/// from a round trip after it gives the peer work. Before, it declared both other peers
/// silent at every frame (a burst of results waits a round trip on QUIC's congestion window)
/// and re-issued their work. Backups of tiles that look overdue from so far are the policy's
/// and may happen.
#[test]
fn a_silence_timeout_shorter_than_the_round_trip_gives_up_no_peer() {
    let reference = render(1, node::Options::default());
    let mut options = node::Options::default();
    options.set_peer_timeout(Duration::from_millis(100));
    options.net.impairment = Some(Impairment {
        seed: 3,
        drop: 0.0,
        duplicate: 0.0,
        delay: Duration::from_millis(150),
        jitter: Duration::from_millis(1),
    });
    let far = render(3, options);
    assert_eq!(far.len(), reference.len());
    for (a, b) in far.iter().zip(&reference) {
        assert!(bits(a) == bits(b), "frame {} differs", a.frame);
        assert_eq!(
            (a.audit.failed, a.audit.reissued),
            (0, 0),
            "frame {}: live peers were given up",
            a.frame
        );
    }
    assert_remote_peers_took_part(&far);
}
