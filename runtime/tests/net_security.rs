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
    CertError, CloseCode, CloseReason, ClusterCerts, Config, ConnId, Direction, Event, Expect,
    Link, PeerIdentity, SendError, tls,
};
use tokio::sync::mpsc::Receiver;

/// Test messages carry this prefix; the test decoder refuses anything without it.
const MAGIC: &[u8] = b"TT1:";
/// A small limit, so that oversized messages are cheap to make.
const LIMIT: usize = 64 * 1024;

type Node = (Link<Vec<u8>>, Receiver<Event<Vec<u8>>>);

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

fn config() -> Config {
    Config {
        max_message_bytes: LIMIT,
        ..Config::default()
    }
}

fn node(identity: &PeerIdentity) -> Node {
    Link::bind(loopback(), identity, config(), decode).expect("binding a loopback node")
}

fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

/// Runs a test body under a time limit, so that a hang fails instead of stalling the suite.
async fn bounded<F: Future<Output = ()>>(body: F) {
    tokio::time::timeout(Duration::from_secs(20), body)
        .await
        .expect("test timed out");
}

async fn next(events: &mut Receiver<Event<Vec<u8>>>) -> Event<Vec<u8>> {
    events
        .recv()
        .await
        .expect("the link keeps its event channel open")
}

async fn expect_connected(events: &mut Receiver<Event<Vec<u8>>>) -> (ConnId, SocketAddr) {
    match next(events).await {
        Event::Connected { conn, remote, .. } => (conn, remote),
        other => panic!("expected a connection, got {other:?}"),
    }
}

async fn expect_message(events: &mut Receiver<Event<Vec<u8>>>) -> (ConnId, Vec<u8>) {
    match next(events).await {
        Event::Message { conn, message } => (conn, message),
        other => panic!("expected a message, got {other:?}"),
    }
}

/// A client endpoint that is not a `Link`, with whatever TLS it is given.
fn raw_endpoint(tls: rustls::ClientConfig) -> Endpoint {
    let mut endpoint = Endpoint::client(loopback()).expect("binding a raw client");
    let crypto = QuicClientConfig::try_from(tls).expect("ring has QUIC's initial suite");
    endpoint.set_default_client_config(quinn::ClientConfig::new(Arc::new(crypto)));
    endpoint
}

/// A rustls client that trusts `ca` and presents `client` (if any) as its certificate.
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

