//! The network between simulated peers: what a message costs in time, and how big it is.
//!
//! Every effect is off unless a scenario asks for it ([`Network::default`] is an ideal network:
//! no latency, infinite bandwidth, no loss), so that a result can be traced to the effect that
//! caused it. The effects, in the order a message meets them:
//!
//! - **Bandwidth**: each peer has one link of `bandwidth` bytes per second each way. A message
//!   first waits for its sender's uplink to finish what it is sending, occupies it for
//!   `bytes / bandwidth`, crosses the network, then passes the receiver's downlink the same
//!   way. Tile results carry pixels (12 bytes each), so the owner's downlink, where every
//!   result converges, is where a large cluster feels it. Queues are served in send order (a
//!   simplification: a message sent later over a shorter link still waits behind earlier ones).
//! - **Latency**: `latency` one way, fixed per link but varied between links by up to
//!   `link_spread` of itself either way (from the seed), plus up to `jitter` per message
//!   (uniform), so that messages overtake each other as they do on QUIC streams.
//! - **Loss**: each transmission is lost with probability `loss`; QUIC resends it after a
//!   probe timeout of three round trips plus a millisecond, as often as it takes. Nothing is
//!   lost for good while a connection lives, which is what the protocol relies on; only a
//!   crash loses messages (those addressed to the dead peer).
//!
//! Message sizes are the wire encoding's ([`runtime_core::wire::encoded_len`]: the real encoder,
//! counting instead of writing); simulated tile results carry pixels and a cost map of a real
//! result's lengths ([`runtime_core::wire::cost_map_bytes`]), all zeros.

use std::time::Duration;

use runtime_core::rng::SplitMix;
use runtime_core::wire::PeerId;
use serde::{Deserialize, Serialize};

/// The network model's knobs. All effects default to off.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Network {
    /// One-way latency of a link.
    pub latency: Duration,
    /// Each link's latency differs from `latency` by up to this fraction either way, fixed per
    /// link (the same both ways), drawn from the scenario's seed. In `[0, 1]`.
    pub link_spread: f64,
    /// Each message takes up to this much longer, uniformly at random.
    pub jitter: Duration,
    /// Bytes per second each peer's link carries each way; `None`: unlimited.
    pub bandwidth: Option<f64>,
    /// Probability that a transmission is lost and resent. In `[0, 1)`.
    pub loss: f64,
    /// How long after a peer crashes the others notice (QUIC's idle timeout).
    pub loss_detection: Duration,
}

impl Default for Network {
    fn default() -> Self {
        Self {
            latency: Duration::ZERO,
            link_spread: 0.0,
            jitter: Duration::ZERO,
            bandwidth: None,
            loss: 0.0,
            loss_detection: Duration::from_millis(100),
        }
    }
}

impl Network {
    /// Checks that every value is in its range; the error says which is not.
    pub fn validate(&self) -> Result<(), String> {
        if !(0.0..=1.0).contains(&self.link_spread) {
            return Err("link spread must be in [0, 1]".into());
        }
        if !(0.0..1.0).contains(&self.loss) {
            return Err("loss must be in [0, 1)".into());
        }
        if self.bandwidth.is_some_and(|b| !(b > 0.0 && b.is_finite())) {
            return Err("bandwidth must be positive".into());
        }
        Ok(())
    }
}

/// The links' state during a run: queues, per-link latencies and the loss generator.
pub(crate) struct Links {
    network: Network,
    /// When each peer's uplink and downlink are next free (indexed by peer id).
    uplink_free: Vec<Duration>,
    downlink_free: Vec<Duration>,
    seed: u64,
    rng: SplitMix,
}

impl Links {
    pub(crate) fn new(network: Network, peers: usize, seed: u64) -> Self {
        Self {
            network,
            uplink_free: vec![Duration::ZERO; peers],
            downlink_free: vec![Duration::ZERO; peers],
            seed,
            rng: SplitMix(seed ^ 0x6C6F_7373),
        }
    }

