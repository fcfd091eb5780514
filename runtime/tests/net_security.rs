//! The QUIC transport under attack, over real QUIC on 127.0.0.1: only peers holding a certificate
//! of the cluster CA get through the handshake, and a connected peer that sends anything malformed
//! loses its connection while the node goes on serving the others.
//!
//! Hostile clients are built here from quinn and rustls directly, as an attacker would, not from
//! the helpers under test. Every test runs under a time limit.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use quinn::crypto::rustls::QuicClientConfig;
use quinn::{ConnectionError, Endpoint};
use runtime::net::certs::ANY_PEER_NAME;
use runtime::net::{
    CloseCode, CloseReason, ClusterCerts, Config, ConnId, Direction, Event, Expect, Link,
    PeerIdentity, SendError, tls,
};
use tokio::sync::mpsc::Receiver;

/// The transport's limits on messages and connections.
#[path = "net_security/limits.rs"]
mod limits;

/// Malformed bytes from a peer with a good certificate.
#[path = "net_security/malformed.rs"]
mod malformed;

/// Test messages carry this prefix; the test decoder refuses anything without it.
const MAGIC: &[u8] = b"TT1:";
/// A small limit, so that oversized messages are cheap to make.
const LIMIT: usize = 64 * 1024;

type Events = Receiver<Event<Vec<u8>>>;
type Node = (Link<Vec<u8>>, Events);

fn decode(bytes: &[u8]) -> Result<Vec<u8>, String> {
    if bytes == b"TT1:panic" {
        panic!("test decoder told to panic");
    }
    bytes
        .strip_prefix(MAGIC)
        .map(<[u8]>::to_vec)
        .ok_or_else(|| "no magic prefix".to_owned())
}

fn message(payload: &[u8]) -> Vec<u8> {
    [MAGIC, payload].concat()
}

/// The frame the transport puts on a stream: a 4-byte little-endian length, then the bytes.
fn framed(bytes: &[u8]) -> Vec<u8> {
    let len = u32::try_from(bytes.len()).expect("test messages are small");
    [&len.to_le_bytes()[..], bytes].concat()
}

/// Deterministic noise (xorshift64), so that a failure can be replayed.
fn noise(len: usize, mut state: u64) -> Vec<u8> {
    (0..len)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state.to_le_bytes()[0]
        })
        .collect()
}

fn cluster(peers: u32) -> ClusterCerts {
    ClusterCerts::generate(peers).expect("generating certificates")
}

fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

fn bind(identity: &PeerIdentity, config: Config) -> Node {
    Link::bind(loopback(), identity, config, decode).expect("binding a loopback node")
}

/// A node with the small test limit.
fn node(identity: &PeerIdentity) -> Node {
    let config = Config {
        max_message_bytes: LIMIT,
        ..Config::default()
    };
    bind(identity, config)
}

fn addr(link: &Link<Vec<u8>>) -> SocketAddr {
    link.local_addr().expect("a bound node")
}

/// Runs a test body under a time limit, so that a hang fails instead of stalling the suite.
async fn bounded<F: Future<Output = ()>>(body: F) {
    tokio::time::timeout(Duration::from_secs(20), body)
        .await
        .expect("test timed out");
}

async fn next(events: &mut Events) -> Event<Vec<u8>> {
    let event = events.recv().await;
    event.expect("the link keeps its event channel open")
}

async fn expect_connected(events: &mut Events) -> (ConnId, SocketAddr) {
    match next(events).await {
        Event::Connected { conn, remote, .. } => (conn, remote),
        other => panic!("expected a connection, got {other:?}"),
    }
}

async fn expect_message(events: &mut Events) -> (ConnId, Vec<u8>) {
    match next(events).await {
        Event::Message { conn, message } => (conn, message),
        other => panic!("expected a message, got {other:?}"),
    }
}

async fn expect_closed(events: &mut Events) -> (ConnId, CloseReason) {
    match next(events).await {
        Event::Closed { conn, reason } => (conn, reason),
        other => panic!("expected a close, got {other:?}"),
    }
}

/// A rustls client that trusts `ca`'s CA and presents `client`'s certificate, if any.
fn rustls_client(ca: &PeerIdentity, client: Option<&PeerIdentity>) -> rustls::ClientConfig {
    let mut roots = rustls::RootCertStore::empty();
    roots.add(ca.ca().clone()).expect("a valid CA certificate");
    let builder = rustls::ClientConfig::builder_with_provider(tls::provider())
        .with_protocol_versions(&[&rustls::version::TLS13])
        .expect("ring supports TLS 1.3")
        .with_root_certificates(roots);
    let mut config = match client {
        Some(id) => builder
            .with_client_auth_cert(vec![id.cert().clone()], id.key())
            .expect("a matching certificate and key"),
        None => builder.with_no_client_auth(),
    };
    config.alpn_protocols = vec![tls::ALPN.to_vec()];
    config
}

