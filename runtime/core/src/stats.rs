//! What a render records: the schema of `stats.json` (documented in `docs/stats.md`), which the
//! QUIC node's renders write and the simulator reads back (`tessera simulate --validate`), and
//! the per-piece records a frame's statistics are made from.
//!
//! It lives here, beside the director that hands over the pieces it is made from, because both
//! drivers depend on this crate and the simulator must not link the QUIC runtime. Plain data and
//! pure functions: no I/O (the drivers read and write the JSON). Fields are only ever added;
//! fields missing from older files read as their defaults.

use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::time::Duration;

use balancer::Rect;
use serde::{Deserialize, Serialize};

use crate::peer::PeerStats;
use crate::wire::PeerId;

/// The `--stats` file: one entry per frame, plus what the render was.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct StatsFile {
    /// The scene file rendered, as given on the command line.
    pub scene: String,
    /// The image's width in pixels.
    pub width: u32,
    /// The image's height in pixels.
    pub height: u32,
    /// Samples traced per pixel.
    pub samples_per_pixel: u32,
    /// `pbt` or `regular`.
    pub balancer: String,
    /// How tiles were dealt to peers: `interleaved`, `contiguous` or `round-robin` (empty in
    /// files written before dealing was a choice, which always dealt contiguously).
    pub deal: String,
    /// Motion-compensated prediction (`--motion`): the largest shift searched, in blocks per
    /// frame, or `off` (empty in files written before it existed, which predicted still: off).
    pub motion: String,
    /// The light-transport effects the render paid for (see `tracer::Effects`).
    pub effects: String,
    /// How many peers the render was started with.
    pub peers: usize,
    /// The render's identity: a hash of the scene files and the render settings
    /// (`runtime::node::bundle::render_hash`), also in every frame's EXR header. Empty in files
    /// written before `--resume` existed.
    pub render_hash: String,
    /// The first frame this run rendered: 0, or with `--resume` the first frame missing. The
    /// frames before it were done already and have no entry in `frames`.
    pub first_frame: u32,
    /// The frames this run rendered, in order.
    pub frames: Vec<FrameStats>,
}

impl StatsFile {
    /// Adds each peer's own account of each frame (as its core counted it, keyed by frame and
    /// peer) to that frame's entry, and counts as the render's peers everyone who took part:
    /// peers may join a served render after it started. Frames without an entry (none was
    /// rendered by this run) are skipped.
    pub fn add_peer_accounts(&mut self, accounts: &BTreeMap<(u32, PeerId), PeerStats>) {
        let took_part: BTreeSet<PeerId> = accounts.keys().map(|(_, peer)| *peer).collect();
        self.peers = self.peers.max(took_part.len());
        for ((frame, peer), account) in accounts {
            if let Some(entry) = self.frames.iter_mut().find(|f| f.frame == *frame) {
                entry.peers.push(PeerFrameStats::new(peer.0, account));
            }
        }
    }
}

/// One frame.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct FrameStats {
    /// The frame's number in the animation.
    pub frame: u32,
    /// Wall time from the first tile handed out to the last tile received, in seconds.
    pub seconds: f64,
    /// When the frame was complete, in seconds since the render started (0 in older files).
    /// Frames overlap, so the difference between two frames' is what each added to the render.
    pub completed_at: f64,
    /// Rays traced for the frame, of every kind.
    pub rays: u64,
    /// Counted work of the whole frame (the tracer's deterministic cost unit).
    pub work: u64,
    /// Population variance of the measured leaf costs (counted work).
    pub leaf_cost_variance: f64,
    /// Largest measured leaf cost divided by the mean: 1 is a perfect partition.
    pub leaf_cost_max_over_mean: f64,
    /// Every tile's record, in tile order.
    pub tiles: Vec<TileStats>,
    /// Each peer's own account of the frame.
    pub peers: Vec<PeerFrameStats>,
    /// Duplicate results (backups of stragglers, re-issued tiles) the owner compared with the
    /// first and found bit-identical, and found different: a free audit of determinism.
    pub duplicates_agreed: u32,
    /// Results that differed from the first: a peer is broken, as rendering is deterministic.
    pub duplicates_disagreed: u32,
    /// Tiles the owner gave again because no live holder was rendering them (their holders
    /// were lost, or every peer was idle with the tile still missing).
    pub tiles_reissued: u32,
    /// Tiles of overdue peers the owner copied to idle peers. Their duplicates are compared
    /// above only where they arrive before the frame is done. Both counts are of times given:
    /// a tile given again twice counts twice.
    pub tiles_backed_up: u32,
    /// The frame's participants the owner gave up on while it ran (lost, or silent past their
    /// timeout; not those that left when asked). A peer lost between frames counts in none.
    pub peers_failed: u32,
}

