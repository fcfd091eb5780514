//! Dealing an ordered list of tiles to peers.
//!
//! **Contiguous runs.** Peer `k` (of `P`, with speed weight `u_k`, normalised so `sum u = 1`)
//! gets one run of consecutive tiles. With `W` the total predicted cost and `L` the largest
//! tile's, the cut guarantees a common `lambda` with
//!
//! ```text
//! lambda * u_k  <=  cost(run k)  <=  lambda * u_k + L      for every peer k,
//! ```
//!
//! so with equal weights **any two runs differ by at most the largest tile**, and every run is
//! within `L` of its share `W / P`. The simple greedy cut does not give this: cutting at the
//! last prefix sum below each boundary `k * W / P` only keeps each run within `L` of its share,
//! so two runs may differ by nearly `2L` (tiles `[1.01, 9, 9.99, 9, 1]` to 3 peers: that greedy
//! gives runs 1.01, 18.99, 10 although 10.01, 9.99, 10 exist), and rounding each cut to the
//! nearest boundary still allows more than `L`.
//!
//! How: call the prefix sums `S_0 = 0 <= S_1 <= ... <= S_n = W` points; neighbours are at
//! most `L` apart. For a given `lambda`, the cut positions reachable after `k` runs each within
//! its band form a contiguous range of points, because the windows
//! `[S_i + lambda u_k, S_i + lambda u_k + L]` of neighbouring points overlap. The range's ends
//! follow two greedy chains (always the shortest allowed run, always the longest), so checking
//! a `lambda` costs `O(P log n)`. We take the largest `lambda*` whose shortest-run chain fits
//! within the tiles (by bisection: fitting is monotone in `lambda`), and recover the cuts
//! backwards, each the one nearest the plain proportional cut that the band allows.
//!
//! Why `lambda*` always works, i.e. its longest-run chain reaches `W`: `lambda*` exists, since
//! `lambda = 0` fits, nothing above `W` does, and a chain only jumps just *after* a target meets
//! a point. For a slightly larger `lambda* + e` the shortest-run chain no longer fits: at some
//! run `k` its target passes `W`. But from any point `x`, the first point at or past
//! `x + (lambda* + e) u` is at most one gap, so at most `L`, after the last point at or before
//! `x + lambda* u` (for `e` small enough), so it is no further than the longest run from `x` at
//! `lambda*`. Run by run, then, the longest-run chain at `lambda*` stays level with or ahead of
//! the failing chain, and at run `k` its window `[.., x + lambda* u_k + L]` reaches past
//! `W - e u_k + L >= W`: it takes the last point, `W`. Both ends of the reachable range are
//! thus fine and `W` is in it. (Floating-point rounding could in principle break a comparison
//! by an ulp; should a step then find no cut, we fall back to the proportional cut at the
//! prefix sum *nearest* each boundary, which still keeps each run within `L` of its share, as
//! each cut is within `L / 2` of its boundary.)
//!
//! Where prefix sums tie (tiles predicted to cost nothing), cuts prefer the proportional tile
//! count, so free tiles are still spread. If every tile is predicted to cost nothing, tiles are
//! dealt by count.
//!
//! **Interleaved.** Tiles in order, each to the peer with the least predicted load over its
//! share (list scheduling): every share is spread over the image and balanced in predicted
//! cost, within the largest tile for equal weights. See [`interleaved`].
//!
//! **Round-robin.** Tile `i` goes to the peer with the most accumulated credit, each peer
//! earning its weight per tile (smooth weighted round-robin); with equal weights, tile `i` goes
//! to peer `i mod P`.

use std::ops::Range;

use serde::{Deserialize, Serialize};

use crate::{Error, Order};

/// Which tiles each peer starts a frame with: `runs[p]` holds tile indices for peer `p`, in
/// order. Every peer has a run, possibly empty (more peers than tiles).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Assignment {
    /// Peer `p`'s tile indices, in the order it renders them; one run per peer.
    pub runs: Vec<Vec<usize>>,
}

impl Assignment {
    /// How many peers the tiles were dealt to, counting those dealt nothing.
    pub fn peers(&self) -> usize {
        self.runs.len()
    }

