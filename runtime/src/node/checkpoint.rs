//! Checkpoints of the frame in progress: what the owner has of it, written every so often, so
//! that a render stopped in the middle of a long frame resumes with the tiles it had
//! (`--resume`), not from the frame's start.
//!
//! A checkpoint holds the frame's tiles as they were dealt and every result the owner had
//! accepted of it (pixels and measured costs, exactly as they arrived), with the render hash
//! that names the scene files and settings. The results fit only those tiles, so a resumed
//! render cuts the frame into them again (`Director::resume_with`) and hands the results to its
//! ledger (`Core::resume_frame`), which gives out only the tiles they do not cover. Pixels do
//! not depend on who rendered them or when, so the frame is bit for bit the one an
//! uninterrupted render makes.
//!
//! The file is written to a temporary name, flushed to disk and renamed over the last one, so a
//! reader finds a whole checkpoint or the previous whole one, never a torn one.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use runtime_core::wire::{FrameId, TileResult};
use serde::{Deserialize, Serialize};

/// The file name of a render's checkpoint in its output folder.
pub const FILE: &str = "checkpoint.bin";

/// What the file starts with: a format mark and version, so that another file under the name,
/// or a checkpoint of another version, is recognised and not misread.
const MAGIC: &[u8; 8] = b"tsrckpt1";

/// How the owner checkpoints a render.
#[derive(Clone, Debug)]
pub struct Checkpointing {
    /// Where the checkpoint goes (usually `OUT/checkpoint.bin`).
    pub path: PathBuf,
    /// How often the frame in progress is written, at most (only when results came in since);
    /// `None` writes none (a kept checkpoint is still resumed from).
    pub every: Option<Duration>,
    /// The render hash a checkpoint is written with and must carry to be resumed from.
    pub render_hash: String,
    /// A checkpoint of the render's first frame (`Job::first`) to resume from.
    pub resume: Option<Checkpoint>,
}

impl Checkpointing {
    /// How the owner checkpoints a render into the folder `out` every `every` (`None`: none is
    /// written), with, if `resume` asks for it, the checkpoint there of frame `first` of this
    /// render (`render_hash`) to go on from. A checkpoint of another frame or render, or one
    /// that does not read, is left to be overwritten and said so; the frame starts afresh.
    /// `None` when there is nothing to write or resume.
    pub fn for_render(
        out: &Path,
        every: Option<Duration>,
        render_hash: &str,
        first: u32,
        resume: bool,
    ) -> Option<Checkpointing> {
        let path = out.join(FILE);
        let kept = match resume {
            true => match Checkpoint::read(&path) {
                Ok(Some(kept)) if kept.render_hash == render_hash && kept.frame.0 == first => {
                    Some(kept)
                }
                Ok(Some(kept)) => {
                    tracing::info!(
                        "--resume: {} is of {} or of other settings; frame {first} starts afresh",
                        path.display(),
                        kept.frame
                    );
                    None
                }
                Ok(None) => None,
                Err(error) => {
                    tracing::warn!("--resume: {error}; frame {first} starts afresh");
                    None
                }
            },
            false => None,
        };
        if every.is_none() && kept.is_none() {
            return None;
        }
        Some(Checkpointing {
            path,
            // With checkpoints off, a kept one is still resumed from; none is written after it.
            every,
            render_hash: render_hash.to_owned(),
            resume: kept,
        })
    }
}

/// The frame in progress, as far as the owner had it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The render it belongs to (`bundle::render_hash`); a checkpoint of another render is not
    /// resumed from.
    pub render_hash: String,
    /// The frame in progress.
    pub frame: FrameId,
    /// The frame's tiles as dealt, in order.
    pub tiles: Vec<balancer::Tile>,
    /// Every result accepted of the frame, in tile order.
    pub results: Vec<TileResult>,
}

/// Why a checkpoint file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// The checkpoint file could not be read.
    #[error("reading {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The file lacks a checkpoint's header, or has another version's.
    #[error("{path} is not a tessera checkpoint of this version")]
    NotACheckpoint {
        /// The file.
        path: PathBuf,
    },
    /// The file has a checkpoint's header but its body does not decode.
    #[error("{path} does not decode: {source}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// What postcard said.
        source: postcard::Error,
    },
}

