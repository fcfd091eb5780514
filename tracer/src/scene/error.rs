//! The one error type of scene loading.
//!
//! A scene is written by hand or exported by tools that disagree about the formats, so every error
//! says where to look: the file (relative to the scene's folder, or the full path when loaded from
//! disk), the 1-based line when one applies, and the problem in words. Three variants: a file
//! that cannot be read at all, an image that was read but cannot be used (named with the line
//! that asked for it, since the fix is as often there as in the image), and a file whose
//! contents are wrong.

use std::fmt;
use std::io;

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file the scene needs could not be read (missing, unreadable, not a file).
    #[error("cannot read {file}{}: {source}", referenced(.referenced_at))]
    Read {
        /// The file that could not be read: relative to the scene's folder, or its full path
        /// when the scene was loaded from disk.
        file: String,
        /// Where the file is named (the TOML key, the `mtllib` or `map_Kd` line), if anywhere.
        referenced_at: Option<Location>,
        /// What the file source said (the operating system's error, or not found in memory).
        #[source]
        source: io::Error,
    },
    /// An image (a texture, an environment map) was read but cannot be used: it does not decode,
    /// or holds what it must not (an environment map's negative texel).
    #[error("{file} (referenced at {referenced_at}): {detail}")]
    Image {
        /// The image: relative to the scene's folder, or its full path when the scene was
        /// loaded from disk.
        file: String,
        /// Where the image is named (the `map_Kd` line, the environment's `map` key): a scene
        /// may use one image from several places, and the fix is often there.
        referenced_at: Location,
        /// The problem in words: what the decoder said, or what the image holds.
        detail: String,
    },
    /// A file was read but its contents are invalid.
    #[error("{at}: {detail}")]
    Invalid {
        /// The file, and the line when the problem is on one.
        at: Location,
        /// The problem in words, for the person who wrote the file.
        detail: String,
    },
}

/// A place in a scene file: the file, and the 1-based line when the problem has one.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    /// The file: relative to the scene's folder, or its full path when the scene was loaded
    /// from disk.
    pub file: String,
    /// The 1-based line, as editors count; `None` for a problem of the file as a whole.
    pub line: Option<usize>,
}

impl SceneError {
    /// The file the error is about (the unreadable file, or the file with the bad contents).
    pub fn file(&self) -> &str {
        match self {
            SceneError::Read { file, .. } | SceneError::Image { file, .. } => file,
            SceneError::Invalid { at, .. } => &at.file,
        }
    }

    /// The 1-based line of the problem in [`SceneError::file`], when one applies.
    pub fn line(&self) -> Option<usize> {
        match self {
            SceneError::Read { .. } | SceneError::Image { .. } => None,
            SceneError::Invalid { at, .. } => at.line,
        }
    }

    pub(crate) fn at_line(file: &str, line: usize, detail: impl Into<String>) -> Self {
        SceneError::Invalid {
            at: Location::line(file, line),
            detail: detail.into(),
        }
    }

    pub(crate) fn in_file(file: &str, detail: impl Into<String>) -> Self {
        SceneError::Invalid {
            at: Location::file(file),
            detail: detail.into(),
        }
    }

    /// An image `file` that was read but cannot be used, named at `from` (file, line).
    pub(crate) fn image(file: &str, from: (&str, usize), detail: impl Into<String>) -> Self {
        SceneError::Image {
            file: file.to_owned(),
            referenced_at: Location::line(from.0, from.1),
            detail: detail.into(),
        }
    }

    /// The same error with every file name passed through `rename`: used to turn names relative
    /// to a disk root into full paths.
    pub(crate) fn rename_files(self, rename: impl Fn(&str) -> String) -> Self {
        let fix = |at: Location| Location {
            file: rename(&at.file),
            line: at.line,
        };
        match self {
            SceneError::Read {
                file,
                referenced_at,
                source,
            } => SceneError::Read {
                file: rename(&file),
                referenced_at: referenced_at.map(fix),
                source,
            },
            SceneError::Image {
                file,
                referenced_at,
                detail,
            } => SceneError::Image {
                file: rename(&file),
                referenced_at: fix(referenced_at),
                detail,
            },
            SceneError::Invalid { at, detail } => SceneError::Invalid {
                at: fix(at),
                detail,
            },
        }
    }
}

impl Location {
    pub(crate) fn line(file: &str, line: usize) -> Self {
        Location {
            file: file.to_owned(),
            line: Some(line),
        }
    }

    pub(crate) fn file(file: &str) -> Self {
        Location {
            file: file.to_owned(),
            line: None,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{}", self.file, line),
            None => f.write_str(&self.file),
        }
    }
}

fn referenced(at: &Option<Location>) -> String {
    match at {
        Some(at) => format!(" (referenced at {at})"),
        None => String::new(),
    }
}

/// The 1-based line of byte offset `offset` in `text`.
pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    1 + text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}