/// Starts a handshake from a client endpoint that is not a `Link`, with whatever TLS it is given.
fn raw_connect(tls: rustls::ClientConfig, server: SocketAddr) -> quinn::Connecting {
    let mut endpoint = Endpoint::client(loopback()).expect("binding a raw client");
    let crypto = QuicClientConfig::try_from(tls).expect("ring has QUIC's initial suite");
    endpoint.set_default_client_config(quinn::ClientConfig::new(Arc::new(crypto)));
    let connecting = endpoint.connect(server, ANY_PEER_NAME);
    connecting.expect("a valid connect call")
}

/// A raw connection with `identity`'s good certificate, for sending what a `Link` never would.
async fn raw_peer(identity: &PeerIdentity, server: SocketAddr) -> quinn::Connection {
    let connecting = raw_connect(rustls_client(identity, Some(identity)), server);
    connecting
        .await
        .expect("a peer with a good certificate gets in")
}

/// Writes `bytes` on a new stream and ends it; errors are ignored, as the server may close the
/// connection before all of it is written.
async fn write_stream(connection: &quinn::Connection, bytes: &[u8]) {
    if let Ok(mut stream) = connection.open_uni().await {
        let _ = stream.write_all(bytes).await;
        let _ = stream.finish();
    }
}

/// Connects a client that should not get in and has it try to send a message anyway; returns
/// how its connection ended.
async fn intrude(tls: rustls::ClientConfig, server: SocketAddr) -> ConnectionError {
    match raw_connect(tls, server).await {
        Err(error) => error,
        Ok(connection) => {
            write_stream(&connection, &framed(&message(b"let me in"))).await;
            connection.closed().await
        }
    }
}

/// Whether a connection ended by a TLS alert, that is, in the handshake.
fn is_tls_alert(error: &ConnectionError) -> bool {
    let code = match error {
        ConnectionError::ConnectionClosed(close) => close.error_code,
        ConnectionError::TransportError(error) => error.code,
        _ => return false,
    };
    (0x100..0x200).contains(&u64::from(code))
}

/// Checks that a server still serves, and reported nothing before: a fresh peer connects, its
/// connection is the next event, and its message goes through.
async fn assert_serves(server: &mut Node, client_identity: &PeerIdentity) {
    let (client, _client_events) = node(client_identity);
    let conn = client.connect(addr(&server.0), Expect::AnyPeer).await;
    let conn = conn.expect("a good peer connects");
    let sent = client.send(conn, &message(b"still there?")).await;
    sent.expect("sending to the server");
    let (_, remote) = expect_connected(&mut server.1).await;
    assert_eq!(remote, addr(&client));
    assert_eq!(expect_message(&mut server.1).await.1, b"still there?");
}

#[tokio::test]
async fn message_round_trip_between_peers_of_one_ca() {
    bounded(async {
        let cluster = cluster(2);
        let (a, mut a_events) = node(&cluster.peers()[0]);
        let (b, mut b_events) = node(&cluster.peers()[1]);
        let a_conn = a.connect(addr(&b), Expect::Peer(1)).await;
        let a_conn = a_conn.expect("connecting to peer 1");

        // Each side learns from the certificate which peer is at the other end.
        let sides = [
            (&mut b_events, Direction::Inbound, 0, 1),
            (&mut a_events, Direction::Outbound, 1, 0),
        ];
        for (events, expected, remote_peer, not_remote_peer) in sides {
            let Event::Connected {
                direction,
                certificate,
                ..
            } = next(events).await
            else {
                panic!("a connection is reported before anything else");
            };
            assert_eq!(direction, expected);
            assert!(certificate.certifies(remote_peer));
            assert!(!certificate.certifies(not_remote_peer));
        }
        a.send(a_conn, &message(b"steal?")).await.expect("sending");
        let (b_conn, received) = expect_message(&mut b_events).await;
        assert_eq!(received, b"steal?");
        b.send(b_conn, &message(b"tiles")).await.expect("replying");
        assert_eq!(
            expect_message(&mut a_events).await,
            (a_conn, b"tiles".to_vec())
        );
        // QUIC's path estimate, which the node hands to its core: loopback is well under the
        // 333 ms QUIC assumes before its first sample.
        let rtt = a.rtt(a_conn).expect("an open connection has an RTT");
        assert!(rtt < Duration::from_millis(100), "loopback RTT {rtt:?}");

        a.close(a_conn, CloseCode::Normal, "done");
        let remote = CloseReason::Remote {
            code: 0,
            reason: "done".into(),
        };
        assert_eq!(expect_closed(&mut b_events).await, (b_conn, remote));
        let local = CloseReason::Local(CloseCode::Normal);
        assert_eq!(expect_closed(&mut a_events).await, (a_conn, local));
        assert_eq!(a.rtt(a_conn), None, "a closed connection has none");
        let late = a.send(a_conn, &message(b"late")).await;
        assert!(matches!(late, Err(SendError::UnknownConnection(_))));
    })
    .await;
}

