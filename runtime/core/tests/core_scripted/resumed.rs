//! A frame resumed from results kept by an earlier run: only what they do not cover is handed out.

use super::*;

/// The results `synthetic_result` gives for `tiles` of `frame`, as a checkpoint would keep them.
fn kept_results(frame: FrameId, tiles: &[TileSpec]) -> Vec<TileResult> {
    tiles
        .iter()
        .map(|tile| synthetic_result(&runtime_core::peer::WorkItem { frame, tile: *tile }))
        .collect()
}

#[test]
fn a_frame_resumed_from_kept_results_hands_out_only_what_they_do_not_cover() {
    let all = tiles(0, &uneven(12));
    for kept in [0, 1, 5, 11] {
        let mut core = Core::new(OWNER, 1, Config::default(), 0);
        let assignments = BTreeMap::from([(OWNER, all.clone())]);
        let done = kept_results(FrameId(1), &all[..kept]);
        core.resume_frame(Duration::ZERO, FrameId(1), assignments, u64::MAX, done)
            .unwrap();
        let mut handed = Vec::new();
        let mut now = Duration::ZERO;
        while let Some(item) = core.poll_work() {
            handed.push(item.tile.id);
            now += Duration::from_millis(1);
            core.handle_tile_rendered(now, synthetic_result(&item));
        }
        let expected: Vec<TileId> = (kept as u32..12).map(TileId).collect();
        assert_eq!(handed, expected, "{kept} kept");
        let complete = std::iter::from_fn(|| core.poll_event()).find_map(|event| match event {
            Event::FrameComplete { results, .. } => Some(results),
            _ => None,
        });
        let results = complete.unwrap_or_else(|| panic!("{kept} kept: no completion"));
        assert_all_results(&results, FrameId(1), 12);
        assert_eq!(results[..kept], kept_results(FrameId(1), &all[..kept]));
    }
}

#[test]
fn kept_results_covering_the_frame_complete_it_at_once_and_wrong_ones_are_not_used() {
    let all = tiles(0, &uneven(6));
    let mut core = Core::new(OWNER, 1, Config::default(), 0);
    let done = kept_results(FrameId(2), &all);
    let assignments = BTreeMap::from([(OWNER, all.clone())]);
    core.resume_frame(Duration::ZERO, FrameId(2), assignments, u64::MAX, done)
        .unwrap();
    assert!(
        core.poll_work().is_none(),
        "work handed out for a done frame"
    );
    let events: Vec<Event> = std::iter::from_fn(|| core.poll_event()).collect();
    assert!(
        events.iter().any(|e| matches!(
            e,
            Event::FrameComplete {
                frame: FrameId(2),
                ..
            }
        )),
        "{events:?}"
    );

    // A kept result that does not fit its tile (another rectangle) is refused and re-rendered.
    let mut core = Core::new(OWNER, 1, Config::default(), 0);
    let mut done = kept_results(FrameId(3), &all[..2]);
    done[1].rect = Rect::new(999, 0, 4, 4);
    let assignments = BTreeMap::from([(OWNER, all.clone())]);
    core.resume_frame(Duration::ZERO, FrameId(3), assignments, u64::MAX, done)
        .unwrap();
    let first = core.poll_work().expect("work for the tiles not kept");
    assert_eq!(
        first.tile.id,
        TileId(1),
        "the wrong result was taken as done"
    );
    let faults = std::iter::from_fn(|| core.poll_event())
        .filter(|e| {
            matches!(
                e,
                Event::FaultyPeer {
                    fault: Fault::WrongRect,
                    ..
                }
            )
        })
        .count();
    assert_eq!(faults, 1);
}
