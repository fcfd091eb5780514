//! The owner's output folder: each finished frame's files (PNG preview, tile map, EXR), written
//! in frame order on a thread of their own, and ([`resume`]) which frames an earlier render of
//! the same settings left done.
//!
//! The owner's loop also feeds its own rendering slots, and a frame's files take it 20 to 40 ms
//! on the shipped 256x256 animation: written in the loop, the owner's thread idled that long at
//! every hand-over (peer 0's row of `gantt/frame-NNNN.svg`). Here the loop hands the film over
//! and goes on. A write that fails stops the render at the next frame handed over, or at the
//! end, with the file's error; nothing is written after it, and `--resume` finds the frames
//! before it whole (each file is written whole or not at all, the EXR last).

pub mod resume;

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::thread::JoinHandle;

use tracer::Film;
use tracer::output::OutputError;

/// Why a frame's files could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FrameFileError {
    /// A frame's PNG preview, its tile map or its EXR could not be written.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The film's pixels do not fill its width and height, a bug in whoever built it.
    #[error("the preview has the wrong size")]
    PreviewSize,
    /// The system refused to start the writing thread.
    #[error("starting the thread that writes frames: {0}")]
    Thread(std::io::Error),
    /// The writing thread panicked, so whether the last frames are on disk is unknown.
    #[error("the thread writing frames panicked")]
    Panicked,
}

/// What every frame's files share.
#[derive(Clone)]
pub struct Settings {
    /// The folder the frames are written into; it must exist.
    pub out: PathBuf,
    /// The factor linear pixels are multiplied by before the PNG's tone mapping.
    pub exposure: f32,
    /// Whether each frame's tile map (`tiles-NNNN.png`) is drawn too.
    pub tile_map: bool,
    /// The render's identity, written into every EXR's header (`resume::ATTRIBUTE`).
    pub render_hash: String,
}

/// One frame to write: its film, and its pieces' rectangles and measured costs (for the tile
/// map); `seconds` is what is reported once it is written.
pub struct Frame {
    /// The frame's number, which names its files.
    pub frame: u32,
    /// The frame's render time, handed to [`Written`] once its files are on disk.
    pub seconds: f64,
    /// The assembled pixels.
    pub film: Film,
    /// Each piece's rectangle and measured cost, which the tile map draws.
    pub costs: Vec<(balancer::Rect, u64)>,
}

/// Told of each frame once its files are on disk: its number and its `seconds`.
pub type Written = Box<dyn FnMut(u32, f64) + Send>;

/// The writing thread and the way to it.
pub struct Writer {
    frames: Option<mpsc::Sender<Frame>>,
    thread: Option<JoinHandle<Result<(), FrameFileError>>>,
}

impl Writer {
    /// Starts the thread; it calls `written` for each frame once its files are written, so
    /// that "frame N done" means on disk.
    pub fn start(settings: Settings, mut written: Written) -> Result<Writer, FrameFileError> {
        let (frames, inbox) = mpsc::channel::<Frame>();
        let thread = std::thread::Builder::new()
            .name("frame-files".into())
            .spawn(move || {
                // Stops at the first error: the sender then finds the channel closed.
                inbox.iter().try_for_each(|frame| {
                    write(&settings, &frame)?;
                    written(frame.frame, frame.seconds);
                    Ok(())
                })
            })
            .map_err(FrameFileError::Thread)?;
        Ok(Writer {
            frames: Some(frames),
            thread: Some(thread),
        })
    }

    /// Queues a frame; an error if an earlier frame's files could not be written.
    pub fn send(&mut self, frame: Frame) -> Result<(), FrameFileError> {
        let sent = self
            .frames
            .as_ref()
            .is_some_and(|frames| frames.send(frame).is_ok());
        match sent {
            true => Ok(()),
            // The thread has stopped: its error says why.
            _ => self.finish(),
        }
    }

    /// Waits until every queued frame is written; the first write's error if one failed.
    pub fn finish(&mut self) -> Result<(), FrameFileError> {
        drop(self.frames.take());
        match self.thread.take() {
            None => Ok(()),
            Some(thread) => match thread.join() {
                Ok(result) => result,
                Err(_) => Err(FrameFileError::Panicked),
            },
        }
    }
}