    /// The sum of `costs[tile]` over each peer's run.
    pub fn run_costs(&self, costs: &[f64]) -> Vec<f64> {
        self.runs
            .iter()
            .map(|run| run.iter().map(|&tile| costs[tile]).sum())
            .collect()
    }
}

/// Deals tiles with predicted `costs` to `peers` peers by `order`, weighted by peer speed
/// (`None`: all equal).
pub fn assign(
    costs: &[f64],
    order: Order,
    peers: usize,
    weights: Option<&[f64]>,
) -> Result<Assignment, Error> {
    let equal;
    let weights = match weights {
        Some(weights) if weights.len() != peers => {
            return Err(Error::Weights("one weight per peer is needed"));
        }
        Some(weights) => weights,
        None => {
            equal = vec![1.0; peers];
            &equal
        }
    };
    let runs = match order {
        Order::Contiguous => contiguous(costs, weights)?
            .into_iter()
            .map(Iterator::collect)
            .collect(),
        Order::RoundRobin => round_robin(costs.len(), weights)?,
        Order::Interleaved => interleaved(costs, weights)?,
    };
    Ok(Assignment { runs })
}

/// Cuts tiles with predicted `costs` into one contiguous run per weight, as the module docs
/// describe.
pub fn contiguous(costs: &[f64], weights: &[f64]) -> Result<Vec<Range<usize>>, Error> {
    let shares = normalise(weights)?;
    check_costs(costs)?;
    let by_count = costs.iter().all(|&cost| cost == 0.0);
    let mut prefix = Vec::with_capacity(costs.len() + 1);
    prefix.push(0.0);
    for &cost in costs {
        prefix.push(prefix[prefix.len() - 1] + if by_count { 1.0 } else { cost });
    }
    if !prefix[costs.len()].is_finite() {
        return Err(Error::Overflow);
    }
    let largest = if by_count {
        1.0
    } else {
        costs.iter().fold(0.0, |a: f64, &b| a.max(b))
    };
    let proportional = proportional_cuts(&prefix, &shares);
    let cuts = band_cuts(&prefix, &shares, largest, &proportional).unwrap_or(proportional);
    Ok(cuts.windows(2).map(|pair| pair[0]..pair[1]).collect())
}

/// Deals `tiles` tiles one at a time by smooth weighted round-robin.
pub fn round_robin(tiles: usize, weights: &[f64]) -> Result<Vec<Vec<usize>>, Error> {
    let shares = normalise(weights)?;
    let mut credit = vec![0.0; shares.len()];
    let mut runs = vec![Vec::new(); shares.len()];
    for tile in 0..tiles {
        for (credit, share) in credit.iter_mut().zip(&shares) {
            *credit += share;
        }
        // The first peer with the most credit: a deterministic tie-break.
        let best =
            (0..credit.len()).fold(0, |best, p| if credit[p] > credit[best] { p } else { best });
        credit[best] -= 1.0;
        runs[best].push(tile);
    }
    Ok(runs)
}

/// Deals tiles with predicted `costs` one at a time, in order, each to the peer whose predicted
/// load over its share is the lowest (ties: the lowest index), as list scheduling does: with
/// equal weights, no two peers' predicted loads differ by more than the largest tile. If every
/// tile is predicted to cost nothing, tiles are dealt by count.
pub fn interleaved(costs: &[f64], weights: &[f64]) -> Result<Vec<Vec<usize>>, Error> {
    use std::cmp::{Ordering, Reverse};
    use std::collections::BinaryHeap;

    /// A peer's load over its share, ordered by `total_cmp`, then by peer index.
    #[derive(PartialEq)]
    struct Load(f64, usize);
    impl Eq for Load {}
    impl PartialOrd for Load {
        fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
            Some(self.cmp(other))
        }
    }
    impl Ord for Load {
        fn cmp(&self, other: &Self) -> Ordering {
            self.0.total_cmp(&other.0).then(self.1.cmp(&other.1))
        }
    }

    let shares = normalise(weights)?;
    check_costs(costs)?;
    if costs.iter().all(|&cost| cost == 0.0) {
        return round_robin(costs.len(), weights);
    }
    let mut runs = vec![Vec::new(); shares.len()];
    let mut loads = vec![0.0; shares.len()];
    // Peers with no share get nothing; the others wait in a min-heap of load over share.
    let mut heap: BinaryHeap<Reverse<Load>> = (0..shares.len())
        .filter(|&p| shares[p] > 0.0)
        .map(|p| Reverse(Load(0.0, p)))
        .collect();
    for (tile, &cost) in costs.iter().enumerate() {
        let Reverse(Load(_, peer)) = heap.pop().expect("normalise leaves a positive share");
        runs[peer].push(tile);
        loads[peer] += cost;
        heap.push(Reverse(Load(loads[peer] / shares[peer], peer)));
    }
    Ok(runs)
}

