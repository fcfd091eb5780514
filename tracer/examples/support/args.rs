//! The command line of the tracer's speed examples that take a scene and numbers
//! (`walk_bounds`, `traversal_speed`), shared through `#[path]` as `thread_cpu.rs` is: a scene
//! named by the first word, numbers with defaults after it.

use tracer::scene::Scene;

/// The scene the first word names, and the words; exits with `usage` (status 2) where there is
/// no first word, and with the loader's message (status 1) where the scene does not load.
pub fn scene_and_words(usage: &str) -> (Scene, Vec<String>) {
    let words: Vec<String> = std::env::args().collect();
    let Some(path) = words.get(1) else {
        eprintln!("usage: {usage}");
        std::process::exit(2);
    };
    match tracer::scene::load(std::path::Path::new(path)) {
        Ok(scene) => (scene, words),
        Err(e) => {
            eprintln!("{path}: {e}");
            std::process::exit(1);
        }
    }
}

/// Word `i` as a number, or `default` where there are fewer words; a word that is not a
/// number stops the example.
pub fn number<T: std::str::FromStr>(words: &[String], i: usize, default: T) -> T {
    words.get(i).map_or(default, |s| {
        s.parse()
            .unwrap_or_else(|_| panic!("word {i}, `{s}`, is not a number"))
    })
}