/// One peer's account of one frame (times in seconds of slot time: a peer with 2 rendering
/// threads busy for 1 s reports 2 s busy).
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct PeerFrameStats {
    /// The peer's id.
    pub peer: u32,
    /// Its rendering threads (slots).
    pub threads: u32,
    /// Slot-seconds spent rendering.
    pub busy_seconds: f64,
    /// Slot-seconds not rendering.
    pub idle_seconds: f64,
    /// Tiles and pieces it rendered.
    pub tiles_rendered: u32,
    /// Tiles this peer took from others.
    pub tiles_stolen: u32,
    /// Tiles this peer gave to thieves.
    pub tiles_given: u32,
    /// Steal requests it sent as a thief.
    pub steal_requests_sent: u32,
    /// Of those, refused or unanswered in time.
    pub steal_requests_refused: u32,
    /// Bytes it sent, as its driver counted them.
    pub bytes_sent: u64,
    /// Bytes it received, as its driver counted them.
    pub bytes_received: u64,
}

impl PeerFrameStats {
    /// Peer `peer`'s own statistics of a frame, as its core counted them.
    pub fn new(peer: u32, s: &PeerStats) -> Self {
        Self {
            peer,
            threads: s.slots,
            busy_seconds: s.busy.as_secs_f64(),
            idle_seconds: s.idle.as_secs_f64(),
            tiles_rendered: s.tiles_rendered,
            tiles_stolen: s.tiles_stolen,
            tiles_given: s.tiles_given,
            steal_requests_sent: s.steal_requests_sent,
            steal_requests_refused: s.steal_requests_refused,
            bytes_sent: s.bytes_sent,
            bytes_received: s.bytes_received,
        }
    }
}

/// A tile of a finished frame, or one piece of it. The one record of a tile's facts (where it
/// is, what was predicted and measured, who was dealt it and who rendered it): the owner makes
/// one per piece it accepted ([`TileStats::piece`]), and the file holds one per tile of the
/// partition, its pieces summed ([`TileStats::per_tile`]).
#[derive(Debug, Default, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TileStats {
    /// The tile's index in the frame's partition (depth-first leaf order for the PBT).
    pub tile: u32,
    /// In pixels, origin at the top-left; written `[x, y, w, h]`.
    #[serde(with = "rect_as_array")]
    pub rect: Rect,
    /// The balancer's prediction, in counted work.
    pub predicted: f64,
    /// The measured counted work.
    pub measured: u64,
    /// The peer that rendered it (0 is the frame owner); of a tile rendered in pieces, the
    /// peer that rendered most of its pixels.
    pub peer: u32,
    /// The peer whose initial set held it; differs from `peer` when stolen or re-issued.
    pub initial_peer: u32,
    /// The pieces it arrived in: 1, or more where it was cut on the way (rendered half by half,
    /// or halved for a thief).
    pub pieces: u32,
}

impl TileStats {
    /// One piece as the owner accepted it.
    pub fn piece(
        tile: u32,
        rect: Rect,
        predicted: f64,
        measured: u64,
        peer: u32,
        initial_peer: u32,
    ) -> Self {
        Self {
            tile,
            rect,
            predicted,
            measured,
            peer,
            initial_peer,
            pieces: 1,
        }
    }

    /// One entry per tile of the partition from a frame's pieces (in tile order, a tile's
    /// pieces together): the tile's rectangle is their bounding box, its costs their sums, its
    /// peer the one that rendered most of its pixels.
    pub fn per_tile(pieces: &[TileStats]) -> Vec<TileStats> {
        let mut tiles: Vec<TileStats> = Vec::new();
        let mut rendered: Vec<(u32, u64)> = Vec::new();
        for piece in pieces {
            let r = piece.rect;
            match tiles.last_mut().filter(|t| t.tile == piece.tile) {
                Some(tile) => {
                    let t = tile.rect;
                    let (x1, y1) = ((t.x + t.w).max(r.x + r.w), (t.y + t.h).max(r.y + r.h));
                    let (x0, y0) = (t.x.min(r.x), t.y.min(r.y));
                    tile.rect = Rect::new(x0, y0, x1 - x0, y1 - y0);
                    tile.predicted += piece.predicted;
                    tile.measured += piece.measured;
                    tile.pieces += piece.pieces;
                }
                None => {
                    if let Some(tile) = tiles.last_mut() {
                        tile.peer = most_pixels(&rendered);
                    }
                    rendered.clear();
                    tiles.push(piece.clone());
                }
            }
            match rendered.iter_mut().find(|(peer, _)| *peer == piece.peer) {
                Some((_, pixels)) => *pixels += r.area(),
                None => rendered.push((piece.peer, r.area())),
            }
        }
        if let Some(tile) = tiles.last_mut() {
            tile.peer = most_pixels(&rendered);
        }
        tiles
    }
}

/// The peer with the most pixels (the first of equals).
fn most_pixels(rendered: &[(u32, u64)]) -> u32 {
    let mut best = (0, 0);
    for &(peer, pixels) in rendered {
        if pixels > best.1 {
            best = (peer, pixels);
        }
    }
    best.0
}

