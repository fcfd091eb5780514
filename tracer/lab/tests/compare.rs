//! The image metrics through the library, on real EXR files in a temporary folder; the expected
//! values are worked out by hand (`tests/accuracy.rs` at the top runs `tessera compare` itself).

// Test code: an unwrap that fails is a failed test, with its place in the output.
#![allow(clippy::unwrap_used)]

use std::path::Path;

fn write_rgb(
    path: &Path,
    width: usize,
    height: usize,
    pixel: impl Fn(usize, usize) -> [f32; 3] + Sync,
) {
    exr::prelude::write_rgb_file(path, width, height, |x, y| {
        let [r, g, b] = pixel(x, y);
        (r, g, b)
    })
    .unwrap();
}

#[test]
fn an_image_compared_with_itself_is_exactly_zero() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.exr");
    write_rgb(&a, 5, 3, |x, y| {
        [x as f32 * 0.3, y as f32 * 1.7, 0.25 + (x * y) as f32]
    });
    let c = lab::compare::compare_files(&a, &a).unwrap();
    let m = &c.metrics;
    assert_eq!([m.mse, m.rmse, m.rel_mse, m.mae], [0.0; 4], "{c:?}");
    assert_eq!(m.max_difference.value, 0.0, "{c:?}");
    assert_eq!(c.flip.mean, 0.0, "{c:?}");
}

#[test]
fn one_changed_value_gives_the_hand_computed_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let (test, reference) = (
        dir.path().join("test.exr"),
        dir.path().join("reference.exr"),
    );
    // 4x2 pixels, 24 values of 0.5; the test image has 0.75 in the green of pixel (3, 1).
    write_rgb(&reference, 4, 2, |_, _| [0.5; 3]);
    write_rgb(&test, 4, 2, |x, y| {
        if (x, y) == (3, 1) {
            [0.5, 0.75, 0.5]
        } else {
            [0.5; 3]
        }
    });
    let c = lab::compare::compare_files(&test, &reference).unwrap();
    let m = &c.metrics;
    let n = 24.0;
    assert_eq!(m.mse, 0.0625 / n);
    assert_eq!(m.rmse, (0.0625f64 / n).sqrt());
    assert!((m.rel_mse - 0.0625 / (0.51 * 0.51) / n).abs() < 1e-15);
    assert_eq!(m.mae, 0.25 / n);
    let max = &m.max_difference;
    assert_eq!((max.value, max.x, max.y), (0.25, 3, 1));
    assert_eq!(max.channel, "G");
    assert_eq!(m.mean_test[1], 0.5 + 0.25 / 8.0);
    assert!(c.flip.mean > 0.0, "{c:?}");
}