/// Connects a hostile client and, if its side of the handshake completes, has it try to send a
/// message; returns how its connection ended.
async fn attempt(endpoint: &Endpoint, server: SocketAddr) -> ConnectionError {
    let connecting = endpoint
        .connect(server, ANY_PEER_NAME)
        .expect("a valid connect call");
    match connecting.await {
        Err(error) => error,
        Ok(connection) => {
            if let Ok(mut stream) = connection.open_uni().await {
                let _ = stream.write_all(&framed(&message(b"let me in"))).await;
                let _ = stream.finish();
            }
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

/// Checks that a server still serves: a fresh peer connects, and a message goes through.
async fn assert_serves(server: &mut Node, client_identity: &PeerIdentity) {
    let (client, _client_events) = node(client_identity);
    let server_addr = server.0.local_addr().expect("a bound node");
    let conn = client
        .connect(server_addr, Expect::AnyPeer)
        .await
        .expect("a good peer connects");
    client
        .send(conn, &message(b"still there?"))
        .await
        .expect("sending to the server");
    let (_, remote) = expect_connected(&mut server.1).await;
    assert_eq!(remote, client.local_addr().expect("a bound node"));
    let (_, received) = expect_message(&mut server.1).await;
    assert_eq!(received, b"still there?");
}

#[tokio::test]
async fn message_round_trip_between_peers_of_one_ca() {
    bounded(async {
        let cluster = ClusterCerts::generate(2).expect("generating certificates");
        let (a, mut a_events) = node(&cluster.peers()[0]);
        let (b, mut b_events) = node(&cluster.peers()[1]);
        let b_addr = b.local_addr().expect("a bound node");

        let a_conn = a
            .connect(b_addr, Expect::Peer(1))
            .await
            .expect("connecting to peer 1");
        let Event::Connected {
            conn: b_conn,
            direction,
            certificate,
            ..
        } = next(&mut b_events).await
        else {
            panic!("peer 1 should see the connection first");
        };
        assert_eq!(direction, Direction::Inbound);
        assert!(
            certificate.certifies(0),
            "peer 0's certificate names peer 0"
        );
        assert!(!certificate.certifies(1), "and no other peer");
        match next(&mut a_events).await {
            Event::Connected {
                conn,
                direction,
                certificate,
                ..
            } => {
                assert_eq!((conn, direction), (a_conn, Direction::Outbound));
                assert!(certificate.certifies(1));
            }
            other => panic!("expected a connection, got {other:?}"),
        }

        a.send(a_conn, &message(b"steal?")).await.expect("sending");
        assert_eq!(
            expect_message(&mut b_events).await,
            (b_conn, b"steal?".to_vec())
        );
        b.send(b_conn, &message(b"tiles")).await.expect("replying");
        assert_eq!(
            expect_message(&mut a_events).await,
            (a_conn, b"tiles".to_vec())
        );

        a.close(a_conn, CloseCode::Normal, "done");
        match next(&mut b_events).await {
            Event::Closed { conn, reason } => {
                assert_eq!(conn, b_conn);
                assert_eq!(
                    reason,
                    CloseReason::Remote {
                        code: 0,
                        reason: "done".into()
                    }
                );
            }
            other => panic!("expected the close, got {other:?}"),
        }
        match next(&mut a_events).await {
            Event::Closed { reason, .. } => {
                assert_eq!(reason, CloseReason::Local(CloseCode::Normal))
            }
            other => panic!("expected the close, got {other:?}"),
        }
        assert!(matches!(
            a.send(a_conn, &message(b"late")).await,
            Err(SendError::UnknownConnection(_))
        ));
    })
    .await;
}

#[tokio::test]
async fn connecting_to_the_wrong_peer_is_refused() {
    bounded(async {
        let cluster = ClusterCerts::generate(3).expect("generating certificates");
        let (a, _a_events) = node(&cluster.peers()[0]);
        let mut server = node(&cluster.peers()[1]);
        let addr = server.0.local_addr().expect("a bound node");
        // Peer 1 answers at this address, but the caller wants peer 2.
        let refused = a.connect(addr, Expect::Peer(2)).await;
        assert!(refused.is_err(), "peer 1 passed for peer 2");
        assert_serves(&mut server, &cluster.peers()[2]).await;
    })
    .await;
}

#[tokio::test]
async fn client_with_certificate_from_another_ca_is_refused() {
    bounded(async {
        let cluster = ClusterCerts::generate(2).expect("generating certificates");
        let foreign = ClusterCerts::generate(1).expect("generating certificates");
        let mut server = node(&cluster.peers()[0]);
        let addr = server.0.local_addr().expect("a bound node");

        // Knows and trusts our CA, but its own certificate is signed by another.
        let impostor = raw_endpoint(rustls_client(
            &cluster.peers()[1],
            Some(&foreign.peers()[0]),
        ));
        let ended = attempt(&impostor, addr).await;
        assert!(
            is_tls_alert(&ended),
            "impostor not refused in the handshake: {ended:?}"
        );

        // A whole foreign cluster's node: refused as well (here by its own side of the check).
        let (stranger, _stranger_events) = node(&foreign.peers()[0]);
        assert!(stranger.connect(addr, Expect::AnyPeer).await.is_err());

        // Neither produced an event: the first thing the server reports is the good peer.
        assert_serves(&mut server, &cluster.peers()[1]).await;
    })
    .await;
}

#[tokio::test]
async fn client_without_certificate_is_refused() {
    bounded(async {
        let cluster = ClusterCerts::generate(2).expect("generating certificates");
        let mut server = node(&cluster.peers()[0]);
        let addr = server.0.local_addr().expect("a bound node");

        let anonymous = raw_endpoint(rustls_client(&cluster.peers()[1], None));
        let ended = attempt(&anonymous, addr).await;
        assert!(
            is_tls_alert(&ended),
            "anonymous client not refused in the handshake: {ended:?}"
        );

        assert_serves(&mut server, &cluster.peers()[1]).await;
    })
    .await;
}

/// Has a peer with a good certificate write `bytes` on one stream, then checks that both ends see
/// the connection closed with `expected`, and that the server still serves a good peer.
async fn assert_stream_closes_connection(bytes: Vec<u8>, expected: CloseCode) {
    let cluster = ClusterCerts::generate(3).expect("generating certificates");
    let mut server = node(&cluster.peers()[0]);
    let addr = server.0.local_addr().expect("a bound node");
    let hostile = raw_endpoint(rustls_client(
        &cluster.peers()[1],
        Some(&cluster.peers()[1]),
    ));
    let connection = hostile
        .connect(addr, ANY_PEER_NAME)
        .expect("a valid connect call")
        .await
        .expect("a peer with a good certificate gets in");
    let (conn, _) = expect_connected(&mut server.1).await;

    let mut stream = connection.open_uni().await.expect("opening a stream");
    // The server may close the connection before all of it is written: that is the point.
    let _ = stream.write_all(&bytes).await;
    let _ = stream.finish();

    match connection.closed().await {
        ConnectionError::ApplicationClosed(close) => {
            assert_eq!(
                close.error_code,
                expected.varint(),
                "reason: {:?}",
                close.reason
            );
        }
        other => panic!("expected an application close, got {other:?}"),
    }
    match next(&mut server.1).await {
        Event::Closed {
            conn: closed,
            reason,
        } => {
            assert_eq!(closed, conn);
            assert_eq!(reason, CloseReason::Local(expected));
        }
        other => panic!("expected the close, got {other:?}"),
    }
    assert_serves(&mut server, &cluster.peers()[2]).await;
}

#[tokio::test]
async fn random_bytes_in_a_frame_are_malformed() {
    let payload = noise(512, 0x5eed);
    assert!(decode(&payload).is_err(), "the noise must not decode");
    bounded(assert_stream_closes_connection(
        framed(&payload),
        CloseCode::Malformed,
    ))
    .await;
}

#[tokio::test]
async fn unframed_random_bytes_close_the_connection() {
    let bytes = noise(4096, 0xfeed);
    // Read as a frame, the noise declares a length far over the limit.
    let declared = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
    assert!(declared as usize > LIMIT);
    bounded(assert_stream_closes_connection(bytes, CloseCode::TooLarge)).await;
}

#[tokio::test]
async fn truncated_frame_closes_the_connection() {
    let mut cut = framed(&message(&[7; 100]));
    cut.truncate(50);
    bounded(assert_stream_closes_connection(cut, CloseCode::Truncated)).await;
}

#[tokio::test]
async fn truncated_header_closes_the_connection() {
    bounded(assert_stream_closes_connection(
        vec![9, 0],
        CloseCode::Truncated,
    ))
    .await;
}

#[tokio::test]
async fn oversized_message_closes_the_connection() {
    let big = framed(&message(&vec![1; LIMIT]));
    bounded(assert_stream_closes_connection(big, CloseCode::TooLarge)).await;
}

#[tokio::test]
async fn bytes_beyond_the_declared_length_are_malformed() {
    let mut long = framed(&message(b"short"));
    long.extend_from_slice(b"and then some");
    bounded(assert_stream_closes_connection(long, CloseCode::Malformed)).await;
}

#[tokio::test]
async fn a_decoder_panic_costs_only_that_connection() {
    bounded(assert_stream_closes_connection(
        framed(b"TT1:panic"),
        CloseCode::Malformed,
    ))
    .await;
}

#[tokio::test]
async fn an_abandoned_message_is_dropped_and_the_connection_lives() {
    bounded(async {
        let cluster = ClusterCerts::generate(2).expect("generating certificates");
        let mut server = node(&cluster.peers()[0]);
        let addr = server.0.local_addr().expect("a bound node");
        let client = raw_endpoint(rustls_client(
            &cluster.peers()[1],
            Some(&cluster.peers()[1]),
        ));
        let connection = client
            .connect(addr, ANY_PEER_NAME)
            .expect("a valid connect call")
            .await
            .expect("a peer with a good certificate gets in");
        let (conn, _) = expect_connected(&mut server.1).await;

        let mut abandoned = connection.open_uni().await.expect("opening a stream");
        let mut cut = framed(&message(b"never mind"));
        cut.truncate(8);
        abandoned.write_all(&cut).await.expect("writing");
        abandoned.reset(0u32.into()).expect("resetting");
        let mut whole = connection.open_uni().await.expect("opening a stream");
        whole
            .write_all(&framed(&message(b"this one")))
            .await
            .expect("writing");
        whole.finish().expect("finishing");

        assert_eq!(
            expect_message(&mut server.1).await,
            (conn, b"this one".to_vec())
        );
        // Round trips after the reset, by which time the server has long seen it: the connection
        // must still carry messages both ways.
        server
            .0
            .send(conn, &message(b"reply"))
            .await
            .expect("the server can still send");
        let mut reply = connection.accept_uni().await.expect("the connection lives");
        assert_eq!(
            reply.read_to_end(64).await.expect("reading the reply"),
            framed(&message(b"reply"))
        );
        let mut again = connection.open_uni().await.expect("opening a stream");
        again
            .write_all(&framed(&message(b"again")))
            .await
            .expect("writing");
        again.finish().expect("finishing");
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
async fn sending_over_the_limit_is_refused_locally() {
    bounded(async {
        let cluster = ClusterCerts::generate(2).expect("generating certificates");
        let (a, _a_events) = node(&cluster.peers()[0]);
        let (b, mut b_events) = node(&cluster.peers()[1]);
        let conn = a
            .connect(b.local_addr().expect("a bound node"), Expect::Peer(1))
            .await
            .expect("connecting");
        let refused = a.send(conn, &vec![0; LIMIT + 1]).await;
        assert!(
            matches!(refused, Err(SendError::TooLarge { len, max: LIMIT }) if len == LIMIT + 1)
        );
        a.send(conn, &message(b"fits")).await.expect("sending");
        expect_connected(&mut b_events).await;
        assert_eq!(expect_message(&mut b_events).await.1, b"fits");
    })
    .await;
}

#[tokio::test]
async fn a_cancelled_send_resets_its_stream() {
    bounded(async {
        let cluster = ClusterCerts::generate(2).expect("generating certificates");
        let (a, _a_events) = Link::bind(
            loopback(),
            &cluster.peers()[0],
            Config {
                max_message_bytes: 4 << 20,
                ..Config::default()
            },
            decode,
        )
        .expect("binding");
        // A bare server that takes the stream but reads nothing, so that flow control stalls the
        // sender after 64 KiB, mid-message.
        let mut transport = quinn::TransportConfig::default();
        transport.stream_receive_window((64u32 * 1024).into());
        let crypto = tls::server_config(&cluster.peers()[1]).expect("a server configuration");
        let mut server_config = quinn::ServerConfig::with_crypto(Arc::new(crypto));
        server_config.transport_config(Arc::new(transport));
        let server = Endpoint::server(server_config, loopback()).expect("binding");
        let addr = server.local_addr().expect("a bound endpoint");
        let accepting = tokio::spawn(async move {
            let incoming = server.accept().await.expect("an incoming connection");
            let connection = incoming.await.expect("a handshake");
            let stream = connection.accept_uni().await.expect("a stream");
            (server, connection, stream)
        });

        let conn = a.connect(addr, Expect::Peer(1)).await.expect("connecting");
        let big = message(&vec![5; 1 << 20]);
        let stalled = tokio::time::timeout(Duration::from_millis(300), a.send(conn, &big)).await;
        assert!(stalled.is_err(), "the send should stall on flow control");

        let (_server, _connection, mut stream) = accepting.await.expect("the server task");
        match stream.read_to_end(4 << 20).await {
            Err(quinn::ReadToEndError::Read(quinn::ReadError::Reset(_))) => {}
            other => panic!("a cancelled send must reset its stream, got {other:?}"),
        }
    })
    .await;
}

#[tokio::test]
async fn connections_over_the_limit_are_refused() {
    bounded(async {
        let cluster = ClusterCerts::generate(3).expect("generating certificates");
        let (server, mut server_events) = Link::bind(
            loopback(),
            &cluster.peers()[0],
            Config {
                max_connections: 1,
                ..config()
            },
            decode,
        )
        .expect("binding");
        let addr = server.local_addr().expect("a bound node");
        let (a, _a_events) = node(&cluster.peers()[1]);
        let (b, _b_events) = node(&cluster.peers()[2]);

        let a_conn = a
            .connect(addr, Expect::AnyPeer)
            .await
            .expect("the first gets in");
        expect_connected(&mut server_events).await;
        assert!(
            b.connect(addr, Expect::AnyPeer).await.is_err(),
            "the second got in"
        );

        a.send(a_conn, &message(b"still served"))
            .await
            .expect("sending");
        assert_eq!(expect_message(&mut server_events).await.1, b"still served");

        a.close(a_conn, CloseCode::Normal, "making room");
        assert!(matches!(
            next(&mut server_events).await,
            Event::Closed { .. }
        ));
        b.connect(addr, Expect::AnyPeer)
            .await
            .expect("a freed place is taken again");
    })
    .await;
}

#[tokio::test]
async fn shutdown_and_a_dropped_receiver_tell_the_peers() {
    bounded(async {
        let cluster = ClusterCerts::generate(3).expect("generating certificates");
        let (a, mut a_events) = node(&cluster.peers()[0]);
        let (b, mut b_events) = node(&cluster.peers()[1]);
        let (c, c_events) = node(&cluster.peers()[2]);
        let b_addr = b.local_addr().expect("a bound node");
        let c_addr = c.local_addr().expect("a bound node");
        a.connect(b_addr, Expect::Peer(1))
            .await
            .expect("connecting");
        expect_connected(&mut a_events).await;
        expect_connected(&mut b_events).await;

        b.shutdown().await;
        let shutdown = CloseCode::Shutdown.varint().into_inner();
        match next(&mut a_events).await {
            Event::Closed {
                reason: CloseReason::Remote { code, .. },
                ..
            } => assert_eq!(code, shutdown),
            other => panic!("expected a remote close, got {other:?}"),
        }
        match next(&mut b_events).await {
            Event::Closed { reason, .. } => {
                assert_eq!(reason, CloseReason::Local(CloseCode::Shutdown))
            }
            other => panic!("expected a local close, got {other:?}"),
        }
        assert!(
            a.connect(b_addr, Expect::Peer(1)).await.is_err(),
            "b still accepts"
        );

        a.connect(c_addr, Expect::Peer(2))
            .await
            .expect("connecting");
        expect_connected(&mut a_events).await;
        // The driver of c goes away without a word: c closes its connections all the same.
        drop(c_events);
        match next(&mut a_events).await {
            Event::Closed {
                reason: CloseReason::Remote { code, .. },
                ..
            } => assert_eq!(code, shutdown),
            other => panic!("expected a remote close, got {other:?}"),
        }
    })
    .await;
}

#[test]
fn keygen_files_load_back_and_are_never_overwritten() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let cluster = ClusterCerts::generate(3).expect("generating certificates");
    cluster.write_pem(dir.path()).expect("writing PEM files");

    let loaded = PeerIdentity::load(dir.path(), 2).expect("loading peer 2");
    assert_eq!(loaded.index(), 2);
    assert_eq!(loaded.cert(), cluster.peers()[2].cert());
    assert_eq!(loaded.ca(), cluster.peers()[2].ca());
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(dir.path().join("peer-2-key.pem"))
            .expect("the key file exists")
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "private key readable by others: {mode:o}");
    }

    assert!(matches!(
        cluster.write_pem(dir.path()),
        Err(CertError::Exists { .. })
    ));
    assert!(matches!(
        PeerIdentity::load(dir.path(), 3),
        Err(CertError::Io { .. })
    ));

    // Peer 0's certificate and key under peer 1's name: the certificate does not name peer 1.
    let renamed = tempfile::tempdir().expect("a temporary directory");
    for (from, to) in [
        ("ca.pem", "ca.pem"),
        ("peer-0.pem", "peer-1.pem"),
        ("peer-0-key.pem", "peer-1-key.pem"),
    ] {
        std::fs::copy(dir.path().join(from), renamed.path().join(to)).expect("copying");
    }
    assert!(matches!(
        PeerIdentity::load(renamed.path(), 1),
        Err(CertError::WrongPeer { index: 1 })
    ));

    // Another cluster's CA: peer 0's certificate was not issued by it.
    let foreign = tempfile::tempdir().expect("a temporary directory");
    ClusterCerts::generate(1)
        .expect("generating certificates")
        .write_pem(foreign.path())
        .expect("writing PEM files");
    std::fs::copy(foreign.path().join("ca.pem"), renamed.path().join("ca.pem")).expect("copying");
    for file in ["peer-0.pem", "peer-0-key.pem"] {
        std::fs::copy(dir.path().join(file), renamed.path().join(file)).expect("copying");
    }
    assert!(matches!(
        PeerIdentity::load(renamed.path(), 0),
        Err(CertError::NotIssuedByCa { index: 0, .. })
    ));

    std::fs::write(renamed.path().join("ca.pem"), "not PEM").expect("writing");
    assert!(matches!(
        PeerIdentity::load(renamed.path(), 0),
        Err(CertError::Pem { .. })
    ));
}

#[tokio::test]
async fn identities_loaded_from_files_connect() {
    bounded(async {
        let dir = tempfile::tempdir().expect("a temporary directory");
        ClusterCerts::generate(2)
            .expect("generating certificates")
            .write_pem(dir.path())
            .expect("writing PEM files");
        let mut server = node(&PeerIdentity::load(dir.path(), 0).expect("loading peer 0"));
        assert_serves(
            &mut server,
            &PeerIdentity::load(dir.path(), 1).expect("loading peer 1"),
        )
        .await;
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
        let cluster = ClusterCerts::generate(2).expect("generating certificates");
        let big_config = || Config {
            max_message_bytes: 2 * BIG,
            ..Config::default()
        };
        let (a, mut a_events) =
            Link::bind(loopback(), &cluster.peers()[0], big_config(), decode).expect("binding");
        let (b, mut b_events) =
            Link::bind(loopback(), &cluster.peers()[1], big_config(), decode).expect("binding");
        let conn = a
            .connect(b.local_addr().expect("a bound node"), Expect::Peer(1))
            .await
            .expect("connecting");
        expect_connected(&mut a_events).await;

        // Peer 1 echoes small messages and acknowledges the big ones once all arrived intact.
        tokio::spawn(async move {
            // Messages may arrive in any order, so the big ones are counted, not ranked.
            let (mut received, mut intact) = (0, 0);
            while let Some(event) = b_events.recv().await {
                let Event::Message { conn, message: m } = event else { continue };
                if m.len() < 64 {
                    let _ = b.send(conn, &message(&m)).await;
                } else {
                    received += 1;
                    intact += usize::from(m.len() == BIG && m.iter().all(|&byte| byte == m[0]));
                    if received == usize::from(BIG_COUNT) {
                        let _ = b.send(conn, &message(&intact.to_le_bytes())).await;
                    }
                }
            }
        });

        let mut rtts = Vec::with_capacity(ROUND_TRIPS);
        for i in 0..ROUND_TRIPS {
            let ping = (i as u64).to_le_bytes();
            let start = Instant::now();
            a.send(conn, &message(&ping)).await.expect("sending");
            assert_eq!(expect_message(&mut a_events).await.1, ping);
            rtts.push(start.elapsed());
        }
        rtts.sort();

        let start = Instant::now();
        for i in 0..BIG_COUNT {
            a.send(conn, &message(&vec![i; BIG])).await.expect("sending");
        }
        let intact = expect_message(&mut a_events).await.1;
        let elapsed = start.elapsed();
        assert_eq!(intact, usize::from(BIG_COUNT).to_le_bytes());

        let megabytes = f64::from(BIG_COUNT) * (BIG + MAGIC.len()) as f64 / 1e6;
        eprintln!(
            "loopback: round trip of a 12-byte message median {:?} (p10 {:?}, p90 {:?}, n = {ROUND_TRIPS}); \
             {BIG_COUNT} x 1 MiB in {elapsed:?} = {:.0} MB/s",
            rtts[ROUND_TRIPS / 2],
            rtts[ROUND_TRIPS / 10],
            rtts[ROUND_TRIPS * 9 / 10],
            megabytes / elapsed.as_secs_f64(),
        );
    })
    .await;
}
