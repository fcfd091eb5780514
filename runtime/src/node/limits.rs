//! What a render's image and tile count must satisfy before anything is rendered: every error
//! here would otherwise surface later, and worse, as a peer failure or a frame that never
//! completes. Checked by the owner's caller ([`Options::check_frame`]).

use super::Options;
use runtime_core::wire::BYTES_PER_PIXEL;

/// The most rendering threads one process may be asked for. Rendering wants a thread per core,
/// and no machine has thousands; a number past this is a slip (`--threads 100000` spent a minute
/// spawning threads before it failed, naming no flag), so it is refused before anything starts.
pub const MAX_THREADS: usize = 4096;

/// The silences the owner and peers accept as `--peer-timeout`, in seconds: heartbeats go every
/// fifth of it, so below a tenth of a second they would flood the links; above a million
/// seconds (eleven days) a dead peer would never be noticed within a render, and QUIC's idle
/// timer has a range of its own.
pub const PEER_TIMEOUT_SECONDS: std::ops::RangeInclusive<f64> = 0.1..=1e6;

/// Why an image or a tile count cannot work.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LimitError {
    /// The owner cannot hold a frame.
    #[error("a frame needs about {needed_mib} MiB, and this machine has {available_mib} MiB free")]
    Memory {
        /// Memory a frame needs, in MiB.
        needed_mib: u64,
        /// Memory free on this machine, in MiB.
        available_mib: u64,
    },
    /// More tiles than pixels.
    #[error("the {width}x{height} image has only {pixels} pixels")]
    MorePixels {
        /// The tile count asked for.
        tiles: u64,
        /// The image's width in pixels.
        width: u64,
        /// The image's height in pixels.
        height: u64,
        /// The image's pixels.
        pixels: u64,
    },
    /// More tiles than one message can deal (a peer's share travels in one).
    #[error("at most {most} tiles (a peer's share travels in one message)")]
    PerMessage {
        /// The tile count asked for.
        tiles: u64,
        /// The most one message can carry.
        most: u64,
    },
    /// A first frame's tile whose result would not fit in one message.
    #[error(
        "tiles of about {pixels:.0} pixels are too large to send (a result may be at most \
         {most_mib} MiB); use more tiles"
    )]
    TooLarge {
        /// The tile count asked for.
        tiles: u64,
        /// Pixels of the largest tile of the first frame.
        pixels: f64,
        /// The largest result a message may carry, in MiB.
        most_mib: usize,
    },
}

impl LimitError {
    /// The tile count refused, or `None` where the image itself is too large.
    pub fn tiles(&self) -> Option<u64> {
        match self {
            LimitError::Memory { .. } => None,
            LimitError::MorePixels { tiles, .. }
            | LimitError::PerMessage { tiles, .. }
            | LimitError::TooLarge { tiles, .. } => Some(*tiles),
        }
    }
}

impl Options {
    /// Refuses a `width` x `height` image cut into `tiles` tiles (default: the balancer's leaf
    /// count, at most one a pixel) that cannot work with these options: more tiles than pixels
    /// or than one message can deal, first-frame tiles whose results cannot fit in one message,
    /// and a frame larger than `available` bytes of memory (where known). Returns the tile
    /// count to cut frames into.
    pub fn check_frame(
        &self,
        width: u32,
        height: u32,
        tiles: Option<usize>,
        available: Option<u64>,
    ) -> Result<usize, LimitError> {
        let (width, height) = (u64::from(width), u64::from(height));
        // The owner holds the frame's film (12 bytes a pixel) and every result until the frame
        // is assembled (as much again), and writes an EXR and a PNG from the film.
        let needed = width * height * (12 + 12 + 12 + 4);
        if let Some(available) = available
            && needed > available
        {
            return Err(LimitError::Memory {
                needed_mib: needed >> 20,
                available_mib: available >> 20,
            });
        }
        // Tiles smaller than a cost block work (blocks then carry partial work), so the floor
        // is a pixel per tile.
        let pixels = width * height;
        let tiles = match tiles {
            Some(tiles) => tiles as u64,
            None => (balancer::Config::default().leaves as u64).min(pixels),
        };
        if tiles > pixels {
            return Err(LimitError::MorePixels {
                tiles,
                width,
                height,
                pixels,
            });
        }
        let most = self.limits.max_tiles_per_message as u64;
        if tiles > most {
            return Err(LimitError::PerMessage { tiles, most });
        }
        // The first frame's tiles are cut by area, so its largest is about the image over the
        // tile count (rounded up each way); its result must fit in one message.
        let side = (tiles as f64).sqrt().max(1.0);
        let largest = (width as f64 / side).ceil() * (height as f64 / side).ceil();
        if largest * BYTES_PER_PIXEL as f64 > self.limits.max_message_bytes as f64 / 2.0 {
            return Err(LimitError::TooLarge {
                tiles,
                pixels: largest,
                most_mib: self.limits.max_message_bytes >> 21,
            });
        }
        Ok(tiles as usize)
    }
}

/// Free memory as the kernel estimates it (`MemAvailable`), where `/proc/meminfo` says.
pub fn available_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_limit_is_refused_with_the_tile_count_it_refused() {
        let options = Options::default();
        assert_eq!(options.check_frame(16, 16, None, None), Ok(256));
        assert_eq!(options.check_frame(4, 4, None, None), Ok(16));
        let more = options.check_frame(4, 4, Some(17), None).unwrap_err();
        assert_eq!(
            (more.tiles(), more.to_string()),
            (Some(17), "the 4x4 image has only 16 pixels".into())
        );
        let per_message = options
            .check_frame(4096, 4096, Some(100_000), None)
            .unwrap_err();
        assert!(matches!(
            per_message,
            LimitError::PerMessage {
                tiles: 100_000,
                most: 65536
            }
        ));
        let large = options.check_frame(8192, 8192, Some(2), None).unwrap_err();
        assert!(
            matches!(large, LimitError::TooLarge { tiles: 2, .. }),
            "{large}"
        );
        let memory = options
            .check_frame(1024, 1024, None, Some(1 << 20))
            .unwrap_err();
        assert_eq!(
            memory,
            LimitError::Memory {
                needed_mib: 40,
                available_mib: 1
            }
        );
        assert_eq!(memory.tiles(), None);
    }
}
