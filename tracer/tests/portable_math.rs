//! No pixel depends on the machine's C library: every transcendental function the tracer's
//! code calls goes through `tracer::math` (pure-software libm), never through `f32`/`f64`
//! methods that call the platform's, whose implementation glibc picks by processor at run time.
//! A source check, because two machines that round differently are not both on hand: it reads
//! every file of `tracer/src` outside `math.rs` and its test modules (a module's `tests.rs` and
//! `tests` folder, and what follows a file's `#[cfg(test)]`).

use std::path::{Path, PathBuf};

/// Methods of `f32` and `f64` that call the C library (or may: LLVM lowers them to libm calls).
const PLATFORM_CALLS: [&str; 22] = [
    "sin", "cos", "sin_cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh",
    "asinh", "acosh", "atanh", "exp", "exp2", "exp_m1", "ln", "log", "log2", "log10", "powf",
];

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("tracer/src is readable") {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            // `tests` folders beside modules hold unit tests.
            if path.file_name().is_some_and(|n| n != "tests") {
                sources(&path, out);
            }
        } else if path.extension().is_some_and(|e| e == "rs")
            && path.file_name().is_some_and(|n| n != "tests.rs")
        {
            // A module's `tests.rs` is its unit tests' file (`#[cfg(test)] mod tests;`).
            out.push(path);
        }
    }
}

/// The lines of `text` that are code outside test modules: up to the first `#[cfg(test)]`
/// (test modules close each file here), without `//` comments.
fn code_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .take_while(|(_, line)| !line.trim_start().starts_with("#[cfg(test)]"))
        .map(|(n, line)| (n + 1, line.split("//").next().unwrap_or("")))
}

fn calls_in(text: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (number, line) in code_lines(text) {
        for name in PLATFORM_CALLS {
            let call = format!(".{name}(");
            if line.contains(&call) {
                found.push((number, call));
            }
        }
    }
    found
}

#[test]
fn the_tracer_calls_no_platform_transcendental() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&root, &mut files);
    assert!(files.len() > 20, "found only {} source files", files.len());
    let mut offences = Vec::new();
    for file in files.iter().filter(|f| !f.ends_with("math.rs")) {
        let text = std::fs::read_to_string(file).expect("a readable source file");
        for (line, call) in calls_in(&text) {
            offences.push(format!("{}:{line}: {call}", file.display()));
        }
    }
    assert!(
        offences.is_empty(),
        "call tracer::math instead:\n{}",
        offences.join("\n")
    );
}

#[test]
fn the_check_sees_calls_and_skips_comments_and_tests() {
    let text = "let a = x.sin_cos();\n// y.powf(2.0)\nlet b = y.atan2(x); // z.ln()\n#[cfg(test)]\nmod tests { fn f() { 1f32.exp(); } }\n";
    let found: Vec<String> = calls_in(text).into_iter().map(|(_, c)| c).collect();
    assert_eq!(found, [".sin_cos(", ".atan2("]);
    // `.sin(` is not mistaken inside `.sin_cos(`, nor `.ln(` inside `.lnx(`.
    assert_eq!(calls_in("a.sin_cos(); b.lnx();").len(), 1);
}
