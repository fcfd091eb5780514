//! The owner's view of one tile whose parts may arrive separately: which pieces are in, whether
//! they cover the tile, which parts are still missing, and whether two results agree.
//!
//! A tile can be cut on the way (a victim gives a thief the unstarted half of a tile, a worker
//! renders a large tile half by half) and re-issued whole or in parts, so the results of one
//! tile are pieces of its halving tree ([`Piece`]) that may nest: a re-issued whole tile and an
//! earlier half of it both arrive. Rendering is deterministic, so where two results overlap
//! their pixels must agree; the tile is complete once the pieces received cover it, and the
//! frame is assembled from a cover in which no two pieces overlap.
//!
//! Every walk here visits only subtrees that hold a received piece, so its cost is the number
//! of pieces times the depth, however deep the tree could go.

use std::collections::BTreeMap;

use balancer::Rect;

use crate::wire::{BYTES_PER_PIXEL, PeerId, Piece, TileResult, TileSpec};

/// The results received for one tile, by piece, with who sent each.
#[derive(Default)]
pub(super) struct Pieces {
    results: BTreeMap<Piece, (PeerId, TileResult)>,
}

impl Pieces {
    /// Every received result overlapping `piece` (an ancestor, the piece itself, or one inside
    /// it), with its sender.
    pub(super) fn overlapping(
        &self,
        piece: Piece,
    ) -> impl Iterator<Item = (PeerId, &TileResult)> + '_ {
        self.results
            .iter()
            .filter(move |(kept, _)| kept.is_within(piece) || piece.is_within(**kept))
            .map(|(_, (peer, result))| (*peer, result))
    }

    /// Every result received, in tree order.
    pub(super) fn results(&self) -> impl Iterator<Item = &TileResult> + '_ {
        self.results.values().map(|(_, result)| result)
    }

    pub(super) fn insert(&mut self, from: PeerId, result: TileResult) {
        self.results.insert(result.piece, (from, result));
    }

    /// Whether the pieces received cover the whole tile.
    pub(super) fn complete(&self) -> bool {
        self.covers(Piece::WHOLE)
    }

    fn covers(&self, piece: Piece) -> bool {
        if self.results.contains_key(&piece) {
            return true;
        }
        if !self.has_inside(piece) {
            return false;
        }
        let (first, second) = piece.halves();
        self.covers(first) && self.covers(second)
    }

    /// Whether some received piece lies strictly inside `piece`.
    fn has_inside(&self, piece: Piece) -> bool {
        self.results
            .keys()
            .any(|kept| *kept != piece && kept.is_within(piece))
    }

    /// The parts of `tile` no received piece covers, as the largest pieces that are wholly
    /// missing, in tree order.
    pub(super) fn missing(&self, tile: &TileSpec) -> Vec<TileSpec> {
        let mut out = Vec::new();
        self.collect_missing(*tile, &mut out);
        out
    }

    fn collect_missing(&self, spec: TileSpec, out: &mut Vec<TileSpec>) {
        if self.results.contains_key(&spec.piece) {
            return;
        }
        match spec.halves() {
            Some((first, second)) if self.has_inside(spec.piece) => {
                self.collect_missing(first, out);
                self.collect_missing(second, out);
            }
            _ => out.push(spec),
        }
    }

    /// Takes a cover of the tile by received pieces, no two overlapping, in tree order: the
    /// shallowest piece received wherever one was. Call only when [`Pieces::complete`].
    pub(super) fn into_cover(mut self) -> Vec<(PeerId, TileResult)> {
        let mut out = Vec::new();
        self.take_cover(Piece::WHOLE, &mut out);
        out
    }

    fn take_cover(&mut self, piece: Piece, out: &mut Vec<(PeerId, TileResult)>) {
        if let Some(found) = self.results.remove(&piece) {
            out.push(found);
            return;
        }
        let (first, second) = piece.halves();
        self.take_cover(first, out);
        self.take_cover(second, out);
    }
}

/// Whether two results agree, pixel for pixel, wherever their rectangles overlap. Pixels are
/// rows of [`BYTES_PER_PIXEL`]-byte values over each result's rectangle (checked on arrival).
pub(super) fn agree(a: &TileResult, b: &TileResult) -> bool {
    let Some(overlap) = intersection(a.rect, b.rect) else {
        return true;
    };
    (overlap.y..overlap.y + overlap.h).all(|y| {
        let (left, right) = (row_span(a, overlap, y), row_span(b, overlap, y));
        left.is_some() && left == right
    })
}

/// Row `y` of `overlap` within `result`'s pixels, if its buffer holds it.
fn row_span(result: &TileResult, overlap: Rect, y: u32) -> Option<&[u8]> {
    let row_bytes = u64::from(result.rect.w) * BYTES_PER_PIXEL;
    let start = u64::from(y - result.rect.y) * row_bytes
        + u64::from(overlap.x - result.rect.x) * BYTES_PER_PIXEL;
    let len = u64::from(overlap.w) * BYTES_PER_PIXEL;
    result.pixels.get(start as usize..(start + len) as usize)
}

