//! A lossy UDP socket for tests and measurements: it drops, duplicates, delays and so reorders
//! the datagrams a [`Link`](super::Link) sends, every decision drawn from a seed.
//!
//! This is not a mock of the network. The link still runs real QUIC with mutual TLS over a real
//! loopback socket; the wrapper only sits between quinn and that socket and mistreats what goes
//! out, as a bad network would. A link uses it when its [`Config::impairment`](super::Config) is
//! set, which nothing but tests and `examples/lossy_link.rs` do.
//!
//! Why decisions are per datagram and counter-based: the `n`th datagram a socket sends gets its
//! fate from a generator seeded by (seed, peer, `n`), never from a shared stream, so the same
//! datagram index meets the same fate in every run whatever the timing of the others. (Which
//! datagram is the `n`th still depends on timing: QUIC's retransmissions react to the clock.)
//!
//! Only sending is impaired. Every peer of a test cluster wraps its own socket, so both
//! directions of every connection are.

use std::fmt;
use std::io::{self, IoSliceMut};
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use quinn::udp::{RecvMeta, Transmit};
use quinn::{AsyncUdpSocket, UdpPoller};
use runtime_core::rng::SplitMix;

/// How a lossy socket mistreats what it sends. Rates are probabilities per datagram.
#[derive(Clone, Debug, PartialEq)]
pub struct Impairment {
    /// Seeds every decision; mixed with the peer index, so peers of one run differ.
    pub seed: u64,
    /// Datagrams dropped. Default 5%.
    pub drop: f64,
    /// Datagrams (of those not dropped) sent twice. Default 1%.
    pub duplicate: f64,
    /// Every copy is held back this long before it is sent. Default 1 ms.
    pub delay: Duration,
    /// Plus a uniform share of this, drawn per copy. Datagrams sent closer together than this
    /// may overtake each other. Default 2 ms.
    pub jitter: Duration,
}

impl Default for Impairment {
    fn default() -> Self {
        Self {
            seed: 0,
            drop: 0.05,
            duplicate: 0.01,
            delay: Duration::from_millis(1),
            jitter: Duration::from_millis(2),
        }
    }
}

/// What becomes of one datagram: nothing (dropped), or one or two copies, each sent after its
/// delay.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Fate {
    /// When each copy is sent, after the datagram was handed over; empty when it is dropped.
    pub delays: Vec<Duration>,
}

impl Fate {
    /// True when no copy of the datagram is sent.
    pub fn dropped(&self) -> bool {
        self.delays.is_empty()
    }
}

impl Impairment {
    /// The fate of datagram number `index` sent by peer `peer`: a pure function of the seed, the
    /// peer and the index.
    pub fn fate(&self, peer: u32, index: u64) -> Fate {
        let mut rng = SplitMix::stream(SplitMix::stream(self.seed, u64::from(peer)).0, index);
        if rng.unit() < self.drop {
            return Fate { delays: Vec::new() };
        }
        let copies = if rng.unit() < self.duplicate { 2 } else { 1 };
        let delays = (0..copies)
            .map(|_| self.delay + self.jitter.mul_f64(rng.unit()))
            .collect();
        Fate { delays }
    }
}

/// A socket that sends through `inner` what [`Impairment::fate`] lets through, when it says.
pub struct LossySocket {
    inner: Arc<dyn AsyncUdpSocket>,
    impairment: Impairment,
    peer: u32,
    /// Datagrams handed to this socket so far: the index of the next one's fate.
    sent: AtomicU64,
    runtime: tokio::runtime::Handle,
}

impl LossySocket {
    /// Wraps `inner` for peer `peer`. Fails outside a tokio runtime: delayed copies are sent
    /// from tasks of the runtime it is made in.
    pub fn new(
        inner: Arc<dyn AsyncUdpSocket>,
        impairment: Impairment,
        peer: u32,
    ) -> io::Result<Self> {
        let runtime = tokio::runtime::Handle::try_current().map_err(io::Error::other)?;
        Ok(Self {
            inner,
            impairment,
            peer,
            sent: AtomicU64::new(0),
            runtime,
        })
    }