impl FrameStats {
    /// Fills the variance and max/mean from the tiles' measured costs.
    pub fn summarise_leaves(&mut self) {
        let n = self.tiles.len() as f64;
        if n == 0.0 {
            return;
        }
        let mean = self.tiles.iter().map(|t| t.measured as f64).sum::<f64>() / n;
        self.leaf_cost_variance = self
            .tiles
            .iter()
            .map(|t| (t.measured as f64 - mean).powi(2))
            .sum::<f64>()
            / n;
        let max = self.tiles.iter().map(|t| t.measured).max().unwrap_or(0) as f64;
        self.leaf_cost_max_over_mean = if mean > 0.0 { max / mean } else { 1.0 };
    }
}

/// One tile or piece a peer rendered, with when: a bar of the Gantt charts. Not a [`TileStats`]:
/// it is the renderer's account (every render, duplicates included, timed), where that is the
/// owner's (the one result kept, measured).
#[derive(Clone, Debug)]
pub struct LocalTile {
    /// The frame it belongs to.
    pub frame: u32,
    /// The tile's id in that frame.
    pub tile: u32,
    /// The pixels rendered: the whole tile's, or a piece's.
    pub rect: Rect,
    /// Whether it was a piece of a cut tile rather than the whole tile.
    pub piece: bool,
    /// Since the peer started.
    pub start: Duration,
    /// When it finished, since the peer started.
    pub end: Duration,
}

/// Results the owner kept, by (frame, peer, rectangle): a render not among them was a duplicate
/// of one that arrived first.
pub type Accepted = HashSet<(u32, u32, Rect)>;

/// `[x, y, w, h]`, as `stats.json` has always written a rectangle.
mod rect_as_array {
    use balancer::Rect;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(rect: &Rect, serializer: S) -> Result<S::Ok, S::Error> {
        [rect.x, rect.y, rect.w, rect.h].serialize(serializer)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Rect, D::Error> {
        let [x, y, w, h] = <[u32; 4]>::deserialize(deserializer)?;
        Ok(Rect::new(x, y, w, h))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tile cut in three pieces becomes one entry: bounding box, sums, and the peer of most
    /// pixels; the file keeps writing rectangles as arrays.
    #[test]
    fn pieces_fold_into_their_tile_and_rectangles_stay_arrays() {
        let pieces = [
            TileStats::piece(0, Rect::new(0, 0, 4, 4), 1.0, 10, 0, 0),
            TileStats::piece(1, Rect::new(4, 0, 2, 4), 0.5, 3, 1, 0),
            TileStats::piece(1, Rect::new(6, 0, 2, 2), 0.25, 2, 2, 0),
            TileStats::piece(1, Rect::new(6, 2, 2, 2), 0.25, 4, 2, 0),
        ];
        let tiles = TileStats::per_tile(&pieces);
        assert_eq!(tiles.len(), 2);
        assert_eq!(tiles[0], pieces[0]);
        assert_eq!(tiles[1].rect, Rect::new(4, 0, 4, 4));
        assert_eq!((tiles[1].predicted, tiles[1].measured), (1.0, 9));
        assert_eq!(
            (tiles[1].pieces, tiles[1].peer, tiles[1].initial_peer),
            (3, 1, 0)
        );
        let json = serde_json::to_string(&tiles[1]).expect("a tile serialises");
        assert!(json.contains("\"rect\":[4,0,4,4]"), "{json}");
        let back: TileStats = serde_json::from_str(&json).expect("and reads back");
        assert_eq!(back, tiles[1]);
    }

    /// Peers' accounts land in their frames' entries, in peer order; a peer that joined late
    /// raises the count of peers, and an account of a frame this run has no entry for is
    /// dropped.
    #[test]
    fn peer_accounts_join_their_frames_and_count_latecomers() {
        let mut file = StatsFile {
            peers: 2,
            first_frame: 3,
            frames: [3, 4]
                .map(|frame| FrameStats {
                    frame,
                    ..FrameStats::default()
                })
                .into(),
            ..StatsFile::default()
        };
        let account = |tiles_rendered| PeerStats {
            tiles_rendered,
            ..PeerStats::default()
        };
        let accounts = BTreeMap::from([
            ((2, PeerId(0)), account(9)),
            ((3, PeerId(1)), account(5)),
            ((3, PeerId(0)), account(7)),
            ((4, PeerId(2)), account(6)),
        ]);
        file.add_peer_accounts(&accounts);
        assert_eq!(file.peers, 3);
        let rendered = |i: usize| -> Vec<(u32, u32)> {
            let peers = &file.frames[i].peers;
            peers.iter().map(|p| (p.peer, p.tiles_rendered)).collect()
        };
        assert_eq!(rendered(0), [(0, 7), (1, 5)]);
        assert_eq!(rendered(1), [(2, 6)]);
    }
}