impl Checkpoint {
    /// How many of the frame's tiles its results cover whole (pieces of a tile do not count).
    pub fn whole_tiles(&self) -> usize {
        let mut tiles: Vec<_> = self
            .results
            .iter()
            .filter(|result| result.piece == runtime_core::wire::Piece::WHOLE)
            .map(|result| result.tile)
            .collect();
        tiles.dedup();
        tiles.len()
    }

    /// Writes the checkpoint to `path` atomically: a temporary file beside it, flushed to disk,
    /// then renamed over `path`.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let mut bytes = MAGIC.to_vec();
        bytes.extend(
            postcard::to_stdvec(self)
                .expect("invariant: a checkpoint's types serialise to a vector"),
        );
        let temporary = temporary_path(path);
        let mut file = std::fs::File::create(&temporary)?;
        file.write_all(&bytes)?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&temporary, path)
    }

    /// Reads the checkpoint at `path`: `None` if there is none.
    pub fn read(path: &Path) -> Result<Option<Self>, CheckpointError> {
        let bytes = match std::fs::read(path) {
            Ok(bytes) => bytes,
            Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(CheckpointError::Read {
                    path: path.to_owned(),
                    source,
                });
            }
        };
        let Some(body) = bytes.strip_prefix(MAGIC.as_slice()) else {
            return Err(CheckpointError::NotACheckpoint {
                path: path.to_owned(),
            });
        };
        postcard::from_bytes(body)
            .map(Some)
            .map_err(|source| CheckpointError::Decode {
                path: path.to_owned(),
                source,
            })
    }
}

/// Removes the checkpoint at `path` and any temporary one a write left; absent files are fine.
pub fn remove(path: &Path) -> std::io::Result<()> {
    for file in [path.to_owned(), temporary_path(path)] {
        match std::fs::remove_file(&file) {
            Err(error) if error.kind() != std::io::ErrorKind::NotFound => return Err(error),
            _ => {}
        }
    }
    Ok(())
}

fn temporary_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".partial");
    PathBuf::from(name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use balancer::Rect;
    use runtime_core::wire::{Piece, TileId};

    fn checkpoint() -> Checkpoint {
        let result = |tile: u32, piece: Piece| TileResult {
            frame: FrameId(3),
            tile: TileId(tile),
            piece,
            rect: Rect::new(tile * 8, 0, 8, 8),
            pixels: vec![tile as u8; (8 * 8 * runtime_core::wire::BYTES_PER_PIXEL) as usize],
            costs: vec![1, 2, 3],
        };
        Checkpoint {
            render_hash: "ab".repeat(32),
            frame: FrameId(3),
            tiles: (0..4)
                .map(|i| balancer::Tile {
                    rect: Rect::new(i * 8, 0, 8, 8),
                    predicted: f64::from(i),
                })
                .collect(),
            results: vec![
                result(0, Piece::WHOLE),
                result(2, Piece(2)),
                result(3, Piece::WHOLE),
            ],
        }
    }

    #[test]
    fn a_checkpoint_reads_back_as_written_and_replaces_the_last_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        assert!(Checkpoint::read(&path).unwrap().is_none());
        let first = checkpoint();
        first.write(&path).unwrap();
        assert_eq!(Checkpoint::read(&path).unwrap(), Some(first.clone()));
        assert_eq!(first.whole_tiles(), 2);
        let mut second = first;
        second.results.truncate(1);
        second.write(&path).unwrap();
        assert_eq!(Checkpoint::read(&path).unwrap(), Some(second));
        assert!(!temporary_path(&path).exists());
        remove(&path).unwrap();
        remove(&path).unwrap();
        assert!(!path.exists());
    }

    #[test]
    fn other_files_and_torn_checkpoints_are_refused_not_misread() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        std::fs::write(&path, b"not a checkpoint at all").unwrap();
        assert!(matches!(
            Checkpoint::read(&path),
            Err(CheckpointError::NotACheckpoint { .. })
        ));
        checkpoint().write(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        for cut in [MAGIC.len() + 1, bytes.len() / 2, bytes.len() - 1] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            assert!(
                matches!(Checkpoint::read(&path), Err(CheckpointError::Decode { .. })),
                "cut at {cut}"
            );
        }
    }
}
