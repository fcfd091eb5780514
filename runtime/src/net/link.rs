//! The [`Link`]: one QUIC endpoint per peer that both accepts and connects, because any peer may
//! steal from any other and so is client and server at once.
//!
//! The driver talks to it through two things: calls ([`Link::connect`], [`Link::send`],
//! [`Link::close`]) and one channel of [`Event`]s. Connection events and messages share that
//! channel so that, per connection, `Connected` precedes its messages and `Closed` follows them;
//! with two channels the driver could see a message from a connection it has not heard of.
//!
//! Two peers that connect to each other at the same time get two connections; the transport keeps
//! both and the protocol above decides which to use (say, the one opened by the lower index).

use std::collections::BTreeMap;
use std::fmt;
use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use quinn::{ClosedStream, ConnectionError, Endpoint, SendStream, VarInt, WriteError};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tracing::{debug, warn};

use super::certs::{ANY_PEER_NAME, PeerCertificate, PeerIdentity, peer_name};
use super::{CloseCode, Config, ConfigError, TlsError, lossy, reader, tls};

/// This peer's end of the cluster network. Cheap to clone; all clones share one endpoint.
pub struct Link<M> {
    shared: Arc<Shared<M>>,
}

/// A connection, numbered by this node in order of establishment; never reused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ConnId(u64);

/// Who opened a connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// The other side dialled this node.
    Inbound,
    /// This node dialled the other side.
    Outbound,
}

/// Which certificate the server must present to an outgoing connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Expect {
    /// Any peer of the cluster, for when only an address is known.
    AnyPeer,
    /// Peer `K` and no other.
    Peer(u32),
}

/// What happens on the network, in order per connection.
#[derive(Debug)]
pub enum Event<M> {
    /// A handshake succeeded: the peer holds a certificate of the cluster CA.
    Connected {
        /// The connection's id, which later events and sends name.
        conn: ConnId,
        /// The other side's address.
        remote: SocketAddr,
        /// Who dialled.
        direction: Direction,
        /// The other side's certificate, which says which peer it is.
        certificate: PeerCertificate,
    },
    /// A whole message arrived and decoded.
    Message {
        /// The connection it arrived on.
        conn: ConnId,
        /// The decoded message.
        message: M,
    },
    /// The connection is gone; nothing more will come from it, and sends to it fail.
    Closed {
        /// The connection that is gone.
        conn: ConnId,
        /// Who closed it, and why.
        reason: CloseReason,
    },
}

/// Why a connection ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CloseReason {
    /// This node closed it, with this code.
    Local(CloseCode),
    /// The peer closed it; `code` is one of [`CloseCode`] from a tessera peer.
    Remote {
        /// The application close code.
        code: u64,
        /// The text the peer gave.
        reason: String,
    },
    /// Nothing heard for the idle timeout: the peer is presumed dead.
    TimedOut,
    /// The QUIC or TLS layer failed.
    Transport(String),
}

