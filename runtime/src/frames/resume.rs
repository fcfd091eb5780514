//! `--resume`: which frames an earlier render of the same scene files and settings has already
//! written, so that `render` and `serve` go on from the first one missing.
//!
//! Every frame's EXR carries the render hash (`crate::node::bundle::render_hash`: the scene
//! files and the render parameters) as the header attribute [`ATTRIBUTE`], whether or not
//! `--resume` was given, so any render can be resumed. A frame counts as done only if its EXR
//! exists, reads back whole and carries the hash of this render. Frames are written to a
//! temporary name and renamed (`tracer::output`), the EXR after the PNG preview, so an owner
//! killed at any moment leaves either a whole frame or none under the frame's name.
//!
//! A frame of other settings counts as missing like an absent one, so `--resume` with changed
//! settings (another `--spp`, an edited scene file) re-renders from frame 0 rather than refusing:
//! the folder then holds one render again. The render goes on from the first frame missing even
//! if later ones are present, because the director deals a contiguous run of frames.

use std::path::{Path, PathBuf};

/// The EXR header attribute holding a frame's render hash.
pub const ATTRIBUTE: &str = "tessera.render";

/// The path of frame `frame`'s image with extension `ext` in `out`.
pub fn frame_path(out: &Path, frame: u32, ext: &str) -> PathBuf {
    out.join(format!("frame-{frame:04}.{ext}"))
}

/// Removes what a killed render left half-written in `out`: the temporary files of its frames'
/// images (`frame-NNNN.exr.partial`, `tiles-NNNN.png.partial`, ...), which no reader takes for a
/// frame but which would otherwise stay forever. Returns how many it removed.
pub fn remove_leftovers(out: &Path) -> std::io::Result<usize> {
    let Ok(entries) = std::fs::read_dir(out) else {
        // No folder yet: nothing was left.
        return Ok(0);
    };
    let mut removed = 0;
    for entry in entries {
        let entry = entry?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let ours = name.starts_with("frame-")
            || name.starts_with("tiles-")
            || name.starts_with(crate::node::checkpoint::FILE);
        if ours && name.ends_with(tracer::output::TEMPORARY_SUFFIX) && entry.path().is_file() {
            std::fs::remove_file(entry.path())?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Why the first frame not done is not done.
#[derive(Debug, PartialEq)]
pub enum Missing {
    /// Every frame is done.
    None,
    /// No EXR file.
    Absent,
    /// The EXR does not read back: cut short or corrupt.
    Unreadable(String),
    /// The EXR is whole, but of another render (or of a version that recorded no hash).
    OtherRender(Option<String>),
}

/// The first frame of `0..frames` not done in `out` for render `hash`, and why it is not
/// (`frames` and [`Missing::None`] when all are).
pub fn first_missing(out: &Path, frames: u32, hash: &str) -> (u32, Missing) {
    for frame in 0..frames {
        let path = frame_path(out, frame, "exr");
        if !path.is_file() {
            return (frame, Missing::Absent);
        }
        match tracer::output::read_exr_with_text(&path, ATTRIBUTE) {
            Err(e) => return (frame, Missing::Unreadable(e.to_string())),
            Ok((_, found)) if found.as_deref() != Some(hash) => {
                return (frame, Missing::OtherRender(found));
            }
            Ok(_) => {}
        }
    }
    (frames, Missing::None)
}

/// The line a resumed render logs: what is done, and why it goes on where it does.
pub fn describe(first: u32, frames: u32, why: &Missing, hash: &str) -> String {
    let done = match first {
        0 => "no frame is done".to_owned(),
        1 => "frame 0 is done".to_owned(),
        _ => format!("frames 0-{} are done", first - 1),
    };
    let name = |frame: u32| format!("frame-{frame:04}.exr");
    let reason = match why {
        Missing::None => {
            return format!("--resume: all {frames} frames are done; nothing to render");
        }
        Missing::Absent => format!("{} is missing", name(first)),
        Missing::Unreadable(error) => format!("{} does not read back ({error})", name(first)),
        Missing::OtherRender(found) => format!(
            "{} is of other scene files or settings (render {}, now {})",
            name(first),
            found
                .as_deref()
                .map_or("unrecorded", |h| &h[..h.len().min(16)]),
            &hash[..16]
        ),
    };
    format!(
        "--resume: {done}; {reason}: rendering frames {first}-{}",
        frames - 1
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(out: &Path, frame: u32, hash: &str) {
        let pixels = vec![[frame as f32, 0.5, 1.0]; 6];
        let text: &[(&str, &str)] = &[(ATTRIBUTE, hash)];
        tracer::output::write_exr_with_text(&frame_path(out, frame, "exr"), 3, 2, &pixels, text)
            .unwrap();
    }

    #[test]
    fn the_first_frame_absent_cut_short_or_of_another_render_is_where_a_render_resumes() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        let hash = "ab".repeat(32);
        assert_eq!(first_missing(out, 4, &hash), (0, Missing::Absent));
        for frame in 0..4 {
            write(out, frame, &hash);
        }
        assert_eq!(first_missing(out, 4, &hash), (4, Missing::None));
        // Zero frames are always all done.
        assert_eq!(first_missing(out, 0, &hash), (0, Missing::None));

        // A frame of another render (other settings) is not done, nor is one without a hash.
        write(out, 2, &"cd".repeat(32));
        let (first, why) = first_missing(out, 4, &hash);
        assert_eq!(
            (first, &why),
            (2, &Missing::OtherRender(Some("cd".repeat(32))))
        );
        assert!(describe(first, 4, &why, &hash).contains("rendering frames 2-3"));
        tracer::output::write_exr(&frame_path(out, 2, "exr"), 3, 2, &[[0.0; 3]; 6]).unwrap();
        assert_eq!(
            first_missing(out, 4, &hash),
            (2, Missing::OtherRender(None))
        );

        // A file cut short under the frame's name is not done either.
        write(out, 2, &hash);
        let path = frame_path(out, 1, "exr");
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        let (first, why) = first_missing(out, 4, &hash);
        assert_eq!(first, 1);
        assert!(matches!(why, Missing::Unreadable(_)), "{why:?}");
        assert!(describe(first, 4, &why, &hash).starts_with("--resume: frame 0 is done;"));
    }

    #[test]
    fn only_the_temporary_files_of_frames_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        assert_eq!(remove_leftovers(&out.join("absent")).unwrap(), 0);
        let names = [
            "frame-0003.exr.partial",
            "tiles-0002.png.partial",
            "frame-0002.exr",
            "notes.partial",
        ];
        for name in names {
            std::fs::write(out.join(name), b"x").unwrap();
        }
        assert_eq!(remove_leftovers(out).unwrap(), 2);
        let mut left: Vec<String> = std::fs::read_dir(out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["frame-0002.exr", "notes.partial"]);
    }
}
