//! Where scene files come from.
//!
//! The loader never opens files itself: it asks a [`SceneFiles`] source, so a peer that received a
//! scene's files over the network loads them from memory with exactly the code that loads them from
//! disk. Paths are `/`-separated strings relative to the source's root and lexically normalised
//! (`a/./b/../c` is `a/c`; leading `..` stay, which is how the shipped `scenes/shared/*.toml`
//! reach `../shared/scenes`). Absolute paths are refused: a scene must be shippable as a set of
//! relative files.

use super::error::{Location, SceneError};
use std::collections::BTreeMap;
use std::io;
use std::path::PathBuf;

/// A read-only set of files addressed by relative, `/`-separated paths.
pub trait SceneFiles {
    /// The whole content of a file.
    fn read(&self, relative_path: &str) -> Result<Vec<u8>, io::Error>;

    /// The names of the files directly inside a folder (`""` is the root). Used only to match a
    /// file name case-insensitively when the exact name is missing, because texture names in MTL
    /// files written on Windows often differ in case from the files (Sponza's do).
    fn list(&self, relative_folder: &str) -> Result<Vec<String>, io::Error>;
}

/// Files in a folder on disk.
#[derive(Clone, Debug)]
pub struct DiskFiles {
    /// The folder relative paths are resolved against: the scene file's own folder.
    pub root: PathBuf,
}

/// Files held in memory, keyed by their normalised relative path.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MemoryFiles(pub BTreeMap<String, Vec<u8>>);

impl SceneFiles for DiskFiles {
    fn read(&self, relative_path: &str) -> Result<Vec<u8>, io::Error> {
        std::fs::read(self.root.join(relative_path))
    }

    fn list(&self, relative_folder: &str) -> Result<Vec<String>, io::Error> {
        let mut names = Vec::new();
        for entry in std::fs::read_dir(self.root.join(relative_folder))? {
            let entry = entry?;
            if entry.file_type()?.is_file() {
                names.extend(entry.file_name().to_str().map(str::to_owned));
            }
        }
        names.sort();
        Ok(names)
    }
}

impl SceneFiles for MemoryFiles {
    fn read(&self, relative_path: &str) -> Result<Vec<u8>, io::Error> {
        self.0.get(relative_path).cloned().ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::NotFound,
                "no such file in the scene's file set",
            )
        })
    }

    fn list(&self, relative_folder: &str) -> Result<Vec<String>, io::Error> {
        let names = self.0.keys().filter_map(|path| {
            let (folder, name) = split(path);
            (folder == relative_folder).then(|| name.to_owned())
        });
        Ok(names.collect())
    }
}

impl MemoryFiles {
    /// An empty file set, to be filled with [`MemoryFiles::insert`].
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a file; `path` is normalised like every path the loader asks for.
    pub fn insert(&mut self, path: &str, content: impl Into<Vec<u8>>) {
        let path = normalize(path).unwrap_or_else(|| path.to_owned());
        self.0.insert(path, content.into());
    }
}

/// Reads files for one scene load: resolves references relative to the referring file, falls
/// back to a case-insensitive match of the file name, and records every file read, in first-read
/// order, relative to the scene's folder.
pub(crate) struct FileLog<'a> {
    files: &'a dyn SceneFiles,
    /// The TOML's folder, relative to the source's root (`""` for the root itself).
    scene_folder: String,
    read: Vec<String>,
}

impl<'a> FileLog<'a> {
    pub(crate) fn new(files: &'a dyn SceneFiles, toml_name: &str) -> Self {
        let scene_folder = split(&normalize(toml_name).unwrap_or_default())
            .0
            .to_owned();
        FileLog {
            files,
            scene_folder,
            read: Vec::new(),
        }
    }