/// Why a [`Link`] could not start.
#[derive(Debug, thiserror::Error)]
pub enum BindError {
    /// The link's configuration is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The TLS configuration could not be built from the certificates.
    #[error(transparent)]
    Tls(#[from] TlsError),
    /// The UDP socket could not be bound.
    #[error("binding the UDP socket: {0}")]
    Io(#[from] io::Error),
}

/// Why an outgoing connection failed.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    /// quinn refused to start the connection (an invalid address or server name, or a stopped
    /// endpoint).
    #[error("cannot connect: {0}")]
    Invalid(#[from] quinn::ConnectError),
    /// The QUIC or TLS handshake failed, e.g. a certificate of another cluster.
    #[error("handshake failed: {0}")]
    Handshake(#[from] ConnectionError),
    /// The handshake ended without the server's certificate, which the link needs to know who it
    /// is.
    #[error("the server presented no certificate")]
    NoCertificate,
}

/// Why a message was not sent.
#[derive(Debug, thiserror::Error)]
pub enum SendError {
    /// The connection is closed or was never opened.
    #[error("no open connection {0}")]
    UnknownConnection(ConnId),
    /// The encoded message is longer than the link's limit.
    #[error("message of {len} bytes is over the limit of {max}")]
    TooLarge {
        /// The message's length in bytes.
        len: usize,
        /// The limit.
        max: usize,
    },
    /// The connection was lost while sending.
    #[error("connection lost: {0}")]
    Connection(#[from] ConnectionError),
    /// The stream could not be written.
    #[error("writing the message: {0}")]
    Write(#[from] WriteError),
    /// The stream was closed before the message was finished.
    #[error("stream closed before the message was finished")]
    ClosedStream(#[from] ClosedStream),
}

impl<M: Send + 'static> Link<M> {
    /// Binds a UDP socket on `addr` (port 0 for any) and starts accepting peers of `identity`'s
    /// cluster. Every message that arrives, on any connection, goes through `decode`; one it refuses
    /// closes its connection with [`CloseCode::Malformed`]. `decode` runs on the tokio workers, so
    /// it must be quick: a parse, never a render.
    ///
    /// Must be called within a tokio runtime. The node runs until [`Link::shutdown`] or until the
    /// returned receiver is dropped.
    pub fn bind<D, E>(
        addr: SocketAddr,
        identity: &PeerIdentity,
        config: Config,
        decode: D,
    ) -> Result<(Self, mpsc::Receiver<Event<M>>), BindError>
    where
        D: Fn(&[u8]) -> Result<M, E> + Send + Sync + 'static,
        E: fmt::Display,
    {
        let transport = Arc::new(config.transport()?);
        let mut server = quinn::ServerConfig::with_crypto(Arc::new(tls::server_config(identity)?));
        server.transport_config(transport.clone());
        let mut client = quinn::ClientConfig::new(Arc::new(tls::client_config(identity)?));
        client.transport_config(transport);
        let mut endpoint = match &config.impairment {
            None => Endpoint::server(server, addr)?,
            Some(impairment) => {
                let runtime: Arc<dyn quinn::Runtime> = Arc::new(quinn::TokioRuntime);
                let socket = runtime.wrap_udp_socket(std::net::UdpSocket::bind(addr)?)?;
                let socket = lossy::LossySocket::new(socket, impairment.clone(), identity.index())?;
                Endpoint::new_with_abstract_socket(
                    quinn::EndpointConfig::default(),
                    Some(server),
                    Arc::new(socket),
                    runtime,
                )?
            }
        };
        endpoint.set_default_client_config(client);

        let (events, receiver) = mpsc::channel(config.event_capacity);
        let slots = Arc::new(Semaphore::new(config.max_connections));
        let shared = Arc::new(Shared {
            endpoint,
            config,
            decode: Box::new(move |bytes| decode(bytes).map_err(|e| e.to_string())),
            events,
            connections: Mutex::default(),
            next_id: AtomicU64::new(0),
        });
        tokio::spawn(accept(shared.clone(), slots));
        Ok((Self { shared }, receiver))
    }

    /// The address peers reach this node at.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.shared.endpoint.local_addr()
    }

    /// Connects to the peer at `addr`, which must present the certificate `expect` says. Returns
    /// once the handshake is done; the [`Event::Connected`] follows on the channel.
    pub async fn connect(&self, addr: SocketAddr, expect: Expect) -> Result<ConnId, ConnectError> {
        let name = match expect {
            Expect::AnyPeer => ANY_PEER_NAME.to_owned(),
            Expect::Peer(index) => peer_name(index),
        };
        let connection = self.shared.endpoint.connect(addr, &name)?.await?;
        self.shared
            .start(connection, Direction::Outbound, None)
            .ok_or(ConnectError::NoCertificate)
    }

    /// Sends one message on its own stream. Returns once it is handed to QUIC, which delivers it
    /// unless the connection dies; waits while the peer has `max_concurrent_messages` in flight or
    /// the send window is full. Cancelling this future abandons the message: the peer drops it and
    /// the connection stays up.
    pub async fn send(&self, conn: ConnId, message: &[u8]) -> Result<(), SendError> {
        self.send_stream(conn, message).await.map(drop)
    }

    /// [`Link::send`], then waits until the peer has acknowledged every byte of the message
    /// (received, not necessarily read), or the connection is gone. Closing a connection
    /// discards what QUIC has not yet delivered, so whatever must arrive before a close (a
    /// leaving peer's last results and goodbye, the owner's goodbyes) is sent this way and
    /// waited for: handed to QUIC is not enough, as a step under load once showed (the owner
    /// saw the close first and took a peer that was leaving for one that had failed).
    pub async fn send_delivered(&self, conn: ConnId, message: &[u8]) -> Result<(), SendError> {
        let outgoing = self.send_stream(conn, message).await?;
        // `Ok(None)` once every byte is acknowledged; an error once the connection is gone,
        // when there is nothing left to wait for.
        let _ = outgoing.stream.stopped().await;
        Ok(())
    }

    /// The message written and its stream finished: the stream, to wait on or to drop.
    async fn send_stream(&self, conn: ConnId, message: &[u8]) -> Result<Outgoing, SendError> {
        let max = self.shared.config.max_message_bytes;
        let too_large = SendError::TooLarge {
            len: message.len(),
            max,
        };
        let header = match u32::try_from(message.len()) {
            Ok(len) if message.len() <= max => len.to_le_bytes(),
            _ => return Err(too_large),
        };
        let peer = self
            .shared
            .peer(conn)
            .ok_or(SendError::UnknownConnection(conn))?;
        let mut outgoing = Outgoing {
            stream: peer.connection.open_uni().await?,
            finished: false,
        };
        outgoing.stream.write_all(&header).await?;
        outgoing.stream.write_all(message).await?;
        outgoing.finish()?;
        Ok(outgoing)
    }

    /// QUIC's smoothed estimate of one connection's round-trip time; `None` once it is gone.
    pub fn rtt(&self, conn: ConnId) -> Option<std::time::Duration> {
        self.shared.peer(conn).map(|peer| peer.connection.rtt())
    }

    /// Closes one connection; its [`Event::Closed`] reports `code` as [`CloseReason::Local`].
    pub fn close(&self, conn: ConnId, code: CloseCode, reason: &str) {
        if let Some(peer) = self.shared.peer(conn) {
            peer.close(code, reason);
        }
    }

    /// Closes every connection with [`CloseCode::Shutdown`], stops accepting, and waits for the
    /// peers to be told.
    pub async fn shutdown(&self) {
        self.shared.close_all();
        self.shared.endpoint.wait_idle().await;
    }
}

impl<M> Clone for Link<M> {
    fn clone(&self) -> Self {
        Self {
            shared: self.shared.clone(),
        }
    }
}

impl fmt::Display for ConnId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "#{}", self.0)
    }
}

impl fmt::Display for CloseReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Local(code) => write!(f, "closed here: {code:?}"),
            Self::Remote { code, reason } => {
                write!(f, "closed by the other side, code {code}: {reason}")
            }
            Self::TimedOut => write!(f, "nothing heard for the idle timeout"),
            Self::Transport(error) => write!(f, "transport failure: {error}"),
        }
    }
}

