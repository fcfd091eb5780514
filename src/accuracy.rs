//! `tessera accuracy`: the arguments, and [`lab::accuracy::run`] on them.

use lab::accuracy::{Cost, Knob, Rgb};
use std::path::PathBuf;

/// Measure what accuracy costs in time: render a scene over a ladder of values per accuracy knob
/// and write DIR/accuracy.csv, DIR/accuracy.md and DIR/accuracy.svg.
#[derive(Debug, clap::Args)]
pub struct AccuracyArgs {
    /// The scene file (TOML; see scenes/README.md).
    pub scene: PathBuf,
    /// Output folder; the cached reference (reference.exr and reference.json) lives here too.
    #[arg(long, default_value = "accuracy")]
    pub out: PathBuf,
    /// The top of the samples-per-pixel ladder 1, 2, 4, ... (rounded down to a power of two).
    #[arg(long, default_value_t = 1024)]
    pub max_spp: u32,
    /// Image width (default: 128 pixels on the scene's longer side, keeping its aspect ratio).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height (default: as for the width).
    #[arg(long)]
    pub height: Option<u32>,
    /// Samples per pixel of the depth, roulette, BVH and traversal ladders.
    #[arg(long, default_value_t = 64)]
    pub knob_spp: u32,
    /// Samples per pixel of the rendered reference (default: 4 x max-spp).
    #[arg(long)]
    pub reference_spp: Option<u32>,
    /// The exact mean radiance of every pixel, "R,G,B", for scenes that have one (a furnace):
    /// used as the reference instead of a render.
    #[arg(long, value_parser = parse_rgb)]
    pub analytic_mean: Option<Rgb>,
    /// Seed of the ladders' pixel sampler (default: the scene's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Which knobs to measure, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = Knob::ALL)]
    pub knobs: Vec<Knob>,
    /// Rays shot per traversal by the closed-sphere leak check.
    #[arg(long, default_value_t = 1 << 19)]
    pub leak_rays: u32,
    /// Renders (and BVH builds) faster than this many seconds are repeated and the fastest run
    /// kept, for times that scheduler noise and other processes disturb less; 0 times each once.
    #[arg(long, default_value_t = 1.0)]
    pub repeat_below: f64,
    /// Time every render (and BVH build) at least this many times and keep the fastest: on a
    /// machine busy with other work, more runs give steadier comparisons.
    #[arg(long, default_value_t = 1)]
    pub repeats: u32,
    /// What the comparisons (equal cost, efficiency, the plot) count as cost: wall time, or the
    /// tracer's counted work, which the machine's load does not change (for a shared machine).
    #[arg(long, value_enum, default_value_t = Cost::Time)]
    pub cost: Cost,
    /// Rendering threads (default: all cores).
    #[arg(long, value_parser = crate::cli::threads)]
    pub threads: Option<usize>,
}

/// Measures as the flags say.
pub fn run(args: &AccuracyArgs) -> anyhow::Result<()> {
    lab::accuracy::run(&lab::accuracy::Config {
        scene: args.scene.clone(),
        out: args.out.clone(),
        max_spp: args.max_spp,
        width: args.width,
        height: args.height,
        knob_spp: args.knob_spp,
        reference_spp: args.reference_spp,
        analytic_mean: args.analytic_mean,
        seed: args.seed,
        knobs: args.knobs.clone(),
        leak_rays: args.leak_rays,
        repeat_below: args.repeat_below,
        repeats: args.repeats,
        cost: args.cost,
        threads: args.threads,
        available_memory: runtime::node::limits::available_memory(),
        command: command_line(),
    })?;
    Ok(())
}

/// `--analytic-mean`: three values, or one for grey, each finite and not negative.
fn parse_rgb(text: &str) -> Result<Rgb, String> {
    let values: Vec<f32> = text
        .split(',')
        .map(|v| v.trim().parse::<f32>().map_err(|e| format!("`{v}`: {e}")))
        .collect::<Result<_, _>>()?;
    match values[..] {
        [r, g, b] if values.iter().all(|v| v.is_finite() && *v >= 0.0) => Ok(Rgb([r, g, b])),
        [v] if v.is_finite() && v >= 0.0 => Ok(Rgb([v; 3])),
        _ => Err("expected R,G,B (or one value for grey): finite and not negative".to_owned()),
    }
}

/// The command as a reader would retype it: `tessera` and the arguments given.
fn command_line() -> String {
    let args: Vec<String> = std::env::args().skip(1).collect();
    format!("tessera {}", args.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_parse_as_three_values_or_one() {
        assert_eq!(parse_rgb("1,0.5, 2").unwrap(), Rgb([1.0, 0.5, 2.0]));
        assert_eq!(parse_rgb("0.25").unwrap(), Rgb([0.25; 3]));
        assert!(parse_rgb("1,2").is_err());
        assert!(parse_rgb("1,-2,3").is_err());
        assert!(parse_rgb("1,nan,3").is_err());
    }
}
