//! What a render tells people while it runs: a progress bar with ETA on a terminal, plain log
//! lines otherwise. (The statistics file's schema is `runtime_core::stats`; the frames' files
//! are `runtime::frames`.)

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;

/// Progress over the frames of a render. Clones share one bar: the frame writer ticks it.
#[derive(Clone)]
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    pub fn new(frames: u32) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::new(u64::from(frames));
            bar.set_style(
                ProgressStyle::with_template(
                    "[{bar:40}] frame {pos}/{len}, {elapsed} elapsed, ETA {eta} {msg}",
                )
                .expect("the template is a valid indicatif template")
                .progress_chars("=> "),
            );
            bar
        });
        Self { bar }
    }

    pub fn frame_done(&self, frame: u32, seconds: f64) {
        match &self.bar {
            Some(bar) => {
                bar.set_message(format!("(last {seconds:.2} s)"));
                bar.inc(1);
            }
            None => tracing::info!("frame {frame} done in {seconds:.3} s"),
        }
    }

    /// A line for the log, above the bar on a terminal.
    pub fn line(&self, text: &str) {
        match &self.bar {
            Some(bar) => bar.println(text),
            None => tracing::info!("{text}"),
        }
    }

    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