impl CloseReason {
    pub(super) fn new(error: ConnectionError, peer: &PeerConn) -> Self {
        match error {
            ConnectionError::LocallyClosed => Self::Local(peer.local_close()),
            ConnectionError::ApplicationClosed(close) => Self::Remote {
                code: close.error_code.into_inner(),
                reason: String::from_utf8_lossy(&close.reason).into_owned(),
            },
            ConnectionError::TimedOut => Self::TimedOut,
            other => Self::Transport(other.to_string()),
        }
    }
}

/// The caller's decoding function, its error reduced to the text logged and sent to the peer.
type Decoder<M> = Box<dyn Fn(&[u8]) -> Result<M, String> + Send + Sync>;

/// What the endpoint's tasks share.
pub(super) struct Shared<M> {
    endpoint: Endpoint,
    pub(super) config: Config,
    pub(super) decode: Decoder<M>,
    pub(super) events: mpsc::Sender<Event<M>>,
    connections: Mutex<BTreeMap<ConnId, Arc<PeerConn>>>,
    next_id: AtomicU64,
}

/// An established connection, and the code this node closed it with, if it did.
pub(super) struct PeerConn {
    pub(super) connection: quinn::Connection,
    local_close: OnceLock<CloseCode>,
}

impl<M: Send + 'static> Shared<M> {
    /// Registers an established connection and starts its reader. `None` if the peer presented no
    /// certificate, which mutual TLS rules out; the connection is then closed.
    fn start(
        self: &Arc<Self>,
        connection: quinn::Connection,
        direction: Direction,
        slot: Option<OwnedSemaphorePermit>,
    ) -> Option<ConnId> {
        let remote = connection.remote_address();
        let certificate = connection
            .peer_identity()
            .and_then(|identity| {
                identity
                    .downcast::<Vec<rustls::pki_types::CertificateDer>>()
                    .ok()
            })
            .and_then(|chain| chain.into_iter().next());
        let Some(certificate) = certificate else {
            warn!(%remote, "closing a connection without a peer certificate");
            connection.close(CloseCode::Identity.varint(), b"no certificate");
            return None;
        };
        let conn = ConnId(self.next_id.fetch_add(1, Ordering::Relaxed));
        let peer = Arc::new(PeerConn {
            connection,
            local_close: OnceLock::new(),
        });
        self.table().insert(conn, peer.clone());
        debug!(%conn, %remote, ?direction, "connected");
        let connected = Event::Connected {
            conn,
            remote,
            direction,
            certificate: PeerCertificate::new(certificate),
        };
        tokio::spawn(reader::run(self.clone(), conn, peer, connected, slot));
        Some(conn)
    }
}