    /// Sends one copy of a datagram after `delay`, waiting for the socket (up to 16 times) if
    /// its buffer is full: a copy the impairment let through is not lost to back-pressure, so
    /// the loss rate stays the configured one unless the socket stays full.
    fn send_later(&self, delay: Duration, datagram: Datagram) {
        let inner = self.inner.clone();
        self.runtime.spawn(async move {
            tokio::time::sleep(delay).await;
            let mut poller = inner.clone().create_io_poller();
            for _ in 0..16 {
                let transmit = Transmit {
                    destination: datagram.destination,
                    ecn: datagram.ecn,
                    contents: &datagram.contents,
                    segment_size: None,
                    src_ip: datagram.src_ip,
                };
                match inner.try_send(&transmit) {
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                        if std::future::poll_fn(|cx| poller.as_mut().poll_writable(cx))
                            .await
                            .is_err()
                        {
                            return;
                        }
                    }
                    // Sent, or failed as UDP may: either way the datagram's journey ends here.
                    _ => return,
                }
            }
        });
    }
}

/// An owned copy of one datagram, for sending later.
struct Datagram {
    destination: SocketAddr,
    ecn: Option<quinn::udp::EcnCodepoint>,
    src_ip: Option<std::net::IpAddr>,
    contents: Vec<u8>,
}

impl fmt::Debug for LossySocket {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LossySocket")
            .field("impairment", &self.impairment)
            .field("peer", &self.peer)
            .field("sent", &self.sent)
            .finish_non_exhaustive()
    }
}

impl AsyncUdpSocket for LossySocket {
    fn create_io_poller(self: Arc<Self>) -> Pin<Box<dyn UdpPoller>> {
        self.inner.clone().create_io_poller()
    }

    /// Takes every datagram at once (the send "succeeds"), then drops it or sends its copies
    /// later. A transmit of several segments (GSO) is split: each segment is a datagram with its
    /// own fate.
    fn try_send(&self, transmit: &Transmit) -> io::Result<()> {
        let size = transmit
            .segment_size
            .unwrap_or(transmit.contents.len())
            .max(1);
        for segment in transmit.contents.chunks(size) {
            let index = self.sent.fetch_add(1, Ordering::Relaxed);
            for delay in self.impairment.fate(self.peer, index).delays {
                self.send_later(
                    delay,
                    Datagram {
                        destination: transmit.destination,
                        ecn: transmit.ecn,
                        src_ip: transmit.src_ip,
                        contents: segment.to_vec(),
                    },
                );
            }
        }
        Ok(())
    }

