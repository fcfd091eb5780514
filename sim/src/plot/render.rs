//! The charts of a real render (`tessera render --gantt`): its statistics and every peer's
//! timeline turned into the bars and frame spans of [`gantt_svg`] and [`utilisation_svg`], which
//! the simulator draws for its own runs alike.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use runtime_core::stats::{Accepted, LocalTile, StatsFile};
use runtime_core::wire::PeerId;

use super::{BarKind, FrameSpan, GanttBar, gantt_svg, utilisation_svg};
use crate::Error;

/// Draws at `path` the whole run (frame spans, one utilisation strip per peer, the cluster's
/// busy share), and beside it, in a folder named after the file (`gantt/` for `gantt.svg`), one
/// chart per frame with every piece a bar: the peer's own, taken over (stolen or re-issued), a
/// piece of a cut tile, or a duplicate (a render whose result the owner did not keep, as
/// `accepted` tells). Returns the folder.
pub fn render_charts(
    path: &Path,
    stats: &StatsFile,
    timelines: &[(PeerId, Vec<LocalTile>)],
    accepted: &Accepted,
) -> Result<PathBuf, Error> {
    // Each tile's initial peer by (frame, tile), by number: a resumed render's entries start at
    // its first frame. Looked up once per bar, not searched for.
    let initial: HashMap<(u32, u32), u32> = stats
        .frames
        .iter()
        .flat_map(|f| {
            f.tiles
                .iter()
                .map(move |t| ((f.frame, t.tile), t.initial_peer))
        })
        .collect();
    let mut bars = Vec::new();
    for (peer, tiles) in timelines {
        for t in tiles {
            let taken = initial
                .get(&(t.frame, t.tile))
                .is_some_and(|&first| first != peer.0);
            let kind = if !accepted.contains(&(t.frame, peer.0, t.rect)) {
                BarKind::Duplicate
            } else if t.piece {
                BarKind::Piece
            } else if taken {
                BarKind::Taken
            } else {
                BarKind::Own
            };
            bars.push(GanttBar {
                row: peer.0,
                start: t.start.as_secs_f64(),
                end: t.end.as_secs_f64(),
                frame: t.frame,
                kind,
            });
        }
    }
    let spans: Vec<FrameSpan> = stats
        .frames
        .iter()
        .map(|f| FrameSpan {
            frame: f.frame,
            start: (f.completed_at - f.seconds).max(0.0),
            end: f.completed_at,
        })
        .collect();
    let rows = timelines.iter().map(|(p, _)| p.0 + 1).max().unwrap_or(1);
    // Threads per peer, as the peers reported them.
    let mut slots = vec![1u32; rows as usize];
    for peer in stats.frames.iter().flat_map(|f| &f.peers) {
        if let Some(s) = slots.get_mut(peer.peer as usize) {
            *s = (*s).max(peer.threads);
        }
    }
    let title = format!("{} ({} peers)", stats.scene, stats.peers);
    utilisation_svg(path, &title, &slots, &bars, &spans)?;
    let folder = path.with_extension("");
    std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
    for span in &spans {
        let chart = folder.join(format!("frame-{:04}.svg", span.frame));
        let title = format!("{}: frame {}", stats.scene, span.frame);
        gantt_svg(&chart, &title, rows, &bars, span.frame)?;
    }
    Ok(folder)
}
