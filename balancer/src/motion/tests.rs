use super::*;

/// A Gaussian spot of `sigma` blocks at block position `(x, y)` on a background of 1, over a
/// grid of `columns` x `rows` 8-pixel blocks.
fn spot(columns: u32, rows: u32, (x, y): (f64, f64), sigma: f64) -> CostMap {
    CostMap::from_fn(columns * 8, rows * 8, 8, |c, r| {
        let (dx, dy) = (f64::from(c) - x, f64::from(r) - y);
        1.0 + 100.0 * (-(dx * dx + dy * dy) / (2.0 * sigma * sigma)).exp()
    })
    .unwrap()
}

/// A deterministic pseudo-random stream in [0, 1) (SplitMix64), for noise.
fn noise(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn whole_block_shifts_are_found_on_every_grid_size_spot_size_and_direction() {
    for (columns, rows) in [(32, 32), (128, 128), (160, 90), (40, 200)] {
        for sigma in [1.5, 4.0, 8.0] {
            for shift in [(1i64, 0i64), (0, -1), (3, 2), (-7, 5), (12, -12), (-16, 0)] {
                let limit = (columns.min(rows) as i64 - 1) / 2;
                if shift.0.abs().max(shift.1.abs()) > limit.min(16) {
                    continue;
                }
                let from = (f64::from(columns) * 0.45, f64::from(rows) * 0.5);
                let to = (from.0 + shift.0 as f64, from.1 + shift.1 as f64);
                let older = spot(columns, rows, from, sigma);
                let newer = spot(columns, rows, to, sigma);
                let motion = estimate(&older, &newer, 16)
                    .unwrap_or_else(|| panic!("{columns}x{rows}, sigma {sigma}, {shift:?}: none"));
                let error = (motion.dx - shift.0 as f64)
                    .abs()
                    .max((motion.dy - shift.1 as f64).abs());
                assert!(
                    error < 0.1,
                    "{columns}x{rows}, sigma {sigma}, {shift:?}: found {motion:?}"
                );
            }
        }
    }
}

#[test]
fn fractions_of_a_block_are_found_within_a_quarter() {
    // Motion of less than half a block is not sought (see `estimate`): each of these moves at
    // least a block along one axis.
    for (fx, fy) in [
        (1.25, 0.0),
        (0.75, -1.5),
        (2.4, 1.3),
        (-5.7, 0.8),
        (9.5, -3.25),
    ] {
        for sigma in [2.0, 4.0, 6.0] {
            let from = (60.0, 64.0);
            let older = spot(128, 128, from, sigma);
            let newer = spot(128, 128, (from.0 + fx, from.1 + fy), sigma);
            let motion = estimate(&older, &newer, 16)
                .unwrap_or_else(|| panic!("sigma {sigma}, moved ({fx}, {fy}): none"));
            assert!(
                (motion.dx - fx).abs() <= 0.25 && (motion.dy - fy).abs() <= 0.25,
                "sigma {sigma}, moved ({fx}, {fy}): found {motion:?}"
            );
        }
    }
}

#[test]
fn a_still_landscape_has_no_motion_even_under_noise() {
    for amplitude in [0.0, 0.01, 0.1, 0.5] {
        for seed in 0..4 {
            let mut older_noise = noise(seed);
            let mut newer_noise = noise(seed + 100);
            let base = spot(96, 64, (40.0, 30.0), 5.0);
            let older = CostMap::from_fn(96 * 8, 64 * 8, 8, |c, r| {
                base.block_cost(c, r).unwrap() * (1.0 + amplitude * older_noise())
            })
            .unwrap();
            let newer = CostMap::from_fn(96 * 8, 64 * 8, 8, |c, r| {
                base.block_cost(c, r).unwrap() * (1.0 + amplitude * newer_noise())
            })
            .unwrap();
            assert_eq!(
                estimate(&older, &newer, 16),
                None,
                "noise {amplitude}, seed {seed}"
            );
        }
    }
    // Pure noise with no structure invents nothing either.
    for seed in 0..4 {
        let (mut a, mut b) = (noise(seed), noise(seed + 7));
        let older = CostMap::from_fn(512, 512, 8, |_, _| 1.0 + a()).unwrap();
        let newer = CostMap::from_fn(512, 512, 8, |_, _| 1.0 + b()).unwrap();
        assert_eq!(estimate(&older, &newer, 16), None, "seed {seed}");
    }
}

#[test]
fn motion_under_half_a_block_is_not_sought() {
    let older = spot(64, 64, (30.0, 30.0), 4.0);
    let newer = spot(64, 64, (30.3, 29.8), 4.0);
    assert_eq!(estimate(&older, &newer, 16), None);
}

#[test]
fn grids_that_differ_or_a_zero_search_give_no_motion() {
    let a = spot(32, 32, (10.0, 10.0), 2.0);
    let b = spot(32, 32, (13.0, 10.0), 2.0);
    assert!(estimate(&a, &b, 16).is_some());
    assert_eq!(estimate(&a, &b, 0), None);
    let other = CostMap::from_fn(256, 256, 16, |_, _| 1.0).unwrap();
    assert_eq!(estimate(&a, &other, 16), None, "block sizes differ");
    let tiny = spot(2, 2, (0.0, 0.0), 1.0);
    assert_eq!(estimate(&tiny, &tiny, 16), None, "no room to shift");
}

#[test]
fn extrapolation_carries_the_landscape_on_by_whole_and_fractional_frames() {
    for (motion, frames) in [
        ((3.0, 0.0), 1),
        ((2.0, -1.0), 2),
        ((1.5, 2.5), 2),
        ((-4.0, 0.0), 3),
    ] {
        let from = (50.0, 60.0);
        let last = spot(128, 128, from, 4.0);
        let step = Motion {
            dx: motion.0,
            dy: motion.1,
        };
        let predicted = extrapolate(&last, ahead(&[step], frames)).unwrap();
        let k = f64::from(frames);
        let expected = spot(
            128,
            128,
            (from.0 + k * motion.0, from.1 + k * motion.1),
            4.0,
        );
        // Bilinear sampling of a smooth spot is close, not exact: within 2% of the peak.
        for r in 0..128 {
            for c in 0..128 {
                let (p, e) = (
                    predicted.block_cost(c, r).unwrap(),
                    expected.block_cost(c, r).unwrap(),
                );
                assert!(
                    (p - e).abs() < 2.0,
                    "{motion:?} x{frames}: block ({c}, {r}) {p} vs {e}"
                );
            }
        }
    }
}

#[test]
fn extrapolation_clamps_to_the_edge_and_keeps_a_still_map() {
    let last = CostMap::from_fn(64, 32, 8, |c, r| f64::from(c + 10 * r)).unwrap();
    let same = extrapolate(&last, Motion { dx: 0.0, dy: 0.0 }).unwrap();
    for r in 0..4 {
        for c in 0..8 {
            assert_eq!(same.block_cost(c, r), last.block_cost(c, r));
        }
    }
    // Moved right by two blocks: the first two columns repeat the old first column.
    let moved = extrapolate(&last, Motion { dx: 2.0, dy: 0.0 }).unwrap();
    for r in 0..4 {
        assert_eq!(moved.block_cost(0, r), last.block_cost(0, r));
        assert_eq!(moved.block_cost(1, r), last.block_cost(0, r));
        assert_eq!(moved.block_cost(5, r), last.block_cost(3, r));
    }
}

fn polar(length: f64, degrees: f64) -> Motion {
    let (sin, cos) = degrees.to_radians().sin_cos();
    Motion {
        dx: length * cos,
        dy: length * sin,
    }
}

#[test]
fn steady_turns_and_changes_of_speed_are_carried_on() {
    // Motions of an orbit (a constant turn), of a camera easing in (a constant factor), and
    // of both, for 1 to 3 frames ahead.
    for (turn, factor) in [(18.0, 1.0f64), (-10.0, 1.0), (0.0, 1.2), (25.0, 0.8)] {
        let motions: Vec<Motion> = (0..6)
            .map(|i| polar(6.0 * factor.powi(i), 30.0 + turn * f64::from(i)))
            .collect();
        for frames in 1..=3usize {
            let predicted = ahead(&motions[..3], frames as u32);
            let actual = motions[3..3 + frames]
                .iter()
                .fold(Motion { dx: 0.0, dy: 0.0 }, |t, m| Motion {
                    dx: t.dx + m.dx,
                    dy: t.dy + m.dy,
                });
            assert!(
                distance(predicted, actual) < 1e-9,
                "turn {turn}, factor {factor}, {frames} ahead: {predicted:?} vs {actual:?}"
            );
        }
    }
}

#[test]
fn without_a_steady_turn_motion_continues_straight() {
    let straight = |motions: &[Motion], frames: u32| {
        let last = *motions.last().unwrap();
        Motion {
            dx: last.dx * f64::from(frames),
            dy: last.dy * f64::from(frames),
        }
    };
    let cases: [&[Motion]; 4] = [
        // A turn undone: with three motions, the first turn does not predict the second.
        &[polar(5.0, 0.0), polar(5.0, 20.0), polar(5.0, 0.0)],
        // A zigzag: a turn would have predicted the last motion worse than going straight.
        &[polar(5.0, 0.0), polar(5.0, 30.0), polar(5.0, 0.0)],
        // Under a block: direction is noise.
        &[polar(0.6, 0.0), polar(0.7, 40.0), polar(0.6, 80.0)],
        &[polar(4.0, 10.0)],
    ];
    for motions in cases {
        for frames in 1..=3 {
            let predicted = ahead(motions, frames);
            let expected = straight(motions, frames);
            assert!(
                distance(predicted, expected) < 1e-9,
                "{motions:?}: {predicted:?}"
            );
        }
    }
    assert_eq!(ahead(&[], 2), Motion { dx: 0.0, dy: 0.0 });
}

#[test]
fn two_motions_turn_unchecked() {
    let motions = [polar(5.0, 0.0), polar(5.0, 20.0)];
    let predicted = ahead(&motions, 2);
    let expected = Motion {
        dx: polar(5.0, 40.0).dx + polar(5.0, 60.0).dx,
        dy: polar(5.0, 40.0).dy + polar(5.0, 60.0).dy,
    };
    assert!(distance(predicted, expected) < 1e-9, "{predicted:?}");
}

#[test]
fn turns_are_clamped_to_the_most_believed() {
    let motions = [polar(5.0, 0.0), polar(5.0, 80.0), polar(5.0, 160.0)];
    let predicted = ahead(&motions, 1);
    let angle = predicted.dy.atan2(predicted.dx).to_degrees();
    assert!(
        (angle - 205.0 + 360.0).abs() < 1e-6 || (angle - (160.0f64 + 45.0 - 360.0)).abs() < 1e-6,
        "{angle}"
    );
}

/// `--motion` and `stats.json` spell the search as a positive number of blocks or `off`, and
/// what is written reads back as itself.
#[test]
fn motion_search_spellings_read_back() {
    assert_eq!(MotionSearch::default().0, crate::Config::default().motion);
    for search in [
        MotionSearch(None),
        MotionSearch(Some(1)),
        MotionSearch(Some(16)),
    ] {
        assert_eq!(search.to_string().parse::<MotionSearch>(), Ok(search));
    }
    assert_eq!(MotionSearch(None).to_string(), "off");
    assert_eq!("4".parse::<MotionSearch>(), Ok(MotionSearch(Some(4))));
    for bad in ["0", "-1", "1.5", "", "Off", "none"] {
        let error = bad.parse::<MotionSearch>().unwrap_err();
        assert_eq!(
            error,
            format!("{bad:?}: give a positive number of blocks, or off")
        );
    }
}
