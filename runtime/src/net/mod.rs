//! The QUIC transport between peers: certificates, mutual TLS, and a [`Link`] that moves opaque
//! byte messages.
//!
//! Map:
//! - [`certs`]: the cluster certificate authority and per-peer certificates (rcgen), in memory or as
//!   PEM files.
//! - [`tls`]: rustls configurations for mutual TLS against the cluster CA, on the ring provider.
//! - `link`: the endpoint every peer both accepts and connects on, sending and connection events.
//! - `reader`: one task per connection that turns incoming streams into messages, and closes the
//!   connection of a peer that sends something it must not.
//! - [`lossy`]: a socket wrapper that drops, duplicates and reorders datagrams from a seed, for
//!   tests and measurements of the link over a bad network ([`Config::impairment`]).
//!
//! # Why this shape
//! The transport knows nothing of the message types: it moves byte strings, and the decoding is a
//! function the caller hands to [`Link::bind`]. A message that fails to decode closes its connection
//! here, with [`CloseCode::Malformed`], so a hostile or buggy peer costs one connection and never the
//! node, and the scheduling core only ever sees well-formed messages.
//!
//! # Framing: one message per unidirectional stream
//! Each message travels on its own QUIC unidirectional stream as a 4-byte little-endian length, the
//! message bytes, then the stream's end (FIN). One stream per message because:
//! - no head-of-line blocking: a 1 MB tile result in flight never delays a 30-byte steal request,
//!   and a lost packet delays only the message it belongs to; this is what keeps the prefetch queue
//!   full without waiting on round trips;
//! - QUIC flow control then bounds each message separately, and opening a stream costs no round trip.
//!
//! The length prefix is redundant with the FIN on purpose: it lets the receiver refuse an oversized
//! message after reading 4 bytes instead of after buffering it, and tell a message cut short (FIN
//! before the declared length: [`CloseCode::Truncated`]) from one that is complete, without knowing
//! the message format. A stream *reset* by its sender is an abandoned message (a cancelled send): it
//! is dropped quietly and the connection lives on.
//!
//! The price: messages on one connection may be delivered in any order. Per connection the events
//! are still ordered where it matters: [`Event::Connected`] comes before any of its messages, and
//! [`Event::Closed`] after all of them.
//!
//! # Peer identity
//! Every peer certificate names its peer index (`peer-K.tessera`, see [`certs::peer_name`]). A
//! connection's [`PeerCertificate`] says which index the cluster CA vouched for, so the id a peer
//! claims in its first message can be checked with [`PeerCertificate::certifies`]; outgoing
//! connections can require the index up front with [`Expect::Peer`].

pub mod certs;
mod link;
pub mod lossy;
mod reader;
pub mod tls;

pub use certs::{CertError, ClusterCerts, PeerCertificate, PeerIdentity};
pub use link::{
    BindError, CloseReason, ConnId, ConnectError, Direction, Event, Expect, Link, SendError,
};
pub use tls::TlsError;

use std::time::Duration;

use quinn::{IdleTimeout, TransportConfig, VarInt};

/// Application error codes a connection is closed with, as carried in QUIC's CONNECTION_CLOSE.
///
/// Both ends see them: the offender in its `ApplicationClosed` error, the node that closed it in
/// [`CloseReason::Local`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum CloseCode {
    /// An orderly close: [`Link::close`] with nothing wrong.
    Normal = 0,
    /// A message declared more bytes than [`Config::max_message_bytes`].
    TooLarge = 1,
    /// A stream ended before the length its header declared.
    Truncated = 2,
    /// A stream held more bytes than declared, or a message the decoder refused.
    Malformed = 3,
    /// A well-formed message that the protocol above does not allow at this point.
    Protocol = 4,
    /// The peer's certificate does not vouch for the identity it claims.
    Identity = 5,
    /// The node is shutting down.
    Shutdown = 6,
}

impl CloseCode {
    /// The code as QUIC carries it.
    pub const fn varint(self) -> VarInt {
        VarInt::from_u32(self as u32)
    }

    /// The code a remote closed with, if it is one of ours.
    pub fn from_code(code: u64) -> Option<Self> {
        [
            Self::Normal,
            Self::TooLarge,
            Self::Truncated,
            Self::Malformed,
            Self::Protocol,
            Self::Identity,
            Self::Shutdown,
        ]
        .into_iter()
        .find(|c| *c as u64 == code)
    }
}