fn intersection(a: Rect, b: Rect) -> Option<Rect> {
    let x = a.x.max(b.x);
    let y = a.y.max(b.y);
    let right = a.right().min(b.right());
    let bottom = a.bottom().min(b.bottom());
    (u64::from(x) < right && u64::from(y) < bottom).then(|| {
        // Both ends lie within a u32 rectangle, so the differences fit.
        Rect::new(
            x,
            y,
            (right - u64::from(x)) as u32,
            (bottom - u64::from(y)) as u32,
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{FrameId, TileId};

    /// A result whose pixel bytes are a pure function of the absolute pixel position.
    fn result(piece: Piece, tile: Rect) -> TileResult {
        let rect = piece.rect(tile).expect("test pieces fit their tile");
        let mut pixels = Vec::new();
        for y in rect.y..rect.y + rect.h {
            for x in rect.x..rect.x + rect.w {
                for c in 0..BYTES_PER_PIXEL as u32 {
                    pixels.push((x * 7 + y * 13 + c) as u8);
                }
            }
        }
        TileResult {
            frame: FrameId(0),
            tile: TileId(0),
            piece,
            rect,
            pixels,
            costs: Vec::new(),
        }
    }

    const TILE: Rect = Rect {
        x: 3,
        y: 5,
        w: 13,
        h: 7,
    };

    #[test]
    fn pieces_tile_their_tile_at_every_depth() {
        for depth in 0..6u32 {
            let first = 1u64 << depth;
            let rects: Vec<Rect> = (first..first * 2)
                .filter_map(|n| Piece(n).rect(TILE))
                .collect();
            let area: u64 = rects.iter().map(Rect::area).sum();
            assert_eq!(area, TILE.area(), "depth {depth}");
            for (i, a) in rects.iter().enumerate() {
                assert!(
                    rects[i + 1..].iter().all(|b| !a.overlaps(b)),
                    "depth {depth}"
                );
            }
        }
    }

    #[test]
    fn completion_needs_a_full_cover_in_any_mix_of_depths() {
        let spec = TileSpec::whole(TileId(0), TILE, 8.0);
        let mut pieces = Pieces::default();
        // 2 = left half; 6 and 7 = the right half's halves, 7 arriving last.
        for (n, complete_after) in [(2, false), (6, false), (7, true)] {
            assert!(!pieces.complete());
            pieces.insert(PeerId(1), result(Piece(n), TILE));
            assert_eq!(pieces.complete(), complete_after, "after piece {n}");
        }
        let cover = pieces.into_cover();
        let order: Vec<u64> = cover.iter().map(|(_, r)| r.piece.0).collect();
        assert_eq!(order, [2, 6, 7]);
        assert_eq!(spec.piece, Piece::WHOLE);
    }

    #[test]
    fn missing_parts_are_the_largest_uncovered_pieces() {
        let spec = TileSpec::whole(TileId(0), TILE, 8.0);
        let mut pieces = Pieces::default();
        assert_eq!(pieces.missing(&spec), vec![spec]);
        pieces.insert(PeerId(1), result(Piece(6), TILE));
        let missing: Vec<u64> = pieces.missing(&spec).iter().map(|s| s.piece.0).collect();
        assert_eq!(missing, [2, 7]);
        let total: f64 = pieces.missing(&spec).iter().map(|s| s.predicted).sum();
        let expected = 8.0 * (1.0 - Piece(6).rect(TILE).unwrap().area() as f64 / 91.0);
        assert!((total - expected).abs() < 1e-9, "{total} vs {expected}");
    }

    #[test]
    fn a_whole_tile_covers_even_with_parts_already_in() {
        let mut pieces = Pieces::default();
        pieces.insert(PeerId(1), result(Piece(5), TILE));
        pieces.insert(PeerId(2), result(Piece::WHOLE, TILE));
        assert!(pieces.complete());
        let cover = pieces.into_cover();
        assert_eq!(cover.len(), 1);
        assert_eq!(cover[0].0, PeerId(2));
    }

    #[test]
    fn overlapping_results_agree_only_when_their_shared_pixels_match() {
        let whole = result(Piece::WHOLE, TILE);
        for n in 2..32 {
            let part = result(Piece(n), TILE);
            assert!(agree(&whole, &part) && agree(&part, &whole), "piece {n}");
            let mut wrong = part.clone();
            let last = wrong.pixels.len() - 1;
            wrong.pixels[last] ^= 1;
            assert!(!agree(&whole, &wrong), "piece {n}");
        }
        // Disjoint pieces share nothing to disagree on.
        let mut right = result(Piece(3), TILE);
        right.pixels.fill(0);
        assert!(agree(&result(Piece(2), TILE), &right));
    }

    #[test]
    fn overlapping_finds_ancestors_descendants_and_itself_only() {
        let mut pieces = Pieces::default();
        for n in [1, 2, 5, 3] {
            pieces.insert(PeerId(n as u32), result(Piece(n), TILE));
        }
        let found: Vec<u64> = pieces
            .overlapping(Piece(2))
            .map(|(_, r)| r.piece.0)
            .collect();
        assert_eq!(found, [1, 2, 5]);
    }
}
