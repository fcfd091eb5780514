//! What a peer has measured about itself and the network: its slots' rendering rate and the
//! round trip its steals are planned with ([`Estimates`]).

use std::time::Duration;

use super::config::Config;
use crate::rng::SplitMix;

/// What a peer has measured about itself and the network.
pub(super) struct Estimates {
    /// Predicted cost rendered per second by one slot; `None` before the first tile.
    pub(super) slot_rate: Option<f64>,
    /// The round trip steals are planned with (the low-water mark, whether a grant pays, how
    /// long a request may go unanswered): the smoothed time of this peer's own steal exchanges,
    /// request to answer, the victim's time to answer included; before the first, the links'
    /// round trips as the driver measured them, or `Config::initial_rtt` before either.
    pub(super) rtt: Duration,
    /// Whether `rtt` comes from a steal exchange yet.
    rtt_measured: bool,
    /// Whether `rtt` comes from a link's round trip, before any exchange.
    rtt_seeded: bool,
    /// Draws victims: a stream of its own per peer, so that thieves do not draw alike.
    pub(super) rng: SplitMix,
}

impl Estimates {
    pub(super) fn new(config: &Config, rng: SplitMix) -> Self {
        Self {
            slot_rate: None,
            rtt: config.initial_rtt,
            rtt_measured: false,
            rtt_seeded: false,
            rng,
        }
    }

    /// Folds in one rendered tile: its predicted cost and how long a slot took over it.
    pub(super) fn sample_rate(&mut self, predicted: f64, took: Duration) {
        let secs = took.as_secs_f64();
        if predicted > 0.0 && secs > 0.0 {
            let sample = predicted / secs;
            self.slot_rate = Some(self.slot_rate.map_or(sample, |r| r + (sample - r) * 0.25));
        }
    }

    /// A link's round trip as the driver measures it: until a steal exchange has been timed,
    /// the estimate is these, smoothed as exchanges are (the links may differ); after, they
    /// move it no more. Fed every link's round trip (the QUIC driver reports one with every
    /// message), the estimate followed the bare links, which leave out the victims' time to
    /// answer, and stealing in the simulator ran less efficiently than seeded only
    /// (docs/results.md, "Re-run on 2026-12-05"). A zero round trip, an ideal link in the
    /// simulator, is no measurement and is not taken: planned with it, a peer would never
    /// ask before it ran dry and a victim would find every grant worth its transfer.
    pub(super) fn seed_rtt(&mut self, rtt: Duration) {
        if self.rtt_measured || rtt.is_zero() {
            return;
        }
        self.rtt = smoothed(self.rtt, rtt, std::mem::replace(&mut self.rtt_seeded, true));
    }

    /// Folds in one steal exchange's round trip, smoothed as TCP does.
    pub(super) fn sample_rtt(&mut self, rtt: Duration) {
        self.rtt = smoothed(
            self.rtt,
            rtt,
            std::mem::replace(&mut self.rtt_measured, true),
        );
    }

    /// How long a steal request may stay unanswered: `steal_timeout_rtts` round trips, at
    /// least 2 ms, at most `steal_timeout`.
    pub(super) fn steal_timeout(&self, config: &Config) -> Duration {
        let floor = Duration::from_millis(2).min(config.steal_timeout);
        self.rtt
            .mul_f64(config.steal_timeout_rtts.max(0.0))
            .clamp(floor, config.steal_timeout)
    }

    /// Seconds this peer needs for `work`, if it has measured its rate yet.
    pub(super) fn seconds_for(&self, work: f64, slots: usize) -> Option<f64> {
        self.slot_rate
            .filter(|r| *r > 0.0)
            .map(|r| work / (r * slots.max(1) as f64))
    }
}

/// `sample` folded into the estimate `old` as TCP smooths round trips (7/8 old, 1/8 new), or
/// `sample` alone where `old` holds no sample of the same kind yet.
fn smoothed(old: Duration, sample: Duration, old_is_a_sample: bool) -> Duration {
    if old_is_a_sample {
        (old * 7 + sample) / 8
    } else {
        sample
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    /// The driver's round trips of links stand in, smoothed, until a steal exchange is timed,
    /// and change nothing after: an exchange's time includes the victim's time to answer,
    /// which a link's round trip leaves out. A zero round trip is no measurement.
    #[test]
    fn links_round_trips_seed_the_estimate_and_steal_exchanges_set_it() {
        let config = Config::default();
        let mut estimates = Estimates::new(&config, SplitMix(1));
        assert_eq!(estimates.rtt, config.initial_rtt);
        estimates.seed_rtt(Duration::ZERO);
        assert_eq!(
            estimates.rtt, config.initial_rtt,
            "a zero round trip is not taken"
        );
        estimates.seed_rtt(ms(40));
        assert_eq!(
            estimates.rtt,
            ms(40),
            "the first link's round trip replaces the default"
        );
        estimates.seed_rtt(ms(120));
        assert_eq!(
            estimates.rtt,
            ms(50),
            "links' round trips are smoothed, 7/8 old and 1/8 new"
        );
        estimates.sample_rtt(ms(80));
        assert_eq!(
            estimates.rtt,
            ms(80),
            "the first exchange replaces the seeds"
        );
        for _ in 0..100 {
            estimates.seed_rtt(ms(1));
        }
        assert_eq!(estimates.rtt, ms(80), "links' round trips move it no more");
        estimates.sample_rtt(ms(160));
        assert_eq!(estimates.rtt, ms(90), "exchanges are smoothed alike");
    }

    /// The timeout follows the estimate within its bounds: at least 2 ms, at most
    /// `steal_timeout`.
    #[test]
    fn the_steal_timeout_is_bounded() {
        let config = Config::default();
        let mut estimates = Estimates::new(&config, SplitMix(1));
        estimates.sample_rtt(Duration::from_micros(10));
        assert_eq!(estimates.steal_timeout(&config), ms(2));
        let mut estimates = Estimates::new(&config, SplitMix(1));
        estimates.sample_rtt(ms(5));
        assert_eq!(
            estimates.steal_timeout(&config),
            ms(5).mul_f64(config.steal_timeout_rtts)
        );
        let mut estimates = Estimates::new(&config, SplitMix(1));
        estimates.sample_rtt(ms(500));
        assert_eq!(estimates.steal_timeout(&config), config.steal_timeout);
    }
}
