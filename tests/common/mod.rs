//! Helpers shared by the end-to-end tests: run the real binary, read its EXR output.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// Runs the command and returns its output, failing the test with stderr if it failed.
pub fn run_ok(command: &mut Command) -> Output {
    let output = command.output().expect("the tessera binary runs");
    assert!(
        output.status.success(),
        "{command:?} failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// The bytes of every `frame-NNNN.exr` in `dir`, in frame order.
pub fn frames(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("frame-") && n.ends_with(".exr"))
        .collect();
    names.sort();
    names
        .into_iter()
        .map(|n| {
            let bytes = std::fs::read(dir.join(&n)).unwrap();
            (n, bytes)
        })
        .collect()
}

/// Every pixel of an EXR file as linear RGB.
pub fn pixels(path: &Path) -> Vec<[f32; 3]> {
    tracer::output::read_exr(path)
        .expect("our EXR files read back")
        .pixels
}

/// `../shared/scenes` beside the repository, if present.
pub fn shared_scenes() -> Option<PathBuf> {
    let dir = repo("../shared/scenes");
    dir.is_dir().then_some(dir)
}
