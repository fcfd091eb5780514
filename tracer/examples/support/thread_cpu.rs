//! The clock of the tracer's speed examples (`traversal_speed`, `trace_rays`), shared through
//! `#[path]`: a folder without a `main.rs` is not an example of its own.

/// This thread's CPU time in seconds, from the first field of `schedstat` (nanoseconds on CPU).
///
/// Why thread CPU time: on a machine shared with other work a wall clock counts the other work
/// too, and interference only ever adds time; measured on the thread that traces, it is the
/// tracing's own.
pub fn thread_cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/thread-self/schedstat")
        .expect("Linux's /proc/thread-self/schedstat: these examples measure with it");
    let nanos: f64 = stat
        .split_whitespace()
        .next()
        .and_then(|n| n.parse().ok())
        .expect("schedstat starts with the nanoseconds on CPU");
    nanos / 1e9
}