    fn poll_recv(
        &self,
        cx: &mut Context,
        bufs: &mut [IoSliceMut<'_>],
        meta: &mut [RecvMeta],
    ) -> Poll<io::Result<usize>> {
        self.inner.poll_recv(cx, bufs, meta)
    }

    fn local_addr(&self) -> io::Result<SocketAddr> {
        self.inner.local_addr()
    }

    /// One datagram per transmit, so that each gets its own fate without splitting.
    fn max_transmit_segments(&self) -> usize {
        1
    }

    fn max_receive_segments(&self) -> usize {
        self.inner.max_receive_segments()
    }

    fn may_fragment(&self) -> bool {
        self.inner.may_fragment()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DATAGRAMS: u64 = 200_000;

    fn counts(impairment: &Impairment, peer: u32) -> (u64, u64) {
        let (mut dropped, mut doubled) = (0, 0);
        for index in 0..DATAGRAMS {
            let fate = impairment.fate(peer, index);
            dropped += u64::from(fate.dropped());
            doubled += u64::from(fate.delays.len() == 2);
        }
        (dropped, doubled)
    }

    /// The rates are the configured ones: within 4 standard deviations of a binomial count.
    #[test]
    fn drop_and_duplicate_rates_follow_the_configuration() {
        for seed in [0, 1, 0xDEAD_BEEF] {
            let impairment = Impairment {
                seed,
                ..Impairment::default()
            };
            let (dropped, doubled) = counts(&impairment, 3);
            let n = DATAGRAMS as f64;
            let within = |count: u64, p: f64| {
                let sd = (n * p * (1.0 - p)).sqrt();
                (count as f64 - n * p).abs() < 4.0 * sd
            };
            assert!(within(dropped, 0.05), "seed {seed}: {dropped} dropped");
            // Duplicates are drawn among the datagrams not dropped.
            assert!(
                within(doubled, 0.95 * 0.01),
                "seed {seed}: {doubled} doubled"
            );
        }
        let none = Impairment {
            drop: 0.0,
            duplicate: 0.0,
            ..Impairment::default()
        };
        assert_eq!(counts(&none, 0), (0, 0));
    }

    /// A fate is a function of (seed, peer, index): the same in every run, different for
    /// another seed or peer.
    #[test]
    fn fates_are_a_function_of_seed_peer_and_index() {
        let a = Impairment {
            seed: 7,
            ..Impairment::default()
        };
        let fates =
            |imp: &Impairment, peer| (0..2000).map(|i| imp.fate(peer, i)).collect::<Vec<_>>();
        assert_eq!(fates(&a, 1), fates(&a.clone(), 1));
        assert_ne!(fates(&a, 1), fates(&a, 2));
        let b = Impairment {
            seed: 8,
            ..a.clone()
        };
        assert_ne!(fates(&a, 1), fates(&b, 1));
        // Delays stay within delay + jitter, and differ enough to reorder neighbours.
        let delays: Vec<Duration> = fates(&a, 1).into_iter().flat_map(|f| f.delays).collect();
        assert!(
            delays
                .iter()
                .all(|d| *d >= a.delay && *d < a.delay + a.jitter)
        );
        let reordered = delays.windows(2).filter(|w| w[1] < w[0]).count();
        assert!(reordered > delays.len() / 4, "only {reordered} reordered");
    }

    /// Through a real socket pair: what arrives is what the fates say, each datagram intact.
    #[tokio::test]
    async fn a_wrapped_socket_delivers_exactly_the_surviving_copies() {
        use quinn::Runtime;
        let runtime = quinn::TokioRuntime;
        let bind = || std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let impairment = Impairment {
            seed: 11,
            drop: 0.3,
            duplicate: 0.2,
            ..Impairment::default()
        };
        let sender = LossySocket::new(
            runtime.wrap_udp_socket(bind()).unwrap(),
            impairment.clone(),
            5,
        )
        .unwrap();
        let receiver = bind();
        receiver
            .set_read_timeout(Some(Duration::from_millis(300)))
            .unwrap();
        let destination = receiver.local_addr().unwrap();
        let mut expected = Vec::new();
        for i in 0u8..100 {
            let contents = [i; 32];
            sender
                .try_send(&Transmit {
                    destination,
                    ecn: None,
                    contents: &contents,
                    segment_size: None,
                    src_ip: None,
                })
                .unwrap();
            let copies = impairment.fate(5, u64::from(i)).delays.len();
            expected.extend(std::iter::repeat_n(i, copies));
        }
        let mut got = tokio::task::spawn_blocking(move || {
            let mut got = Vec::new();
            let mut buf = [0u8; 64];
            while let Ok(n) = receiver.recv(&mut buf) {
                assert_eq!(n, 32);
                assert!(buf[..n].iter().all(|b| *b == buf[0]));
                got.push(buf[0]);
            }
            got
        })
        .await
        .unwrap();
        let arrived_in_order = got.windows(2).all(|w| w[0] <= w[1]);
        got.sort_unstable();
        assert_eq!(got, expected);
        assert!(
            !arrived_in_order,
            "100 datagrams 1-3 ms apart arrived in order"
        );
    }
}