/// Limits and timers of a [`Link`]: everything a remote peer can make this node hold is bounded
/// here.
///
/// Worst-case memory held for one connection is about
/// `max_concurrent_messages * max_message_bytes` (messages being assembled) plus
/// `connection_window_bytes` (received, not yet read), so 136 MiB with the defaults; the event
/// queue adds up to `event_capacity` decoded messages across all connections.
#[derive(Clone, Debug)]
pub struct Config {
    /// Largest message, in bytes, sent or accepted. A tile of 512 x 512 RGBA `f32` pixels is 4 MiB,
    /// so the default of 8 MiB leaves room for twice that. At most `u32::MAX`.
    pub max_message_bytes: usize,
    /// Messages (streams) a peer may have in flight towards us at once on one connection; a sender
    /// past this waits for one to finish. Default 16.
    pub max_concurrent_messages: u32,
    /// Unacknowledged bytes a peer may send on one stream. 1 MiB sustains 1 GB/s per message at a
    /// 1 ms round trip.
    pub stream_window_bytes: u32,
    /// Unread bytes a peer may have buffered at us over all its streams. Default 8 MiB.
    pub connection_window_bytes: u32,
    /// Bytes we keep unacknowledged in flight on one connection. Default 8 MiB.
    pub send_window_bytes: u64,
    /// A connection silent this long is closed: this is how a dead peer is noticed. Default 10 s.
    pub idle_timeout: Duration,
    /// How often an otherwise quiet connection is pinged, so that a live peer never looks idle.
    /// Must be shorter than `idle_timeout`. Default 2 s.
    pub keep_alive: Duration,
    /// Incoming connections, counting handshakes in progress, beyond which new ones are refused.
    /// Default 256.
    pub max_connections: usize,
    /// Events queued for the driver before readers wait (and QUIC flow control pushes back on the
    /// senders). Default 256.
    pub event_capacity: usize,
    /// For tests and measurements only: send through a [`lossy::LossySocket`] that mistreats
    /// datagrams so. Default `None`, a plain UDP socket.
    pub impairment: Option<lossy::Impairment>,
}

impl Default for Config {
    fn default() -> Self {
        const MIB: u32 = 1024 * 1024;
        Self {
            max_message_bytes: 8 * MIB as usize,
            max_concurrent_messages: 16,
            stream_window_bytes: MIB,
            connection_window_bytes: 8 * MIB,
            send_window_bytes: 8 * u64::from(MIB),
            idle_timeout: Duration::from_secs(10),
            keep_alive: Duration::from_secs(2),
            max_connections: 256,
            event_capacity: 256,
            impairment: None,
        }
    }
}

/// A [`Config`] that cannot work.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The message limit does not fit the 4-byte length header.
    #[error("max_message_bytes {0} is over the 4-byte length header's limit of u32::MAX")]
    MessageTooLarge(usize),
    /// The idle timeout is too long for QUIC's variable-length integer.
    #[error("idle_timeout {0:?} is out of QUIC's range")]
    IdleTimeout(Duration),
    /// Keep-alives as rare as the idle timeout would let a healthy connection time out.
    #[error("keep_alive {keep_alive:?} must be shorter than idle_timeout {idle_timeout:?}")]
    KeepAlive {
        /// The keep-alive interval asked for.
        keep_alive: Duration,
        /// The idle timeout asked for.
        idle_timeout: Duration,
    },
    /// A count that must be positive is zero; the text names it.
    #[error("{0} must be at least 1")]
    Zero(&'static str),
}

impl Config {
    /// The QUIC transport parameters for these limits, the same for both directions.
    pub(crate) fn transport(&self) -> Result<TransportConfig, ConfigError> {
        if u32::try_from(self.max_message_bytes).is_err() {
            return Err(ConfigError::MessageTooLarge(self.max_message_bytes));
        }
        if self.keep_alive >= self.idle_timeout {
            return Err(ConfigError::KeepAlive {
                keep_alive: self.keep_alive,
                idle_timeout: self.idle_timeout,
            });
        }
        for (value, name) in [
            (
                self.max_concurrent_messages as usize,
                "max_concurrent_messages",
            ),
            (self.max_connections, "max_connections"),
            (self.event_capacity, "event_capacity"),
        ] {
            if value == 0 {
                return Err(ConfigError::Zero(name));
            }
        }
        let idle = IdleTimeout::try_from(self.idle_timeout)
            .map_err(|_| ConfigError::IdleTimeout(self.idle_timeout))?;
        let mut transport = TransportConfig::default();
        transport
            .max_concurrent_uni_streams(self.max_concurrent_messages.into())
            // Messages travel on unidirectional streams only: a peer may not open a single
            // bidirectional one, nor send datagrams.
            .max_concurrent_bidi_streams(VarInt::from_u32(0))
            .datagram_receive_buffer_size(None)
            .stream_receive_window(self.stream_window_bytes.into())
            .receive_window(self.connection_window_bytes.into())
            .send_window(self.send_window_bytes)
            .max_idle_timeout(Some(idle))
            .keep_alive_interval(Some(self.keep_alive));
        Ok(transport)
    }
}
