//! The real driver against a hostile member of the cluster: a peer with a valid certificate that
//! sends garbage, or lies about who it is, loses its connection; the owner goes on and the render
//! completes with the honest peer.

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

use runtime::net::{self, CloseReason, ClusterCerts, Event, Expect, Link};
use runtime::node::{self, CompletedFrame, FrameSink, Job, Owner};
use runtime_core::wire::{self, Message, PROTOCOL_VERSION, PeerId};
use std::net::{Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::time::Duration;

const SCENE: &str = r#"
[render]
width = 24
height = 16
spp = 1
frames = 2
[camera]
position = [0, 0, -3]
look_at = [0, 0, 0]
[[object]]
shape = "sphere"
center = [0, 0, 0]
radius = 1
material = "m"
[materials.m]
type = "diffuse"
[environment]
radiance = [1, 1, 1]
"#;

struct Frames(Vec<CompletedFrame>);

impl FrameSink for Frames {
    fn frame(&mut self, frame: CompletedFrame) -> Result<(), String> {
        self.0.push(frame);
        Ok(())
    }
}

fn job() -> Job {
    let scene = tracer::scene::load_str(SCENE).unwrap();
    let files = vec![wire::SceneFile {
        name: "scene.toml".into(),
        hash: *blake3::hash(SCENE.as_bytes()).as_bytes(),
        bytes: SCENE.as_bytes().to_vec(),
    }];
    let params = node::bundle::params(&scene, false);
    let frames = scene.settings.frames;
    let partitioner = balancer::Partitioner::new(
        24,
        16,
        &balancer::Config {
            leaves: 8,
            ..balancer::Config::default()
        },
    )
    .unwrap();
    Job {
        world: Arc::new(tracer::World::prepare(scene, None)),
        files,
        params,
        frames,
        first: 0,
        partitioner,
        checkpoint: None,
    }
}

async fn closed_reason(events: &mut tokio::sync::mpsc::Receiver<Event<Vec<u8>>>) -> CloseReason {
    loop {
        match tokio::time::timeout(Duration::from_secs(10), events.recv()).await {
            Ok(Some(Event::Closed { reason, .. })) => return reason,
            Ok(Some(_)) => {}
            Ok(None) | Err(_) => panic!("the connection was never closed"),
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn garbage_and_lies_cost_their_sender_its_connection_and_nothing_else() {
    let certs = ClusterCerts::generate(4).unwrap();
    let loopback = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    let owner = Owner::bind(loopback, &certs.peers()[0], node::Options::default()).unwrap();
    let addr = owner.local_addr().unwrap();
    let render = tokio::spawn(async move {
        let mut frames = Frames(Vec::new());
        owner.run(job(), 1, &mut frames).await.map(|_| frames.0)
    });

    // Peer 2 sends bytes that are no message at all.
    let (link, mut events) = Link::bind(
        loopback,
        &certs.peers()[2],
        net::Config::default(),
        |b: &[u8]| Ok::<_, String>(b.to_vec()),
    )
    .unwrap();
    let conn = link.connect(addr, Expect::Peer(0)).await.unwrap();
    link.send(conn, &[0xff, 0x13, 0x37, 0x00, 0x42])
        .await
        .unwrap();
    match closed_reason(&mut events).await {
        CloseReason::Remote { code, .. } => assert_eq!(code, net::CloseCode::Malformed as u64),
        other => panic!("the garbage sender's connection ended otherwise: {other:?}"),
    }

    // Peer 3 claims to be peer 1 in its Hello: its certificate says otherwise.
    let (liar, mut liar_events) = Link::bind(
        loopback,
        &certs.peers()[3],
        net::Config::default(),
        |b: &[u8]| Ok::<_, String>(b.to_vec()),
    )
    .unwrap();
    let conn = liar.connect(addr, Expect::Peer(0)).await.unwrap();
    liar.send(
        conn,
        &wire::encode(&Message::Hello {
            version: PROTOCOL_VERSION,
            peer: PeerId(1),
            slots: 1,
        }),
    )
    .await
    .unwrap();
    match closed_reason(&mut liar_events).await {
        CloseReason::Remote { code, .. } => assert_eq!(code, net::CloseCode::Identity as u64),
        other => panic!("the liar's connection ended otherwise: {other:?}"),
    }

    // The honest peer 1 joins; the render completes.
    let honest = tokio::spawn({
        let identity = certs.peers()[1].clone();
        async move {
            node::run_peer(
                addr,
                loopback,
                &identity,
                node::Options::default(),
                node::Leave::never(),
            )
            .await
        }
    });
    let frames = tokio::time::timeout(Duration::from_secs(60), render)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
    assert_eq!(frames.len(), 2);
    for frame in &frames {
        assert_eq!(
            frame.tiles.iter().map(|t| t.rect.area()).sum::<u64>(),
            24 * 16
        );
    }
    tokio::time::timeout(Duration::from_secs(20), honest)
        .await
        .unwrap()
        .unwrap()
        .unwrap();
}