    /// Reads `reference` (as written in the file `from`, a path relative to the scene's folder)
    /// and returns the path it resolved to (relative to the scene's folder) and the content.
    pub(crate) fn read(
        &mut self,
        from: Option<(&str, usize)>,
        reference: &str,
    ) -> Result<(String, Vec<u8>), SceneError> {
        let referenced_at = from.map(|(file, line)| Location::line(file, line));
        let base = from.map_or("", |(file, _)| split(file).0);
        let wanted = resolve(base, reference).ok_or_else(|| SceneError::Invalid {
            at: referenced_at
                .clone()
                .unwrap_or_else(|| Location::file(reference)),
            detail: format!("`{reference}` is not a relative path inside the scene's tree"),
        })?;
        let rooted = |path: &str| join(&self.scene_folder, path);
        let (path, result) = match self.files.read(&rooted(&wanted)) {
            Err(e) if e.kind() == io::ErrorKind::NotFound => match self.case_insensitive(&wanted) {
                Some(found) => {
                    let result = self.files.read(&rooted(&found));
                    (found, result)
                }
                None => (wanted, Err(e)),
            },
            result => (wanted, result),
        };
        match result {
            Ok(bytes) => {
                if !self.read.contains(&path) {
                    self.read.push(path.clone());
                }
                Ok((path, bytes))
            }
            Err(source) => Err(SceneError::Read {
                file: path,
                referenced_at,
                source,
            }),
        }
    }

    /// Every file read so far, in first-read order.
    pub(crate) fn into_read(self) -> Vec<String> {
        self.read
    }

    /// The one file in `path`'s folder whose name equals `path`'s name ignoring ASCII case.
    fn case_insensitive(&self, path: &str) -> Option<String> {
        let (folder, name) = split(path);
        let names = self.files.list(&join(&self.scene_folder, folder)).ok()?;
        let mut matches = names.into_iter().filter(|n| n.eq_ignore_ascii_case(name));
        match (matches.next(), matches.next()) {
            (Some(found), None) => Some(join(folder, &found)),
            _ => None,
        }
    }
}

/// `reference` (written in a file inside `base`) as a normalised path; `None` when absolute.
pub(crate) fn resolve(base: &str, reference: &str) -> Option<String> {
    // OBJ/MTL files written on Windows use backslashes.
    let reference = reference.replace('\\', "/");
    let absolute = reference.starts_with('/') || reference.as_bytes().get(1) == Some(&b':');
    if absolute || reference.trim().is_empty() {
        return None;
    }
    normalize(&join(base, &reference))
}

/// Joins two relative paths.
pub(crate) fn join(base: &str, path: &str) -> String {
    if base.is_empty() {
        path.to_owned()
    } else {
        normalize(&format!("{base}/{path}")).unwrap_or_else(|| format!("{base}/{path}"))
    }
}

/// Lexically normalises a relative, `/`-separated path: removes `.` segments and folds `x/..`;
/// keeps leading `..`. `None` for an absolute path.
pub fn normalize(path: &str) -> Option<String> {
    if path.starts_with('/') {
        return None;
    }
    let mut parts: Vec<&str> = Vec::new();
    for part in path.split('/') {
        match part {
            "" | "." => {}
            ".." if parts.last().is_some_and(|p| *p != "..") => {
                parts.pop();
            }
            part => parts.push(part),
        }
    }
    Some(parts.join("/"))
}

/// Splits a path into its folder (`""` when none) and its file name.
fn split(path: &str) -> (&str, &str) {
    path.rsplit_once('/').unwrap_or(("", path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_normalise_and_keep_leading_parents() {
        assert_eq!(
            resolve("meshes", "../tex/./a.png").as_deref(),
            Some("tex/a.png")
        );
        assert_eq!(resolve("", "../../x.obj").as_deref(), Some("../../x.obj"));
        assert_eq!(resolve("a/b", "..\\c.mtl").as_deref(), Some("a/c.mtl"));
        assert_eq!(resolve("", "/etc/passwd"), None);
        assert_eq!(resolve("", "C:\\x.obj"), None);
    }

    #[test]
    fn names_match_case_insensitively_and_are_logged_once_as_found() {
        let mut files = MemoryFiles::new();
        files.insert("scenes/s.toml", "");
        files.insert("scenes/m/Tex.JPG", "jpg");
        let mut log = FileLog::new(&files, "scenes/s.toml");
        let (path, bytes) = log.read(Some(("m/a.mtl", 3)), "TEX.jpg").unwrap();
        assert_eq!(
            (path.as_str(), bytes.as_slice()),
            ("m/Tex.JPG", b"jpg".as_slice())
        );
        log.read(None, "m/Tex.JPG").unwrap();
        let missing = log.read(Some(("m/a.mtl", 4)), "nope.png").unwrap_err();
        assert_eq!(missing.file(), "m/nope.png");
        assert!(missing.to_string().contains("m/a.mtl:4"), "{missing}");
        assert_eq!(log.into_read(), vec!["m/Tex.JPG".to_owned()]);
    }
}