/// Refuses the first predicted cost that is negative or not finite.
fn check_costs(costs: &[f64]) -> Result<(), Error> {
    match costs
        .iter()
        .enumerate()
        .find(|(_, c)| !(c.is_finite() && **c >= 0.0))
    {
        Some((index, &value)) => Err(Error::InvalidTileCost { index, value }),
        None => Ok(()),
    }
}

/// Weights scaled to sum to one.
fn normalise(weights: &[f64]) -> Result<Vec<f64>, Error> {
    if weights.is_empty() {
        return Err(Error::NoPeers);
    }
    if weights.iter().any(|w| !(w.is_finite() && *w >= 0.0)) {
        return Err(Error::Weights("weights must be finite and non-negative"));
    }
    let total: f64 = weights.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return Err(Error::Weights("weights must have a positive finite sum"));
    }
    Ok(weights.iter().map(|w| w / total).collect())
}

/// Boundary `k` of the proportional cut: `W * (u_0 + ... + u_{k-1})`, and the same fraction of
/// the tile count, for `k` in `0..=P`.
fn boundaries(shares: &[f64], total: f64, tiles: usize) -> impl Iterator<Item = (f64, f64)> + '_ {
    let mut before = 0.0;
    (0..=shares.len()).map(move |k| {
        let fraction = if k == shares.len() { 1.0 } else { before };
        if k < shares.len() {
            before += shares[k];
        }
        (total * fraction, tiles as f64 * fraction)
    })
}

/// The proportional cut: at each boundary, the point with the nearest prefix sum; among equal
/// prefix sums, the one nearest the proportional tile count. Cut `k` is within `L / 2` of its
/// boundary, so each run is within `L` of its share.
fn proportional_cuts(prefix: &[f64], shares: &[f64]) -> Vec<usize> {
    let n = prefix.len() - 1;
    let mut previous = 0;
    boundaries(shares, prefix[n], n)
        .map(|(boundary, count)| {
            let above = prefix.partition_point(|&s| s < boundary);
            let value = if above > n {
                prefix[n]
            } else if above == 0 || prefix[above] - boundary <= boundary - prefix[above - 1] {
                prefix[above]
            } else {
                prefix[above - 1]
            };
            let first = prefix.partition_point(|&s| s < value);
            let last = prefix.partition_point(|&s| s <= value) - 1;
            previous = (count.round() as usize).clamp(first, last).max(previous);
            previous
        })
        .collect()
}

