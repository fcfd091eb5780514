//! A resumed render: dealt from its first missing frame, that frame cut into its checkpoint's
//! pieces.

use super::*;

/// A resumed render deals from its first missing frame on, numbered as in the whole animation;
/// one with nothing left finishes without dealing.
#[test]
fn a_resumed_render_deals_from_its_first_frame() {
    let mut cluster = cluster(2);
    let config = Config {
        frames: 4,
        first: 2,
        ..Config::default()
    };
    let mut resumed = Director::new(OWNER, pbt(8), config.clone());
    resumed.handle_peer_joined(Duration::ZERO, PeerId(1));
    let (deals, events) = drive(&mut resumed, &mut cluster, &|_| halves(3));
    let dealt: Vec<u32> = deals.iter().map(|d| d.frame.0).collect();
    assert_eq!(dealt, [2, 3]);
    let completed: Vec<u32> = events
        .iter()
        .filter_map(|e| match e {
            Event::FrameComplete { frame, .. } => Some(frame.0),
            _ => None,
        })
        .collect();
    assert_eq!(completed, [2, 3]);
    assert_eq!(events.last(), Some(&Event::Finished));
    // Frame 2 is cut as frame 0 would be: the balancer has no costs of frame 1.
    let fresh = director(pbt(8), 2, 1)
        .poll_deal(Duration::ZERO)
        .unwrap()
        .unwrap();
    assert_eq!(deals[0].tiles, fresh.tiles);

    let mut done = Director::new(OWNER, pbt(8), Config { first: 4, ..config });
    assert!(done.is_finished());
    assert_eq!(done.poll_deal(Duration::ZERO).unwrap(), None);
    assert_eq!(done.poll_event(), Some(Event::Finished));
}

#[test]
fn a_resumed_first_frame_is_cut_into_its_checkpoints_tiles_and_the_rest_as_usual() {
    // The checkpoint's tiles: a 4x2 grid, not what a 16-leaf PBT cuts.
    let kept: Vec<balancer::Tile> = grid(4, 2).tiles();
    for first in [0, 3] {
        let config = Config {
            frames: first + 3,
            first,
            ..Config::default()
        };
        let mut director = Director::new(OWNER, pbt(16), config);
        director.handle_peer_joined(Duration::ZERO, PeerId(1));
        director.resume_with(kept.clone());
        let mut cluster = cluster(2);
        let (deals, _) = drive(&mut director, &mut cluster, &|_| halves(4));
        assert_eq!(deals.len(), 3);
        assert_eq!(deals[0].frame, FrameId(first));
        assert_eq!(deals[0].tiles, kept, "first {first}");
        let dealt: usize = deals[0].assignments.values().map(Vec::len).sum();
        assert_eq!(dealt, kept.len());
        for deal in &deals[1..] {
            assert_eq!(
                deal.tiles.len(),
                16,
                "first {first}: later frames are the PBT's"
            );
        }
    }
}