impl Drop for Writer {
    /// A render that stops on another error still writes the frames handed over before it,
    /// for `--resume` to find.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

fn write(settings: &Settings, frame: &Frame) -> Result<(), FrameFileError> {
    let film = &frame.film;
    let name = |ext: &str| resume::frame_path(&settings.out, frame.frame, ext);
    tracer::output::write_png(
        &name("png"),
        film.width,
        film.height,
        &film.pixels,
        settings.exposure,
    )?;
    if settings.tile_map {
        let preview = tracer::output::tone_map(&film.pixels, settings.exposure);
        let path = settings.out.join(format!("tiles-{:04}.png", frame.frame));
        let map = draw_tile_map(film.width, film.height, &preview, &frame.costs)?;
        write_tile_map(&path, &map)?;
    }
    // The EXR goes last: `--resume` takes a frame whose EXR is there for done, so the previews
    // must be there before it.
    tracer::output::write_exr_with_text(
        &name("exr"),
        film.width,
        film.height,
        &film.pixels,
        &[(resume::ATTRIBUTE, &settings.render_hash)],
    )?;
    Ok(())
}

/// Draws the tile map of a frame: the tone-mapped image dimmed, each tile tinted from blue
/// (cheap) to red (expensive) by its measured cost relative to the frame's most expensive tile,
/// and tile borders in white.
fn draw_tile_map(
    width: u32,
    height: u32,
    preview: &[u8],
    tiles: &[(balancer::Rect, u64)],
) -> Result<image::RgbImage, FrameFileError> {
    let mut image = image::RgbImage::from_raw(width, height, preview.to_vec())
        .ok_or(FrameFileError::PreviewSize)?;
    let max = tiles.iter().map(|t| t.1).max().unwrap_or(1).max(1) as f32;
    for &(rect, measured) in tiles {
        let (x0, y0, w, h) = (rect.x, rect.y, rect.w, rect.h);
        let heat = measured as f32 / max;
        let tint = [255.0 * heat, 64.0, 255.0 * (1.0 - heat)];
        for y in y0..y0 + h {
            for x in x0..x0 + w {
                let border = x == x0 || y == y0 || x + 1 == x0 + w || y + 1 == y0 + h;
                let pixel = image.get_pixel_mut(x, y);
                pixel.0 = if border {
                    [255, 255, 255]
                } else {
                    std::array::from_fn(|c| (0.35 * f32::from(pixel.0[c]) + 0.45 * tint[c]) as u8)
                };
            }
        }
    }
    Ok(image)
}

/// Writes a drawn tile map as a PNG through the tracer's image writer, so that, like every
/// other image of a frame, it is written to a temporary name and renamed: a reader, or an owner
/// killed midway, never leaves half a tile map under its real name.
fn write_tile_map(path: &Path, map: &image::RgbImage) -> Result<(), FrameFileError> {
    tracer::output::write_png_rgb8(path, map)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(frame: u32) -> Frame {
        let mut film = Film::new(4, 2);
        film.pixels.iter_mut().for_each(|p| *p = [0.5, 0.25, 1.0]);
        Frame {
            frame,
            seconds: 0.0,
            film,
            costs: vec![(balancer::Rect::new(0, 0, 4, 2), 7)],
        }
    }

    fn settings(out: PathBuf) -> Settings {
        Settings {
            out,
            exposure: 1.0,
            tile_map: true,
            render_hash: "h".into(),
        }
    }

    #[test]
    fn every_frame_sent_is_written_by_finish() {
        let dir = tempfile::tempdir().unwrap();
        let mut writer =
            Writer::start(settings(dir.path().to_path_buf()), Box::new(|_, _| ())).unwrap();
        for f in 0..5 {
            writer.send(frame(f)).unwrap();
        }
        writer.finish().unwrap();
        for f in 0..5 {
            for name in [
                format!("frame-{f:04}.png"),
                format!("frame-{f:04}.exr"),
                format!("tiles-{f:04}.png"),
            ] {
                assert!(dir.path().join(&name).is_file(), "{name} missing");
            }
        }
        // Finishing twice (as dropping does after finish) is harmless.
        writer.finish().unwrap();
    }

    #[test]
    fn a_failed_write_stops_the_next_send_or_the_finish_with_its_error() {
        let dir = tempfile::tempdir().unwrap();
        // A folder that does not exist: the first PNG cannot be written.
        let missing = dir.path().join("absent");
        let mut writer = Writer::start(settings(missing.clone()), Box::new(|_, _| ())).unwrap();
        let first = writer.send(frame(0));
        // The thread may or may not have failed yet; if not, finish reports it.
        let error = match first {
            Err(error) => error,
            Ok(()) => {
                let later = (1..1000).find_map(|f| writer.send(frame(f)).err());
                match later {
                    Some(error) => error,
                    None => writer.finish().unwrap_err(),
                }
            }
        };
        let text = error.to_string();
        assert!(text.contains("absent"), "{text}");
        assert!(!missing.exists(), "nothing was written");
    }

    #[test]
    fn the_tile_map_is_written_as_drawn_under_a_temporary_name_then_renamed() {
        let dir = tempfile::tempdir().unwrap();
        let film = frame(0).film;
        let preview = tracer::output::tone_map(&film.pixels, 1.0);
        let costs = [
            (balancer::Rect::new(0, 0, 3, 2), 7),
            (balancer::Rect::new(3, 0, 1, 2), 2),
        ];
        let map = draw_tile_map(4, 2, &preview, &costs).unwrap();
        let path = dir.path().join("tiles-0000.png");
        write_tile_map(&path, &map).unwrap();
        let read = image::open(&path).unwrap().into_rgb8();
        assert_eq!(read.as_raw(), map.as_raw());
        let partial = dir.path().join(format!(
            "tiles-0000.png{}",
            tracer::output::TEMPORARY_SUFFIX
        ));
        assert!(!partial.exists(), "the temporary file was renamed");

        // Where the temporary name cannot be written, the real name is left untouched: the
        // map goes nowhere else first.
        let blocked = dir.path().join("tiles-0001.png");
        let temporary = format!("tiles-0001.png{}", tracer::output::TEMPORARY_SUFFIX);
        std::fs::create_dir(dir.path().join(temporary)).unwrap();
        assert!(write_tile_map(&blocked, &map).is_err());
        assert!(!blocked.exists(), "nothing under the real name");
    }
}