impl<M> Shared<M> {
    fn peer(&self, conn: ConnId) -> Option<Arc<PeerConn>> {
        self.table().get(&conn).cloned()
    }

    pub(super) fn forget(&self, conn: ConnId) {
        self.table().remove(&conn);
    }

    fn close_all(&self) {
        for peer in self.table().values() {
            peer.close(CloseCode::Shutdown, "shutting down");
        }
        self.endpoint
            .close(CloseCode::Shutdown.varint(), b"shutting down");
    }

    fn table(&self) -> std::sync::MutexGuard<'_, BTreeMap<ConnId, Arc<PeerConn>>> {
        // The table is consistent after every statement that touches it, so a panic elsewhere
        // while it was locked leaves nothing to repair.
        self.connections
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
}

impl PeerConn {
    /// Closes the connection, remembering the first code it was closed with.
    pub(super) fn close(&self, code: CloseCode, reason: &str) {
        let _ = self.local_close.set(code);
        self.connection.close(code.varint(), reason.as_bytes());
    }

    fn local_close(&self) -> CloseCode {
        self.local_close
            .get()
            .copied()
            .unwrap_or(CloseCode::Shutdown)
    }
}

/// Accepts incoming connections until the endpoint closes or the driver drops its receiver.
async fn accept<M: Send + 'static>(shared: Arc<Shared<M>>, slots: Arc<Semaphore>) {
    loop {
        let incoming = tokio::select! {
            incoming = shared.endpoint.accept() => match incoming {
                Some(incoming) => incoming,
                None => break,
            },
            () = shared.events.closed() => {
                shared.close_all();
                break;
            }
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            warn!(
                remote = %incoming.remote_address(),
                "refusing a connection: {} already open or opening",
                shared.config.max_connections
            );
            incoming.refuse();
            continue;
        };
        let shared = shared.clone();
        tokio::spawn(async move {
            let remote = incoming.remote_address();
            match incoming.await {
                Ok(connection) => {
                    shared.start(connection, Direction::Inbound, Some(slot));
                }
                Err(e) => warn!(%remote, "refused in the handshake: {e}"),
            }
        });
    }
}

/// A message's stream, reset if dropped before it is finished. Quinn finishes a dropped stream,
/// which would deliver a cancelled send as a truncated message and cost the connection.
struct Outgoing {
    stream: SendStream,
    finished: bool,
}

/// The stream reset code of an abandoned message.
const ABANDONED: VarInt = VarInt::from_u32(0);

impl Outgoing {
    fn finish(&mut self) -> Result<(), ClosedStream> {
        self.finished = true;
        self.stream.finish()
    }
}

impl Drop for Outgoing {
    fn drop(&mut self) {
        if !self.finished {
            let _ = self.stream.reset(ABANDONED);
        }
    }
}
