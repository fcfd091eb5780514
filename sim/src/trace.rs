//! Cost traces: what each frame of a render cost, block by block, so that the simulator can cost
//! any tile of any partition exactly as the real render measured it.
//!
//! The tracer counts deterministic work (BVH nodes, triangle tests, rays) per 8x8 block of
//! pixels; `tessera render --trace FILE` records, for every frame, the whole image's block
//! costs. A tile's cost in any partition is then the sum over its rectangle
//! ([`balancer::CostMap::cost`], exact for block-aligned tiles and area-weighted inside cut
//! blocks), and the map itself is what the frame owner feeds back to the balancer: the
//! simulated PBT sees the very measurements the real one would.
//!
//! **Format** (version [`VERSION`]): JSON Lines. The first line is a [`Header`]; each further
//! line is one [`FrameCosts`], in frame order:
//!
//! ```text
//! {"format":"tessera-trace","version":1,"width":256,"height":256,"block_size":8,"source":"scenes/x.toml"}
//! {"frame":0,"blocks":[812,790,...]}
//! {"frame":1,"blocks":[...]}
//! ```
//!
//! `blocks` holds `ceil(width / block_size) * ceil(height / block_size)` counts, row-major, the
//! last column and row of blocks possibly partial. One line per frame lets a render append each
//! frame as it completes ([`TraceWriter`]), so an interrupted render still leaves a usable trace.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use balancer::CostMap;
use serde::{Deserialize, Serialize};

use crate::Error;

/// The widest and tallest image a trace may describe. The simulator keeps per-frame cost grids
/// of the image in 8-pixel blocks, as the balancer does; a 65536-pixel square already needs
/// half a gigabyte of them per frame, and its film (12 bytes a pixel) more memory than a
/// render's owner has, so larger traces describe no render that could run (a 4294967295-pixel
/// side asked for exabytes and aborted).
pub const MAX_SIDE: u32 = 1 << 16;

/// The version [`TraceWriter`] writes and [`Trace::read`] accepts.
pub const VERSION: u32 = 1;

const FORMAT: &str = "tessera-trace";

/// The first line of a trace: the image and its block grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Always `"tessera-trace"`, so that a wrong file is named as such.
    pub format: String,
    /// The format's version ([`VERSION`]); a reader refuses others.
    pub version: u32,
    /// The image's width in pixels.
    pub width: u32,
    /// The image's height in pixels.
    pub height: u32,
    /// Side of a cost block in pixels (the tracer's `BLOCK_SIZE`, 8).
    pub block_size: u32,
    /// Where the costs came from: a scene file, or a synthetic trace's recipe.
    pub source: String,
}

/// One frame: counted work per block, row-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameCosts {
    /// The frame's number in the animation.
    pub frame: u32,
    /// Counted work of each block.
    pub blocks: Vec<u64>,
}

/// A whole trace, in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    /// The image and its block grid.
    pub header: Header,
    /// Every frame's costs, in order.
    pub frames: Vec<FrameCosts>,
}

impl Header {
    /// A header for the current [`VERSION`]; refuses an image with no blocks.
    pub fn new(width: u32, height: u32, block_size: u32, source: &str) -> Result<Self, Error> {
        if width == 0 || height == 0 || block_size == 0 {
            return Err(Error::BadTrace(format!(
                "a {width}x{height} image in {block_size}-pixel blocks has no blocks"
            )));
        }
        if width > MAX_SIDE || height > MAX_SIDE {
            return Err(Error::BadTrace(format!(
                "a {width}x{height} image: traces are at most {MAX_SIDE} pixels a side"
            )));
        }
        Ok(Self {
            format: FORMAT.to_string(),
            version: VERSION,
            width,
            height,
            block_size,
            source: source.to_string(),
        })
    }

    /// Blocks per frame: `ceil(width / block) * ceil(height / block)`.
    pub fn block_count(&self) -> usize {
        self.width.div_ceil(self.block_size) as usize
            * self.height.div_ceil(self.block_size) as usize
    }

    fn check_frame(&self, frames_so_far: usize, frame: &FrameCosts) -> Result<(), String> {
        if frame.frame as usize != frames_so_far {
            return Err(format!(
                "frame {} where frame {frames_so_far} was expected (frames are in order from 0)",
                frame.frame
            ));
        }
        if frame.blocks.len() != self.block_count() {
            return Err(format!(
                "{} block costs where a {}x{} image in {}-pixel blocks has {}",
                frame.blocks.len(),
                self.width,
                self.height,
                self.block_size,
                self.block_count()
            ));
        }
        Ok(())
    }
}

impl Trace {
    /// An empty trace of a `width` x `height` image in `block_size` blocks.
    pub fn new(width: u32, height: u32, block_size: u32, source: &str) -> Result<Self, Error> {
        Ok(Self {
            header: Header::new(width, height, block_size, source)?,
            frames: Vec::new(),
        })
    }

    /// Appends the next frame's block costs.
    pub fn push(&mut self, blocks: Vec<u64>) -> Result<(), Error> {
        let frame = FrameCosts {
            frame: self.frames.len() as u32,
            blocks,
        };
        self.header
            .check_frame(self.frames.len(), &frame)
            .map_err(Error::BadTrace)?;
        self.frames.push(frame);
        Ok(())
    }

