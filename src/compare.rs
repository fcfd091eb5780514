//! `tessera compare`: the arguments, and the metrics of [`lab::compare`] printed as text or JSON.

use std::path::PathBuf;

/// Compare two OpenEXR images: RMSE, relative MSE, mean absolute error, the largest difference,
/// per-channel means and mean FLIP. B is the reference.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The image under test (OpenEXR, linear RGB).
    pub a: PathBuf,
    /// The reference image (OpenEXR, linear RGB), e.g. another renderer's.
    pub b: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Compares the two files and prints the comparison.
pub fn run(args: &CompareArgs) -> anyhow::Result<()> {
    let comparison = lab::compare::compare_files(&args.a, &args.b)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&comparison)?);
    } else {
        print!("{}", comparison.text());
    }
    Ok(())
}
