//! The steal round trip on loopback: how long a thief waits between asking for work and holding
//! it, which is what the scheduling core's low-water mark must cover (`runtime/src/core/README.md`).
//!
//! Two peers with certificates of one in-memory cluster CA are joined by the real transport
//! ([`runtime::net::Link`], QUIC with mutual TLS), and the thief sends real `StealRequest`
//! messages that the victim answers with real `StealGrant`s of [`GRANT_TILES`] tiles, both through
//! the wire codec. The victim answers at once, so the figure is the transport's and the codec's
//! share of a steal; the victim core's decision adds microseconds. A plain 12-byte echo is timed
//! by the transport's own test (`loopback_round_trips_and_large_messages_arrive_intact` in
//! `runtime/tests/net_security.rs`); this one times the messages a steal really sends.

use crate::LabError;
use runtime::net::{ClusterCerts, Event, Expect, Link};
use runtime_core::wire::{self, FrameId, Message, TileId, TileSpec};
use serde::Serialize;
use std::fmt;
use std::net::{Ipv4Addr, SocketAddr};
use std::time::{Duration, Instant};

/// Tiles in each grant: about half the queue a victim holds with 256 tiles over two peers, once
/// its first tiles are done.
pub const GRANT_TILES: usize = 32;
/// Exchanges before the timed ones, so that connection start-up and first allocations are not
/// counted.
const WARM_UP: usize = 20;
/// The whole measurement gives up after this long: loopback never needs it.
const TIME_LIMIT: Duration = Duration::from_secs(60);

/// The distribution of measured steal round trips, in microseconds.
#[derive(Debug, Serialize)]
pub struct StealRtt {
    pub exchanges: usize,
    pub grant_tiles: usize,
    pub request_bytes: usize,
    pub grant_bytes: usize,
    pub min_us: f64,
    pub p10_us: f64,
    pub median_us: f64,
    pub p90_us: f64,
    pub max_us: f64,
}

impl fmt::Display for StealRtt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "steal round trip on loopback (QUIC, mutual TLS; {}-byte request, {}-byte grant of {} tiles; n = {}): \
             median {:.0} us, p10 {:.0} us, p90 {:.0} us, min {:.0} us, max {:.0} us",
            self.request_bytes,
            self.grant_bytes,
            self.grant_tiles,
            self.exchanges,
            self.median_us,
            self.p10_us,
            self.p90_us,
            self.min_us,
            self.max_us
        )
    }
}

/// Times `exchanges` steal round trips (after a warm-up) between two peers on 127.0.0.1.
pub fn measure(exchanges: usize) -> Result<StealRtt, LabError> {
    // Two workers, as `tessera render` runs its transport: tokio only moves bytes and timers.
    let tokio = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| LabError::Net(e.to_string()))?;
    tokio.block_on(async {
        tokio::time::timeout(TIME_LIMIT, exchange(exchanges))
            .await
            .map_err(|_| {
                LabError::Net("the steal round trips did not finish within a minute".into())
            })?
    })
}

/// A transport error, as the message a user reads.
fn net(error: impl std::fmt::Display) -> LabError {
    LabError::Net(error.to_string())
}

async fn exchange(exchanges: usize) -> Result<StealRtt, LabError> {
    let certs = ClusterCerts::generate(2).map_err(net)?;
    let config = runtime::node::Options::default().net;
    let loopback = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    let (thief, mut thief_events) =
        Link::bind(loopback, &certs.peers()[0], config.clone(), decode).map_err(net)?;
    let (victim, mut victim_events) =
        Link::bind(loopback, &certs.peers()[1], config, decode).map_err(net)?;

    let grant_tiles: Vec<TileSpec> = (0..GRANT_TILES as u32)
        .map(|i| {
            let rect = balancer::Rect::new(16 * (i % 16), 16 * (i / 16), 16, 16);
            TileSpec::whole(TileId(i), rect, 1e6)
        })
        .collect();
    let grant_bytes = wire::encode(&Message::StealGrant {
        frame: FrameId(0),
        tiles: grant_tiles.clone(),
    })
    .len();
    let victim_addr = victim.local_addr().map_err(net)?;
    let answering = tokio::spawn(async move {
        while let Some(event) = victim_events.recv().await {
            if let Event::Message {
                conn,
                message: Message::StealRequest { frame, .. },
            } = event
            {
                let grant = wire::encode(&Message::StealGrant {
                    frame,
                    tiles: grant_tiles.clone(),
                });
                if victim.send(conn, &grant).await.is_err() {
                    break;
                }
            }
        }
    });

    let conn = thief
        .connect(victim_addr, Expect::Peer(1))
        .await
        .map_err(net)?;
    let mut rtts = Vec::with_capacity(exchanges);
    let mut request_bytes = 0;
    for i in 0..WARM_UP + exchanges {
        let request = wire::encode(&Message::StealRequest {
            frame: FrameId(i as u32),
            remaining: vec![(FrameId(i as u32), 0.0)],
        });
        request_bytes = request.len();
        let started = Instant::now();
        thief.send(conn, &request).await.map_err(net)?;
        loop {
            match thief_events
                .recv()
                .await
                .ok_or_else(|| net("the thief's transport stopped"))?
            {
                Event::Message {
                    message: Message::StealGrant { frame, .. },
                    ..
                } if frame == FrameId(i as u32) => break,
                Event::Closed { reason, .. } => {
                    return Err(net(format!("the connection closed: {reason:?}")));
                }
                _ => {}
            }
        }
        if i >= WARM_UP {
            rtts.push(started.elapsed().as_secs_f64() * 1e6);
        }
    }
    answering.abort();
    thief.shutdown().await;

    rtts.sort_by(f64::total_cmp);
    let at = |q: f64| rtts[((rtts.len() - 1) as f64 * q).round() as usize];
    Ok(StealRtt {
        exchanges,
        grant_tiles: GRANT_TILES,
        request_bytes,
        grant_bytes,
        min_us: at(0.0),
        p10_us: at(0.1),
        median_us: at(0.5),
        p90_us: at(0.9),
        max_us: at(1.0),
    })
}

fn decode(bytes: &[u8]) -> Result<Message, wire::WireError> {
    wire::decode(bytes, &wire::Limits::default())
}