#[tokio::test]
async fn connecting_to_the_wrong_peer_is_refused() {
    bounded(async {
        let cluster = cluster(3);
        let (a, _a_events) = node(&cluster.peers()[0]);
        let mut server = node(&cluster.peers()[1]);
        // Peer 1 answers at this address, but the caller wants peer 2.
        let refused = a.connect(addr(&server.0), Expect::Peer(2)).await;
        assert!(refused.is_err(), "peer 1 passed for peer 2");
        assert_serves(&mut server, &cluster.peers()[2]).await;
    })
    .await;
}

#[tokio::test]
async fn client_with_certificate_from_another_ca_is_refused() {
    bounded(async {
        let (cluster, foreign) = (cluster(2), cluster(1));
        let mut server = node(&cluster.peers()[0]);
        let server_addr = addr(&server.0);

        // Knows and trusts our CA, but its own certificate is signed by another.
        let impostor = rustls_client(&cluster.peers()[1], Some(&foreign.peers()[0]));
        let ended = intrude(impostor, server_addr).await;
        assert!(
            is_tls_alert(&ended),
            "impostor not refused in the handshake: {ended:?}"
        );

        // A whole foreign cluster's node: refused as well (here by its own side of the check).
        let (stranger, _stranger_events) = node(&foreign.peers()[0]);
        assert!(
            stranger
                .connect(server_addr, Expect::AnyPeer)
                .await
                .is_err()
        );

        // Neither produced an event: the first thing the server reports is the good peer.
        assert_serves(&mut server, &cluster.peers()[1]).await;
    })
    .await;
}

#[tokio::test]
async fn client_without_certificate_is_refused() {
    bounded(async {
        let cluster = cluster(2);
        let mut server = node(&cluster.peers()[0]);
        let anonymous = rustls_client(&cluster.peers()[1], None);
        let ended = intrude(anonymous, addr(&server.0)).await;
        assert!(
            is_tls_alert(&ended),
            "anonymous client not refused in the handshake: {ended:?}"
        );
        assert_serves(&mut server, &cluster.peers()[1]).await;
    })
    .await;
}

#[tokio::test]
async fn an_abandoned_message_is_dropped_and_the_connection_lives() {
    bounded(async {
        let cluster = cluster(2);
        let mut server = node(&cluster.peers()[0]);
        let connection = raw_peer(&cluster.peers()[1], addr(&server.0)).await;
        let (conn, _) = expect_connected(&mut server.1).await;

        let mut abandoned = connection.open_uni().await.expect("opening a stream");
        let cut = &framed(&message(b"never mind"))[..8];
        abandoned.write_all(cut).await.expect("writing");
        abandoned.reset(0u32.into()).expect("resetting");
        write_stream(&connection, &framed(&message(b"this one"))).await;
        assert_eq!(
            expect_message(&mut server.1).await,
            (conn, b"this one".to_vec())
        );

        // Round trips after the reset, by which time the server has long seen it: the connection
        // must still carry messages both ways.
        let sent = server.0.send(conn, &message(b"reply")).await;
        sent.expect("the server can still send");
        let mut reply = connection.accept_uni().await.expect("the connection lives");
        let reply = reply.read_to_end(64).await.expect("reading the reply");
        assert_eq!(reply, framed(&message(b"reply")));
        write_stream(&connection, &framed(&message(b"again"))).await;
        assert_eq!(
            expect_message(&mut server.1).await,
            (conn, b"again".to_vec())
        );
        assert!(
            connection.close_reason().is_none(),
            "the connection was closed"
        );
        assert!(server.1.try_recv().is_err(), "the server reported more");
    })
    .await;
}

