//! Pixel rectangles: the tiles of an image, and the one way the PBT cuts them.
//!
//! Every tree in this crate halves a rectangle the same way ([`Rect::halves`]): across its longer
//! side, at the middle, the first half getting the floor. Because the cut is a pure function of the
//! rectangle, a node's children never need to be stored apart from its rectangle, and any two
//! trees over the same image agree on what "the children of R" are.
//!
//! Halving keeps tiles within 2:1 *up to one pixel*: a 3x3 tile can only be cut into 1x3 and 2x3,
//! so no integer rule keeps odd squares strictly within 2:1. The bound that halving does preserve
//! is `long <= 2 * short + 1` ([`Rect::within_aspect`]); the proof is in [`Rect::halves`].

use serde::{Deserialize, Serialize};

/// A rectangle of pixels: columns `x..x + w`, rows `y..y + h`.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Rect {
    /// The leftmost column.
    pub x: u32,
    /// The top row.
    pub y: u32,
    /// The width in pixels.
    pub w: u32,
    /// The height in pixels.
    pub h: u32,
}

impl Rect {
    /// A rectangle from its top-left corner and its size.
    pub fn new(x: u32, y: u32, w: u32, h: u32) -> Self {
        Self { x, y, w, h }
    }

    /// The whole of a `width` x `height` image.
    pub fn image(width: u32, height: u32) -> Self {
        Self::new(0, 0, width, height)
    }

    /// The number of pixels, widened so that a large image cannot overflow it.
    pub fn area(&self) -> u64 {
        u64::from(self.w) * u64::from(self.h)
    }

    /// True when the rectangle holds no pixel (zero width or height).
    pub fn is_empty(&self) -> bool {
        self.w == 0 || self.h == 0
    }

    /// One past the last column, widened so that it cannot overflow.
    pub fn right(&self) -> u64 {
        u64::from(self.x) + u64::from(self.w)
    }

    /// One past the last row, widened so that it cannot overflow.
    pub fn bottom(&self) -> u64 {
        u64::from(self.y) + u64::from(self.h)
    }

    /// The longer of width and height, the side the halving tree cuts across.
    pub fn long_side(&self) -> u32 {
        self.w.max(self.h)
    }

    /// The shorter of width and height, which bounds the tile's aspect ratio.
    pub fn short_side(&self) -> u32 {
        self.w.min(self.h)
    }

    /// Whether the longer side is at most `max_aspect` times the shorter side plus one pixel. The
    /// pixel of slack is what integer halving needs (see the module docs); an empty rectangle is
    /// never within any aspect bound.
    pub fn within_aspect(&self, max_aspect: f64) -> bool {
        !self.is_empty()
            && f64::from(self.long_side()) <= max_aspect * f64::from(self.short_side()) + 1.0
    }

    /// Whether `self` lies inside a `width` x `height` image.
    pub fn inside(&self, width: u32, height: u32) -> bool {
        self.right() <= u64::from(width) && self.bottom() <= u64::from(height)
    }

    /// Whether the two rectangles share at least one pixel.
    pub fn overlaps(&self, other: &Rect) -> bool {
        u64::from(self.x) < other.right()
            && u64::from(other.x) < self.right()
            && u64::from(self.y) < other.bottom()
            && u64::from(other.y) < self.bottom()
    }

    /// The two halves of `self`, cut across the longer side at the middle (a square is cut
    /// across its width): the first half is the left or top one and gets `side / 2` pixels, the
    /// second gets the rest. `None` when `self` is a single pixel (or empty) and cannot be cut.
    ///
    /// Halving preserves `long <= 2 * short + 1`. Say `w >= h` (the other case is symmetric) and
    /// `w <= 2h + 1`; the halves are `floor(w/2) x h` and `ceil(w/2) x h`. If a half's width `v`
    /// is at least `h`, its long side is `v <= ceil((2h + 1) / 2) = h + 1 <= 2h + 1`. Otherwise
    /// its long side is `h <= w <= 2 * floor(w/2) + 1 <= 2v + 1`.
    pub fn halves(&self) -> Option<(Rect, Rect)> {
        if self.area() < 2 {
            return None;
        }
        Some(if self.w >= self.h {
            let first = self.w / 2;
            (
                Rect::new(self.x, self.y, first, self.h),
                Rect::new(self.x + first, self.y, self.w - first, self.h),
            )
        } else {
            let first = self.h / 2;
            (
                Rect::new(self.x, self.y, self.w, first),
                Rect::new(self.x, self.y + first, self.w, self.h - first),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_cut_the_longer_side_floor_first() {
        assert_eq!(
            Rect::new(4, 6, 10, 4).halves(),
            Some((Rect::new(4, 6, 5, 4), Rect::new(9, 6, 5, 4)))
        );
        assert_eq!(
            Rect::new(0, 0, 3, 7).halves(),
            Some((Rect::new(0, 0, 3, 3), Rect::new(0, 3, 3, 4)))
        );
        // A square is cut across its width.
        assert_eq!(
            Rect::new(0, 0, 3, 3).halves(),
            Some((Rect::new(0, 0, 1, 3), Rect::new(1, 0, 2, 3)))
        );
        assert_eq!(
            Rect::new(0, 0, 1, 2).halves(),
            Some((Rect::new(0, 0, 1, 1), Rect::new(0, 1, 1, 1)))
        );
        assert_eq!(Rect::new(5, 5, 1, 1).halves(), None);
        assert_eq!(Rect::new(5, 5, 0, 9).halves(), None);
    }

    #[test]
    fn halving_keeps_the_aspect_bound_for_every_small_rectangle() {
        // Exhaustive over every rectangle up to 200 pixels a side that satisfies the bound.
        for w in 1..=200u32 {
            for h in 1..=200u32 {
                let rect = Rect::new(0, 0, w, h);
                if !rect.within_aspect(2.0) {
                    continue;
                }
                if let Some((a, b)) = rect.halves() {
                    assert!(a.within_aspect(2.0) && b.within_aspect(2.0), "{rect:?}");
                    assert_eq!(a.area() + b.area(), rect.area());
                }
            }
        }
    }

    #[test]
    fn aspect_bound_allows_exactly_one_pixel_of_slack() {
        assert!(Rect::new(0, 0, 1, 3).within_aspect(2.0));
        assert!(!Rect::new(0, 0, 1, 4).within_aspect(2.0));
        assert!(Rect::new(0, 0, 9, 4).within_aspect(2.0));
        assert!(!Rect::new(0, 0, 10, 4).within_aspect(2.0));
        assert!(!Rect::new(0, 0, 0, 0).within_aspect(2.0));
    }

    #[test]
    fn overlap_is_strict_at_edges() {
        let a = Rect::new(0, 0, 4, 4);
        assert!(!a.overlaps(&Rect::new(4, 0, 4, 4)));
        assert!(!a.overlaps(&Rect::new(0, 4, 4, 4)));
        assert!(a.overlaps(&Rect::new(3, 3, 4, 4)));
        assert!(a.inside(4, 4) && !a.inside(3, 4));
    }
}