    /// When a message of `bytes` sent now arrives, given the pump's `delay` (the network's
    /// latency plus this message's jitter, which the pump draws).
    pub(crate) fn transit(
        &mut self,
        now: Duration,
        from: PeerId,
        to: PeerId,
        bytes: u64,
        delay: Duration,
    ) -> Duration {
        let n = &self.network;
        let one_way = (delay.as_secs_f64() + self.link_deviation(from, to)).max(0.0);
        let mut flight = one_way;
        if n.loss > 0.0 {
            let probe = 3.0 * 2.0 * one_way + 1e-3;
            while self.rng.unit() < n.loss {
                flight += probe;
            }
        }
        let Some(bandwidth) = n.bandwidth else {
            return Duration::from_secs_f64(flight);
        };
        let wire = Duration::from_secs_f64(bytes as f64 / bandwidth);
        let (from, to) = (from.0 as usize, to.0 as usize);
        let departed = self.uplink_free[from].max(now) + wire;
        self.uplink_free[from] = departed;
        let reached = departed + Duration::from_secs_f64(flight);
        let arrived = reached.max(self.downlink_free[to] + wire);
        self.downlink_free[to] = arrived;
        arrived - now
    }

    /// The round trip QUIC would report on the link between `a` and `b`: its one-way latency
    /// (the mean moved by the link's fixed spread) both ways; jitter, losses and queues left
    /// out, as QUIC's smoothed estimate leaves them.
    pub(crate) fn round_trip(&self, a: PeerId, b: PeerId) -> Duration {
        let one_way = self.network.latency.as_secs_f64() + self.link_deviation(a, b);
        Duration::from_secs_f64(2.0 * one_way.max(0.0))
    }

    /// Seconds this link's latency differs from the mean, the same both ways.
    fn link_deviation(&self, a: PeerId, b: PeerId) -> f64 {
        let n = &self.network;
        n.latency.as_secs_f64() * n.link_spread * self.link_offset(a, b)
    }

    /// This link's fixed deviation from the mean latency, in `[-1, 1]`, the same both ways.
    fn link_offset(&self, a: PeerId, b: PeerId) -> f64 {
        let (lo, hi) = (a.0.min(b.0), a.0.max(b.0));
        let mut rng = SplitMix(self.seed ^ (u64::from(lo) << 32 | u64::from(hi)));
        2.0 * rng.unit() - 1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bandwidth_queues_messages_on_both_links() {
        let network = Network {
            bandwidth: Some(1000.0),
            latency: Duration::from_millis(10),
            ..Network::default()
        };
        let mut links = Links::new(network, 3, 1);
        let delay = Duration::from_millis(10);
        let (a, b, owner) = (PeerId(1), PeerId(2), PeerId(0));
        // 100 bytes take 0.1 s on each link: out of the sender, 10 ms across, and the
        // receiver's downlink is free, so the message arrives when its last byte does.
        let first = links.transit(Duration::ZERO, a, owner, 100, delay);
        assert_eq!(first, Duration::from_millis(110));
        // Another peer's message to the same receiver waits for the downlink.
        let second = links.transit(Duration::ZERO, b, owner, 100, delay);
        assert_eq!(second, Duration::from_millis(210));
    }

    #[test]
    fn loss_only_delays() {
        let network = Network {
            loss: 0.5,
            latency: Duration::from_millis(1),
            ..Network::default()
        };
        let mut links = Links::new(network, 2, 7);
        let delays: Vec<Duration> = (0..200)
            .map(|_| {
                links.transit(
                    Duration::ZERO,
                    PeerId(0),
                    PeerId(1),
                    10,
                    Duration::from_millis(1),
                )
            })
            .collect();
        let resent = delays
            .iter()
            .filter(|d| **d > Duration::from_millis(1))
            .count();
        assert!(
            (60..140).contains(&resent),
            "{resent} of 200 resent at loss 0.5"
        );
        assert!(delays.iter().all(|d| *d >= Duration::from_millis(1)));
    }
}