    /// Reads and checks a trace file.
    pub fn read(path: &Path) -> Result<Self, Error> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let bad = |line: usize, message: String| Error::Trace {
            path: path.to_path_buf(),
            line,
            message,
        };
        let mut lines = BufReader::new(file).lines().enumerate();
        let header: Header = match lines.next() {
            Some((_, line)) => {
                let line = line.map_err(|e| Error::io(path, e))?;
                serde_json::from_str(&line)
                    .map_err(|e| bad(1, format!("not a tessera trace header ({e})")))?
            }
            None => return Err(bad(1, "empty file: no trace header".into())),
        };
        if header.format != FORMAT {
            return Err(bad(
                1,
                format!("format {:?}, not {FORMAT:?}", header.format),
            ));
        }
        if header.version != VERSION {
            return Err(bad(
                1,
                format!(
                    "trace version {}; this tessera reads version {VERSION}",
                    header.version
                ),
            ));
        }
        Header::new(header.width, header.height, header.block_size, "")
            .map_err(|e| bad(1, e.to_string()))?;
        let mut frames = Vec::new();
        for (index, line) in lines {
            let line = line.map_err(|e| Error::io(path, e))?;
            if line.trim().is_empty() {
                continue;
            }
            let frame: FrameCosts =
                serde_json::from_str(&line).map_err(|e| bad(index + 1, e.to_string()))?;
            header
                .check_frame(frames.len(), &frame)
                .map_err(|message| bad(index + 1, message))?;
            frames.push(frame);
        }
        if frames.is_empty() {
            return Err(bad(1, "the trace has a header but no frames".into()));
        }
        Ok(Self { header, frames })
    }

    /// Writes the trace (creating or truncating the file).
    pub fn write(&self, path: &Path) -> Result<(), Error> {
        let mut writer = TraceWriter::with_header(path, self.header.clone())?;
        for frame in &self.frames {
            writer.push(&frame.blocks)?;
        }
        Ok(())
    }

    /// The image's width in pixels.
    pub fn width(&self) -> u32 {
        self.header.width
    }

    /// The image's height in pixels.
    pub fn height(&self) -> u32 {
        self.header.height
    }

    /// Every frame as a cost map with O(1) rectangle queries.
    pub fn cost_maps(&self) -> Result<Vec<CostMap>, Error> {
        let h = &self.header;
        self.frames
            .iter()
            .map(|frame| {
                Ok(CostMap::from_counts(
                    h.width,
                    h.height,
                    h.block_size,
                    &frame.blocks,
                )?)
            })
            .collect()
    }
}

/// Writes a trace frame by frame, flushing each line, as a render completes its frames.
pub struct TraceWriter {
    path: PathBuf,
    header: Header,
    out: BufWriter<File>,
    frames: usize,
}

impl TraceWriter {
    /// Creates (or truncates) `path` and writes the header of a `width` x `height` image in
    /// `block_size` blocks; `source` says where the costs come from (the scene file).
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        block_size: u32,
        source: &str,
    ) -> Result<Self, Error> {
        Self::with_header(path, Header::new(width, height, block_size, source)?)
    }

    fn with_header(path: &Path, header: Header) -> Result<Self, Error> {
        let file = File::create(path).map_err(|e| Error::io(path, e))?;
        let mut writer = Self {
            path: path.to_path_buf(),
            header,
            out: BufWriter::new(file),
            frames: 0,
        };
        let line = serde_json::to_string(&writer.header).expect("a header always serialises");
        writer.line(&line)?;
        Ok(writer)
    }

    /// Appends the next frame (frames are numbered from 0 in the order pushed): its counted
    /// work per block, row-major, as `tracer::Film::block_work` holds it.
    pub fn push(&mut self, blocks: &[u64]) -> Result<(), Error> {
        let frame = FrameCosts {
            frame: self.frames as u32,
            blocks: blocks.to_vec(),
        };
        self.header
            .check_frame(self.frames, &frame)
            .map_err(Error::BadTrace)?;
        let line = serde_json::to_string(&frame).expect("block counts always serialise");
        self.line(&line)?;
        self.frames += 1;
        Ok(())
    }

    fn line(&mut self, line: &str) -> Result<(), Error> {
        let path = &self.path;
        writeln!(self.out, "{line}")
            .and_then(|()| self.out.flush())
            .map_err(|e| Error::io(path, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("tessera-trace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    #[test]
    fn a_trace_reads_back_as_written() {
        let mut trace = Trace::new(20, 10, 8, "test").unwrap();
        trace.push((0..6).collect()).unwrap();
        trace.push(vec![7; 6]).unwrap();
        let path = temp("round-trip.jsonl");
        trace.write(&path).unwrap();
        assert_eq!(Trace::read(&path).unwrap(), trace);
        let maps = trace.cost_maps().unwrap();
        assert_eq!(maps[0].total(), 15.0);
        assert_eq!(maps[1].cost(balancer::Rect::new(0, 0, 8, 8)), 7.0);
    }

    #[test]
    fn a_frame_with_the_wrong_block_count_is_refused_with_its_line() {
        let path = temp("bad.jsonl");
        let header = Header::new(16, 16, 8, "test").unwrap();
        let text = format!(
            "{}\n{}\n{}\n",
            serde_json::to_string(&header).unwrap(),
            r#"{"frame":0,"blocks":[1,2,3,4]}"#,
            r#"{"frame":1,"blocks":[1,2,3]}"#
        );
        std::fs::write(&path, text).unwrap();
        let error = Trace::read(&path).unwrap_err().to_string();
        assert!(
            error.contains("line 3") && error.contains("3 block costs"),
            "{error}"
        );
        let mut trace = Trace::new(16, 16, 8, "test").unwrap();
        assert!(trace.push(vec![1; 5]).is_err());
    }

    #[test]
    fn a_file_that_is_not_a_trace_says_so() {
        let path = temp("not-a-trace.json");
        std::fs::write(&path, "{\"frames\": []}\n").unwrap();
        let error = Trace::read(&path).unwrap_err().to_string();
        assert!(error.contains("not a tessera trace"), "{error}");
    }
}
