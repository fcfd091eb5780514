//! Writes finished frames' files (PNG preview, tile map, EXR) on a thread of their own, in
//! frame order.
//!
//! The owner's loop also feeds its own rendering slots, and a frame's files take it 20 to 40 ms
//! on the shipped 256x256 animation: written in the loop, the owner's thread idled that long at
//! every hand-over (peer 0's row of `gantt/frame-NNNN.svg`). Here the loop hands the film over
//! and goes on. A write that fails stops the render at the next frame handed over, or at the
//! end, with the file's error; nothing is written after it, and `--resume` finds the frames
//! before it whole (each file is written whole or not at all, the EXR last).

use std::path::PathBuf;
use std::sync::mpsc;
use std::thread::JoinHandle;

use anyhow::Context;
use tracer::Film;

use crate::report::{self, Progress};
use crate::resume;

/// What every frame's files share.
#[derive(Clone)]
pub struct Settings {
    pub out: PathBuf,
    pub exposure: f32,
    pub tile_map: bool,
    /// The render's identity, written into every EXR's header (`resume::ATTRIBUTE`).
    pub render_hash: String,
}

/// One frame to write: its film, and its pieces' rectangles `[x, y, w, h]` and measured costs
/// (for the tile map); `seconds` is what the progress line reports once it is written.
pub struct Frame {
    pub frame: u32,
    pub seconds: f64,
    pub film: Film,
    pub costs: Vec<([u32; 4], u64)>,
}

/// The writing thread and the way to it.
pub struct Writer {
    frames: Option<mpsc::Sender<Frame>>,
    thread: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Writer {
    /// Starts the thread; it reports each frame to `progress` once its files are written, so
    /// that "frame N done" means on disk.
    pub fn start(settings: Settings, progress: Progress) -> anyhow::Result<Writer> {
        let (frames, inbox) = mpsc::channel::<Frame>();
        let thread = std::thread::Builder::new()
            .name("frame-files".into())
            .spawn(move || {
                // Stops at the first error: the sender then finds the channel closed.
                inbox.iter().try_for_each(|frame| {
                    write(&settings, &frame)?;
                    progress.frame_done(frame.frame, frame.seconds);
                    Ok(())
                })
            })
            .context("starting the thread that writes frames")?;
        Ok(Writer {
            frames: Some(frames),
            thread: Some(thread),
        })
    }

    /// Queues a frame; an error if an earlier frame's files could not be written.
    pub fn send(&mut self, frame: Frame) -> anyhow::Result<()> {
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
    pub fn finish(&mut self) -> anyhow::Result<()> {
        drop(self.frames.take());
        match self.thread.take() {
            None => Ok(()),
            Some(thread) => match thread.join() {
                Ok(result) => result,
                Err(_) => anyhow::bail!("the thread writing frames panicked"),
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

fn write(settings: &Settings, frame: &Frame) -> anyhow::Result<()> {
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
        report::write_tile_map(&path, film.width, film.height, &preview, &frame.costs)?;
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
            costs: vec![([0, 0, 4, 2], 7)],
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
            Writer::start(settings(dir.path().to_path_buf()), Progress::new(5)).unwrap();
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
        let mut writer = Writer::start(settings(missing.clone()), Progress::new(1)).unwrap();
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
        let text = format!("{error:#}");
        assert!(text.contains("absent"), "{text}");
        assert!(!missing.exists(), "nothing was written");
    }
}
