//! `tessera meshes`: the arguments, and [`lab::meshes::write_meshes`] on them.

use std::path::PathBuf;

/// Write a scene's still triangles, as tessera loaded them, into a folder: one PLY file per
/// object and material, and `meshes.json`, which says each file's object, material and
/// attributes, for another renderer to trace exactly the same geometry.
#[derive(Debug, clap::Args)]
pub struct MeshesArgs {
    /// The scene file.
    pub scene: PathBuf,
    /// The folder to write into (made if missing; files of the same names are replaced).
    #[arg(long)]
    pub out: PathBuf,
}

/// Writes the meshes and prints how many files and triangles.
pub fn run(args: &MeshesArgs) -> anyhow::Result<()> {
    let index = lab::meshes::write_meshes(&args.scene, &args.out)?;
    let triangles: usize = index.iter().map(|m| m.triangles).sum();
    println!(
        "{} meshes, {triangles} triangles, indexed in {}",
        index.len(),
        args.out.join(lab::meshes::INDEX_FILE).display()
    );
    Ok(())
}
