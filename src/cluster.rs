//! `tessera keygen` and `tessera peer`: the two commands of a real cluster besides `serve`.

use crate::cli::{KeygenArgs, PeerArgs};
use anyhow::Context;
use runtime::net::{ClusterCerts, PeerIdentity};
use runtime::node;
use std::path::Path;

pub fn keygen(args: &KeygenArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.peers >= 2,
        "a cluster needs the owner (peer 0) and at least one peer"
    );
    let certs = ClusterCerts::generate(args.peers)?;
    certs
        .write_pem(&args.out)
        .with_context(|| format!("writing certificates to {}", args.out.display()))?;
    println!(
        "wrote a cluster CA and {} peer certificates to {}: give peer 0 to `tessera serve`, peer K to the K-th `tessera peer --index K`; keep ca-key.pem private",
        args.peers,
        args.out.display()
    );
    Ok(())
}

pub fn peer(args: &PeerArgs) -> anyhow::Result<()> {
    let index = match args.index {
        Some(index) => index,
        None => only_peer_index(&args.certs)?,
    };
    anyhow::ensure!(
        index >= 1,
        "peer 0 is the frame owner's certificate; peers use 1 and up"
    );
    let identity = PeerIdentity::load(&args.certs, index).with_context(|| {
        format!(
            "loading peer {index}'s certificate from {}",
            args.certs.display()
        )
    })?;
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let options = node::Options {
        threads,
        ..node::Options::default()
    };
    let tokio = crate::render::tokio_runtime()?;
    tracing::info!("peer {index} joining {} with {threads} threads", args.join);
    let tiles = tokio.block_on(node::run_peer(args.join, args.listen, &identity, options))?;
    println!(
        "peer {index}: rendered {} tiles; the render is over",
        tiles.len()
    );
    Ok(())
}

/// The K of the only `peer-K-key.pem` (K >= 1) in `dir`.
fn only_peer_index(dir: &Path) -> anyhow::Result<u32> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let name = entry?.file_name().to_string_lossy().into_owned();
        if let Some(k) = name
            .strip_prefix("peer-")
            .and_then(|n| n.strip_suffix("-key.pem"))
            && let Ok(k) = k.parse::<u32>()
            && k >= 1
        {
            found.push(k);
        }
    }
    found.sort_unstable();
    match found.as_slice() {
        [k] => Ok(*k),
        [] => anyhow::bail!("no peer-K-key.pem (K >= 1) in {}", dir.display()),
        many => anyhow::bail!(
            "{} holds keys of peers {many:?}: say which with --index",
            dir.display()
        ),
    }
}
