//! A connected peer with a good certificate that sends malformed bytes, unframed noise, cut-off
//! or oversized frames, or a message that panics the decoder: that connection closes, with the
//! right code, and the node goes on serving the others.

use super::*;

/// Has a peer with a good certificate write `bytes` on one stream, then checks that both ends see
/// the connection closed with `expected`, and that the server still serves a good peer.
async fn assert_stream_closes_connection(bytes: Vec<u8>, expected: CloseCode) {
    let cluster = cluster(3);
    let mut server = node(&cluster.peers()[0]);
    let connection = raw_peer(&cluster.peers()[1], addr(&server.0)).await;
    let (conn, _) = expect_connected(&mut server.1).await;
    write_stream(&connection, &bytes).await;
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
    let local = CloseReason::Local(expected);
    assert_eq!(expect_closed(&mut server.1).await, (conn, local));
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
    let bytes = framed(b"TT1:panic");
    bounded(assert_stream_closes_connection(bytes, CloseCode::Malformed)).await;
}
