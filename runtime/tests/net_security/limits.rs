//! The transport's limits: a send over the message limit is refused before it leaves, a cancelled
//! send resets its stream, and connections past the limit are refused.

use super::*;

#[tokio::test]
async fn sending_over_the_limit_is_refused_locally() {
    bounded(async {
        let cluster = cluster(2);
        let (a, _a_events) = node(&cluster.peers()[0]);
        let (b, mut b_events) = node(&cluster.peers()[1]);
        let conn = a
            .connect(addr(&b), Expect::Peer(1))
            .await
            .expect("connecting");
        let refused = a.send(conn, &vec![0; LIMIT + 1]).await;
        let expected = LIMIT + 1;
        assert!(matches!(refused, Err(SendError::TooLarge { len, max: LIMIT }) if len == expected));
        a.send(conn, &message(b"fits")).await.expect("sending");
        expect_connected(&mut b_events).await;
        assert_eq!(expect_message(&mut b_events).await.1, b"fits");
    })
    .await;
}

#[tokio::test]
async fn a_cancelled_send_resets_its_stream() {
    bounded(async {
        let cluster = cluster(2);
        let config = Config {
            max_message_bytes: 4 << 20,
            ..Config::default()
        };
        let (a, _a_events) = bind(&cluster.peers()[0], config);
        // A bare server that takes the stream but reads nothing, so that flow control stalls the
        // sender after 64 KiB, mid-message.
        let mut transport = quinn::TransportConfig::default();
        transport.stream_receive_window((64u32 * 1024).into());
        let crypto = tls::server_config(&cluster.peers()[1]).expect("a server configuration");
        let mut server_config = quinn::ServerConfig::with_crypto(Arc::new(crypto));
        server_config.transport_config(Arc::new(transport));
        let server = Endpoint::server(server_config, loopback()).expect("binding");
        let server_addr = server.local_addr().expect("a bound endpoint");
        let accepting = tokio::spawn(async move {
            let incoming = server.accept().await.expect("an incoming connection");
            let connection = incoming.await.expect("a handshake");
            let stream = connection.accept_uni().await.expect("a stream");
            (server, connection, stream)
        });

        let conn = a
            .connect(server_addr, Expect::Peer(1))
            .await
            .expect("connecting");
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
        let cluster = cluster(3);
        let config = Config {
            max_connections: 1,
            ..Config::default()
        };
        let (server, mut server_events) = bind(&cluster.peers()[0], config);
        let (a, _a_events) = node(&cluster.peers()[1]);
        let (b, _b_events) = node(&cluster.peers()[2]);

        let a_conn = a.connect(addr(&server), Expect::AnyPeer).await;
        let a_conn = a_conn.expect("the first gets in");
        expect_connected(&mut server_events).await;
        let second = b.connect(addr(&server), Expect::AnyPeer).await;
        assert!(second.is_err(), "the second got in");

        a.send(a_conn, &message(b"still served"))
            .await
            .expect("sending");
        assert_eq!(expect_message(&mut server_events).await.1, b"still served");

        a.close(a_conn, CloseCode::Normal, "making room");
        expect_closed(&mut server_events).await;
        let third = b.connect(addr(&server), Expect::AnyPeer).await;
        third.expect("a freed place is taken again");
    })
    .await;
}
