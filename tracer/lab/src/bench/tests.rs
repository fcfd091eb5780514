//! The unit tests of the scene measurements: the two passes on the shipped furnace, the
//! spectral knob, every effect forced, skipping an absent mesh but not a malformed scene, the process's CPU-seconds
//! and finding the shipped scenes. They are a file of their own so that the measurements read
//! without them; as a child module they still reach the private helpers they test.

use super::*;
use tracer::spectrum::SpectralSampling;

fn args() -> Config {
    Config {
        scenes: Vec::new(),
        adjust: Box::new(|settings| {
            (settings.samples_per_pixel, settings.width, settings.height) = (2, 8, 6);
            Ok(())
        }),
        max_depth: None,
        threads: Some(1),
        out: None,
        steal_rtt: 0,
        json: true,
        spectral: SpectralSampling::default(),
        paths: tracer::PathLanes::default(),
        effects: None,
    }
}

fn pool() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool")
}

#[test]
fn primary_pass_traces_one_camera_ray_per_sample_and_paths_trace_more() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/furnace/furnace.toml");
    let measured = bench_scene(&scene, &args(), &pool())
        .expect("the furnace loads")
        .expect("nothing absent");
    assert_eq!(
        (measured.width, measured.height, measured.samples_per_pixel),
        (8, 6, 2)
    );
    assert_eq!(measured.primary.max_depth, Some(0));
    assert_eq!(measured.primary.rays, 8 * 6 * 2);
    // The furnace is closed and emissive: every path bounces, and every bounce adds rays.
    assert!(
        measured.paths.rays > 2 * measured.primary.rays,
        "{} rays",
        measured.paths.rays
    );
    assert_eq!(measured.paths.max_depth, Some(8));
    // The furnace turns roulette off, and the report says so.
    assert_eq!(measured.paths.russian_roulette_depth, None);
}

#[test]
fn the_paths_pass_reports_the_roulette_depth_the_scene_declares() {
    let furnace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/furnace/furnace.toml");
    let text = std::fs::read_to_string(&furnace).expect("the shipped furnace");
    let dir = tempfile::tempdir().expect("a temporary folder");
    for depth in [1, 5] {
        let scene = dir.path().join(format!("furnace-{depth}.toml"));
        let declared = text.replace(
            "russian_roulette_depth = \"off\"",
            &format!("russian_roulette_depth = {depth}"),
        );
        assert_ne!(declared, text, "the furnace declares its roulette depth");
        std::fs::write(&scene, declared).expect("a scene in the temporary folder");
        let measured = bench_scene(&scene, &args(), &pool())
            .expect("the furnace loads")
            .expect("nothing absent");
        assert_eq!(measured.paths.russian_roulette_depth, Some(depth));
    }
}

#[test]
fn the_spectral_knob_renders_other_pixels_from_the_same_camera_rays() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/furnace/furnace.toml");
    let dir = tempfile::tempdir().expect("a temporary folder");
    let mut images = Vec::new();
    let mut primary = Vec::new();
    for spectral in [SpectralSampling::Auto, SpectralSampling::Hero] {
        let out = dir.path().join(spectral.name());
        std::fs::create_dir_all(&out).expect("an output folder");
        let config = Config {
            out: Some(out.clone()),
            spectral,
            ..args()
        };
        let measured = bench_scene(&scene, &config, &pool())
            .expect("the furnace loads")
            .expect("nothing absent");
        primary.push(measured.primary.rays);
        images.push(std::fs::read(out.join("furnace.exr")).expect("the image"));
    }
    assert_eq!(
        primary[0], primary[1],
        "one camera ray per sample either way"
    );
    assert_ne!(
        images[0], images[1],
        "the always-spectral render is another estimate"
    );
}

/// `--effects all` measures the generic pipeline: every effect paid for, one path at a time,
/// and the same image as the scene's own effect set in lanes.
#[test]
fn forcing_every_effect_renders_the_same_image_one_path_at_a_time() {
    let scene =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.toml");
    let dir = tempfile::tempdir().expect("a temporary folder");
    let mut measured = Vec::new();
    for (name, effects) in [("auto", None), ("all", Some(tracer::Effects::ALL))] {
        let out = dir.path().join(name);
        std::fs::create_dir_all(&out).expect("an output folder");
        let config = Config {
            out: Some(out.clone()),
            effects,
            ..args()
        };
        let bench = bench_scene(&scene, &config, &pool())
            .expect("the box loads")
            .expect("nothing absent");
        let image = std::fs::read(out.join("cornell-box.exr")).expect("the image");
        measured.push((bench.effects, bench.path_lanes, image));
    }
    let (auto, all) = (&measured[0], &measured[1]);
    assert_eq!(
        auto.0, "area-lights,shadows,diffuse",
        "the box's own effects"
    );
    assert_eq!(all.0, tracer::Effects::ALL.to_string());
    assert!(auto.1 && !all.1, "lanes only where the effects allow them");
    assert!(auto.2 == all.2, "the same image either way");
}

#[test]
fn an_absent_mesh_is_skipped_and_a_malformed_scene_is_an_error() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let absent = dir.path().join("absent.toml");
    std::fs::write(
        &absent,
        "[camera]\nposition = [0, 0, 1]\nlook_at = [0, 0, 0]\n[[object]]\nobj = \"gone.obj\"\n",
    )
    .expect("writing a scene");
    let malformed = dir.path().join("malformed.toml");
    std::fs::write(&malformed, "[render]\nbogus = 1\n").expect("writing a scene");

    let skipped = bench_scene(&absent, &args(), &pool())
        .expect("absence is no error")
        .expect_err("skipped");
    assert!(
        skipped.reason.contains("gone.obj") && skipped.reason.ends_with("is absent"),
        "{}",
        skipped.reason
    );
    let error =
        bench_scene(&malformed, &args(), &pool()).expect_err("a malformed scene stops the bench");
    let mut chain = error.to_string();
    let mut cause = std::error::Error::source(&error);
    while let Some(next) = cause {
        chain += &format!(": {next}");
        cause = next.source();
    }
    assert!(chain.contains("bogus"), "{chain}");
}

#[test]
fn cpu_seconds_grow_while_this_process_works() {
    let before = process_cpu_seconds().expect("procfs is there on Linux");
    let started = Instant::now();
    let mut x = 1u64;
    while started.elapsed().as_secs_f64() < 0.1 {
        x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
    }
    let after = process_cpu_seconds().expect("procfs is there on Linux");
    assert!(after > before, "{before} -> {after}");
}

#[test]
fn resident_memory_grows_with_what_this_process_holds_and_the_peak_holds_it() {
    let before = process_status_kib("VmRSS").expect("procfs is there on Linux");
    // 256 MiB written, so resident: the reading must grow by about that much (by 200 MiB at
    // least, whatever the tests running beside this one free meanwhile).
    let held = std::hint::black_box(vec![1u8; 256 << 20]);
    let during = process_status_kib("VmRSS").expect("procfs is there on Linux");
    let peak = process_status_kib("VmHWM").expect("procfs is there on Linux");
    assert!(during >= before + 200 * 1024, "{before} -> {during} KiB");
    assert!(peak >= during, "peak {peak} below resident {during} KiB");
    assert_eq!(process_status_kib("NoSuchField"), None);
    drop(held);
}

#[test]
fn shipped_scenes_are_found_sorted() {
    let scenes = shipped_scenes(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes"))
        .expect("reading scenes/");
    assert!(
        scenes
            .iter()
            .any(|s| s.ends_with("cornell-box/cornell-box.toml"))
    );
    assert!(scenes.windows(2).all(|w| w[0] < w[1]));
}
