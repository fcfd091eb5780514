//! The receiving side of a connection: one task per connection accepts its streams, and one task
//! per stream reads a message, checks its frame and decodes it.
//!
//! Whatever a peer sends that breaks the framing or fails to decode closes that connection, with a
//! [`CloseCode`] and a `warn!` line; the node, and its other connections, carry on. What a peer can
//! make us hold is bounded by the [`Config`](super::Config): at most `max_concurrent_messages`
//! streams at a time, each refused as soon as its header declares more than `max_message_bytes`,
//! and read with that limit.

use std::sync::Arc;

use quinn::{ReadError, ReadExactError, ReadToEndError, RecvStream, VarInt};
use tokio::sync::OwnedSemaphorePermit;
use tokio::task::JoinSet;
use tracing::{debug, warn};

use super::CloseCode;
use super::link::{CloseReason, ConnId, Event, PeerConn, Shared};

/// The size of the length header that starts every message stream.
const HEADER_BYTES: usize = 4;

/// Serves one established connection until it closes: reports it connected, reads its messages,
/// then reports it closed once every message read from it has been delivered. `slot` is its
/// place among `max_connections`, held as long as the connection lives.
pub(super) async fn run<M: Send + 'static>(
    shared: Arc<Shared<M>>,
    conn: ConnId,
    peer: Arc<PeerConn>,
    connected: Event<M>,
    slot: Option<OwnedSemaphorePermit>,
) {
    if shared.events.send(connected).await.is_err() {
        // The driver is gone; the loop below sees the close at once and ends.
        peer.close(CloseCode::Shutdown, "shutting down");
    }
    let mut reads = JoinSet::new();
    let error = loop {
        tokio::select! {
            stream = peer.connection.accept_uni() => match stream {
                Ok(stream) => {
                    reads.spawn(read(shared.clone(), conn, peer.clone(), stream));
                }
                Err(error) => break error,
            },
            Some(done) = reads.join_next() => reaped(done, conn, &peer),
        }
    };
    while let Some(done) = reads.join_next().await {
        reaped(done, conn, &peer);
    }
    shared.forget(conn);
    // Freed before the driver hears of the close, so that it may count on the place.
    drop(slot);
    let reason = CloseReason::new(error, &peer);
    debug!(%conn, ?reason, "connection closed");
    let _ = shared.events.send(Event::Closed { conn, reason }).await;
}

/// Reads, checks and decodes one message, and delivers it or closes the connection.
async fn read<M>(
    shared: Arc<Shared<M>>,
    conn: ConnId,
    peer: Arc<PeerConn>,
    mut stream: RecvStream,
) {
    let bytes = match receive(&mut stream, shared.config.max_message_bytes).await {
        Ok(bytes) => bytes,
        Err(Failure::Violation(code, problem)) => return violation(&peer, conn, code, &problem),
        Err(Failure::Abandoned(code)) => {
            return debug!(%conn, %code, "the peer abandoned a message");
        }
        // The connection task reports why the connection ended.
        Err(Failure::Lost) => return,
    };
    match (shared.decode)(&bytes) {
        Ok(message) => {
            // A closed channel means the driver is gone, and the accept loop then shuts down.
            let _ = shared.events.send(Event::Message { conn, message }).await;
        }
        Err(problem) => violation(
            &peer,
            conn,
            CloseCode::Malformed,
            &format!("undecodable message: {problem}"),
        ),
    }
}

/// How reading one message can fail.
enum Failure {
    /// The peer broke the framing: close the connection with this code.
    Violation(CloseCode, String),
    /// The peer reset the stream, abandoning the message (a cancelled send).
    Abandoned(VarInt),
    /// The connection closed under the read.
    Lost,
}

/// Reads one framed message: a 4-byte little-endian length, that many bytes, the end of stream.
async fn receive(stream: &mut RecvStream, max: usize) -> Result<Vec<u8>, Failure> {
    let mut header = [0; HEADER_BYTES];
    stream.read_exact(&mut header).await.map_err(|e| match e {
        ReadExactError::FinishedEarly(read) => Failure::Violation(
            CloseCode::Truncated,
            format!("stream ended after {read} of {HEADER_BYTES} header bytes"),
        ),
        ReadExactError::ReadError(e) => read_failure(e),
    })?;
    // A u32 fits a usize on every target tokio runs on; saturating keeps the check honest anyway.
    let declared = usize::try_from(u32::from_le_bytes(header)).unwrap_or(usize::MAX);
    if declared > max {
        return Err(Failure::Violation(
            CloseCode::TooLarge,
            format!("message declares {declared} bytes, over the limit of {max}"),
        ));
    }
    let body = stream.read_to_end(declared).await.map_err(|e| match e {
        ReadToEndError::TooLong => Failure::Violation(
            CloseCode::Malformed,
            format!("stream holds more than the {declared} bytes its header declares"),
        ),
        ReadToEndError::Read(e) => read_failure(e),
    })?;
    if body.len() < declared {
        return Err(Failure::Violation(
            CloseCode::Truncated,
            format!("stream ended after {} of {declared} bytes", body.len()),
        ));
    }
    Ok(body)
}

fn read_failure(error: ReadError) -> Failure {
    match error {
        ReadError::Reset(code) => Failure::Abandoned(code),
        ReadError::ConnectionLost(_) => Failure::Lost,
        // Only stopping a stream, unordered reads or 0-RTT cause these, and this module uses none
        // of them; should one ever happen, the connection is not to be trusted.
        other @ (ReadError::ClosedStream
        | ReadError::IllegalOrderedRead
        | ReadError::ZeroRttRejected) => {
            Failure::Violation(CloseCode::Protocol, format!("stream read failed: {other}"))
        }
    }
}

/// Accounts for a finished read task. A panic there came from the decoder, on this peer's bytes:
/// tokio contained it, and the connection goes as for any undecodable message.
fn reaped(done: Result<(), tokio::task::JoinError>, conn: ConnId, peer: &PeerConn) {
    if let Err(error) = done
        && error.is_panic()
    {
        violation(peer, conn, CloseCode::Malformed, "the decoder panicked");
    }
}

fn violation(peer: &PeerConn, conn: ConnId, code: CloseCode, problem: &str) {
    warn!(
        %conn,
        remote = %peer.connection.remote_address(),
        ?code,
        "closing connection: {problem}"
    );
    peer.close(code, problem);
}