/// The banded cut of the module docs, or `None` if no band was found.
fn band_cuts(
    prefix: &[f64],
    shares: &[f64],
    largest: f64,
    preferred: &[usize],
) -> Option<Vec<usize>> {
    let (n, p, total) = (prefix.len() - 1, shares.len(), prefix[prefix.len() - 1]);
    // Shortest allowed runs: cut `k + 1` at the first point at least `lambda * u_k` past cut
    // `k`; `visit` sees each cut. False if a run would end past the last tile.
    let shortest = |lambda: f64, mut visit: Option<&mut Vec<usize>>| -> bool {
        let mut at = 0;
        for &share in shares {
            let target = prefix[at] + lambda * share;
            if target > total {
                return false;
            }
            at = prefix.partition_point(|&s| s < target);
            if let Some(chain) = visit.as_deref_mut() {
                chain.push(at);
            }
        }
        true
    };
    // Longest allowed runs from the shortest-run chain's `lambda`: the largest point at most
    // `lambda * u_k + L` past the last. Whether that reaches the last tile.
    let longest = |lambda: f64, high: &mut Vec<usize>| -> bool {
        high.clear();
        high.push(0);
        for &share in shares {
            let limit = prefix[high[high.len() - 1]] + lambda * share + largest;
            high.push(prefix.partition_point(|&s| s <= limit) - 1);
        }
        high[p] == n
    };
    // The largest feasible lambda, by bisection: feasibility is monotone in lambda. Every hop
    // of the shortest-run chain overshoots its target by less than L, so lambda = W - P L is
    // feasible, and no lambda above W is. A lambda a little below the largest usually does as
    // well, so bisection first stops at a relative 1e-9, and goes on down to adjacent floats
    // only if the longest-run chain then falls short.
    let (mut lambda, mut infeasible) = ((total - p as f64 * largest).max(0.0), total);
    if shortest(total, None) {
        lambda = total;
    }
    let (mut low, mut high) = (Vec::with_capacity(p + 1), Vec::with_capacity(p + 1));
    for tolerance in [1e-9 * total, 0.0] {
        while lambda < infeasible {
            let mid = 0.5 * (lambda + infeasible);
            if mid <= lambda || mid >= infeasible || infeasible - lambda <= tolerance {
                break;
            }
            if shortest(mid, None) {
                lambda = mid
            } else {
                infeasible = mid
            }
        }
        low.clear();
        low.push(0);
        if !shortest(lambda, Some(&mut low)) {
            return None;
        }
        if longest(lambda, &mut high) {
            break;
        }
    }
    if high[p] < n {
        return None;
    }
    // Backwards: cut k must be reachable after k runs and leave run k within its band.
    let mut cuts = vec![0; p + 1];
    cuts[p] = n;
    for k in (1..p).rev() {
        let end = prefix[cuts[k + 1]];
        let step = lambda * shares[k];
        let latest = prefix
            .partition_point(|&s| s + step <= end)
            .checked_sub(1)?;
        let earliest = prefix.partition_point(|&s| s + step + largest < end);
        let (from, to) = (earliest.max(low[k]), latest.min(high[k]).min(cuts[k + 1]));
        if from > to {
            return None;
        }
        cuts[k] = preferred[k].clamp(from, to);
    }
    Some(cuts)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_costs(costs: &[f64], runs: &[Range<usize>]) -> Vec<f64> {
        runs.iter()
            .map(|run| costs[run.clone()].iter().sum())
            .collect()
    }

    #[test]
    fn interleaving_deals_every_tile_once_within_the_largest_tile() {
        // A hot run in the middle of a cheap image: the costs a moving spot gives.
        let costs: Vec<f64> = (0..200)
            .map(|i| {
                if (80..100).contains(&i) {
                    50.0 + f64::from(i % 7)
                } else {
                    1.0 + f64::from(i % 3)
                }
            })
            .collect();
        let largest = costs.iter().fold(0.0f64, |a, &b| a.max(b));
        for peers in [1, 2, 3, 7, 16] {
            let runs = interleaved(&costs, &vec![1.0; peers]).unwrap();
            let mut dealt: Vec<usize> = runs.iter().flatten().copied().collect();
            dealt.sort();
            assert_eq!(dealt, (0..200).collect::<Vec<_>>(), "{peers} peers");
            let loads: Vec<f64> = runs
                .iter()
                .map(|r| r.iter().map(|&t| costs[t]).sum())
                .collect();
            let (low, high) = loads
                .iter()
                .fold((f64::MAX, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)));
            assert!(high - low <= largest, "{peers} peers: loads {loads:?}");
            // The hot tiles are spread: no peer holds more than its share of them plus one.
            let hot = |run: &Vec<usize>| run.iter().filter(|t| (80..100).contains(*t)).count();
            assert!(
                runs.iter().all(|r| hot(r) <= 20usize.div_ceil(peers) + 1),
                "{peers} peers"
            );
        }
    }

    #[test]
    fn interleaving_equal_costs_is_round_robin_and_weights_are_followed() {
        let runs = interleaved(&[2.0; 9], &[1.0; 3]).unwrap();
        assert_eq!(runs, vec![vec![0, 3, 6], vec![1, 4, 7], vec![2, 5, 8]]);
        // A peer twice as fast gets about twice the predicted work.
        let runs = interleaved(&[1.0; 30], &[2.0, 1.0]).unwrap();
        assert_eq!((runs[0].len(), runs[1].len()), (20, 10));
        // Nothing predicted: dealt by count.
        assert_eq!(
            interleaved(&[0.0; 4], &[1.0; 2]).unwrap(),
            vec![vec![0, 2], vec![1, 3]]
        );
        assert!(interleaved(&[1.0, f64::NAN], &[1.0]).is_err());
    }

    #[test]
    fn banded_cut_beats_the_floor_greedy_counterexample() {
        let costs = [1.01, 9.0, 9.99, 9.0, 1.0];
        let runs = contiguous(&costs, &[1.0; 3]).unwrap();
        // By hand: 1.01 + 9 | 9.99 | 9 + 1, runs of 10.01, 9.99 and 10.
        assert_eq!(runs, vec![0..2, 2..3, 3..5]);
    }

    #[test]
    fn more_peers_than_tiles_gives_empty_runs() {
        let runs = contiguous(&[5.0, 3.0], &[1.0; 4]).unwrap();
        assert_eq!(runs.len(), 4);
        let mut tiles: Vec<usize> = runs.iter().flat_map(Clone::clone).collect();
        tiles.sort();
        assert_eq!(tiles, vec![0, 1]);
        let costs = run_costs(&[5.0, 3.0], &runs);
        assert!(costs.iter().all(|&c| c == 0.0 || c == 5.0 || c == 3.0));
        assert_eq!(contiguous(&[], &[1.0; 3]).unwrap(), vec![0..0, 0..0, 0..0]);
    }

    #[test]
    fn weights_scale_the_shares() {
        // Twelve unit tiles, peer 1 twice as fast as peers 0 and 2: 3, 6, 3.
        let runs = contiguous(&[1.0; 12], &[1.0, 2.0, 1.0]).unwrap();
        assert_eq!(runs, vec![0..3, 3..9, 9..12]);
        // A peer of weight zero gets nothing when the rest can be balanced exactly.
        let runs = contiguous(&[1.0; 4], &[1.0, 0.0, 1.0]).unwrap();
        assert_eq!(run_costs(&[1.0; 4], &runs), vec![2.0, 0.0, 2.0]);
    }

    #[test]
    fn free_tiles_are_spread_by_count() {
        assert_eq!(
            contiguous(&[0.0; 6], &[1.0; 3]).unwrap(),
            vec![0..2, 2..4, 4..6]
        );
        // One expensive tile among free ones: the cut lands where the count says.
        let runs = contiguous(&[0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0], &[1.0; 2]).unwrap();
        assert_eq!(runs, vec![0..4, 4..8]);
    }

    #[test]
    fn round_robin_deals_in_turn_and_by_weight() {
        assert_eq!(
            round_robin(5, &[1.0; 2]).unwrap(),
            vec![vec![0, 2, 4], vec![1, 3]]
        );
        let runs = round_robin(6, &[2.0, 1.0]).unwrap();
        assert_eq!(runs.iter().map(Vec::len).collect::<Vec<_>>(), vec![4, 2]);
    }

    #[test]
    fn bad_peers_and_weights_are_errors() {
        assert_eq!(
            assign(&[1.0], Order::Contiguous, 0, None).unwrap_err(),
            Error::NoPeers
        );
        let mismatch = assign(&[1.0], Order::Contiguous, 2, Some(&[1.0]));
        assert!(matches!(mismatch, Err(Error::Weights(_))));
        for weights in [
            [f64::NAN, 1.0],
            [-1.0, 1.0],
            [0.0, 0.0],
            [f64::INFINITY, 1.0],
        ] {
            let result = assign(&[1.0], Order::RoundRobin, 2, Some(&weights));
            assert!(matches!(result, Err(Error::Weights(_))), "{weights:?}");
        }
        let nan = contiguous(&[1.0, f64::NAN], &[1.0]);
        assert!(matches!(nan, Err(Error::InvalidTileCost { index: 1, .. })));
    }
}