#[tokio::test]
async fn shutdown_and_a_dropped_receiver_tell_the_peers() {
    bounded(async {
        let cluster = cluster(3);
        let (a, mut a_events) = node(&cluster.peers()[0]);
        let (b, mut b_events) = node(&cluster.peers()[1]);
        let (c, c_events) = node(&cluster.peers()[2]);
        let shutdown = CloseCode::Shutdown.varint().into_inner();
        let closed_by_peer =
            |reason| matches!(reason, CloseReason::Remote { code, .. } if code == shutdown);

        a.connect(addr(&b), Expect::Peer(1))
            .await
            .expect("connecting");
        expect_connected(&mut a_events).await;
        expect_connected(&mut b_events).await;
        b.shutdown().await;
        assert!(closed_by_peer(expect_closed(&mut a_events).await.1));
        let (_, reason) = expect_closed(&mut b_events).await;
        assert_eq!(reason, CloseReason::Local(CloseCode::Shutdown));
        let after = a.connect(addr(&b), Expect::Peer(1)).await;
        assert!(after.is_err(), "b still accepts");

        a.connect(addr(&c), Expect::Peer(2))
            .await
            .expect("connecting");
        expect_connected(&mut a_events).await;
        // The driver of c goes away without a word: c closes its connections all the same.
        drop(c_events);
        assert!(closed_by_peer(expect_closed(&mut a_events).await.1));
    })
    .await;
}

#[tokio::test]
async fn identities_loaded_from_files_connect() {
    bounded(async {
        let dir = tempfile::tempdir().expect("a temporary directory");
        cluster(2).write_pem(dir.path()).expect("writing PEM files");
        let load = |index| PeerIdentity::load(dir.path(), index).expect("loading a peer");
        let mut server = node(&load(0));
        assert_serves(&mut server, &load(1)).await;
    })
    .await;
}

/// Loopback timings, reported and not asserted: speed belongs to benchmarks. What is asserted is
/// that every echo and every 1 MB message arrives intact. Run alone, with `--nocapture`, for
/// figures that other tests running alongside do not disturb.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn loopback_round_trips_and_large_messages_arrive_intact() {
    const ROUND_TRIPS: usize = 300;
    const BIG: usize = 1 << 20;
    const BIG_COUNT: u8 = 64;
    bounded(async {
        let cluster = cluster(2);
        let config = Config {
            max_message_bytes: 2 * BIG,
            ..Config::default()
        };
        let (a, mut a_events) = bind(&cluster.peers()[0], config.clone());
        let (b, mut b_events) = bind(&cluster.peers()[1], config);
        let conn = a
            .connect(addr(&b), Expect::Peer(1))
            .await
            .expect("connecting");
        expect_connected(&mut a_events).await;

        // Peer 1 echoes small messages and acknowledges the big ones once all arrived intact.
        tokio::spawn(async move {
            // Messages may arrive in any order, so the big ones are counted, not ranked.
            let (mut received, mut intact) = (0, 0);
            while let Some(event) = b_events.recv().await {
                let Event::Message { conn, message: m } = event else {
                    continue;
                };
                if m.len() < 64 {
                    let _ = b.send(conn, &message(&m)).await;
                    continue;
                }
                received += 1;
                intact += usize::from(m.len() == BIG && m.iter().all(|&byte| byte == m[0]));
                if received == usize::from(BIG_COUNT) {
                    let _ = b.send(conn, &message(&intact.to_le_bytes())).await;
                }
            }
        });

        let mut rtts = Vec::with_capacity(ROUND_TRIPS);
        for i in 0..ROUND_TRIPS as u64 {
            let start = Instant::now();
            a.send(conn, &message(&i.to_le_bytes()))
                .await
                .expect("sending");
            assert_eq!(expect_message(&mut a_events).await.1, i.to_le_bytes());
            rtts.push(start.elapsed());
        }
        rtts.sort();

        let start = Instant::now();
        for i in 0..BIG_COUNT {
            a.send(conn, &message(&vec![i; BIG]))
                .await
                .expect("sending");
        }
        let intact = expect_message(&mut a_events).await.1;
        let elapsed = start.elapsed();
        assert_eq!(intact, usize::from(BIG_COUNT).to_le_bytes());

        let megabytes = f64::from(BIG_COUNT) * (BIG + MAGIC.len()) as f64 / 1e6;
        let percentile = |p: usize| rtts[ROUND_TRIPS * p / 100];
        eprintln!(
            "loopback: round trip of a 12-byte message median {:?} (p10 {:?}, p90 {:?}, \
             n = {ROUND_TRIPS}); {BIG_COUNT} x 1 MiB in {elapsed:?} = {:.0} MB/s",
            percentile(50),
            percentile(10),
            percentile(90),
            megabytes / elapsed.as_secs_f64(),
        );
    })
    .await;
}
