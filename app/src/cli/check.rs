//! `gast check golden`: the project's numerics against reference files.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use gast_core::golden::{CheckContext, check_file};
use gast_core::vision::ConvAlgo;

/// Arguments of `gast check golden`.
#[derive(Args, Debug)]
pub struct GoldenArgs {
    /// Golden files (safetensors, float64): raster_*, losses_*, color_*,
    /// depth/depth_*; a folder stands for every .safetensors file under it.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// VGG weights for losses_* files (else $GAST_WEIGHTS, the caches, or a download).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Where the rasterizer and the losses run: cpu, gpu (any adapter, lavapipe
    /// included), or auto (a hardware GPU when there is one, else the CPU).
    /// The colour transfer runs on the CPU either way.
    #[arg(long, default_value_t = gast_core::gpu::DeviceChoice::Cpu)]
    pub device: gast_core::gpu::DeviceChoice,
    /// VGG convolutions for losses_* files: im2col or winograd.
    #[arg(long, default_value_t = ConvAlgo::Im2col)]
    pub conv: ConvAlgo,
}

/// Checks every file and prints one line per output; fails when any output is out of tolerance.
pub fn run_golden(args: GoldenArgs) -> anyhow::Result<ExitCode> {
    let gpu = args.device.resolve().map_err(|e| anyhow::anyhow!("--device {}: {e}", args.device))?;
    println!("device: {}", gpu.as_ref().map_or_else(|| "CPU".to_owned(), |g| g.describe()));
    let ctx = CheckContext { weights: args.weights.clone(), gpu, conv: args.conv };
    let mut failed = 0usize;
    let mut total = 0usize;
    for file in &expand_folders(&args.files) {
        println!("{}", file.display());
        if file.is_dir() {
            failed += 1;
            println!("  error: {}: expected golden files (.safetensors) in this folder, found none", file.display());
            continue;
        }
        match check_file(file, &ctx) {
            Ok(checks) => {
                for c in checks {
                    total += 1;
                    if !c.passed {
                        failed += 1;
                    }
                    println!(
                        "  {:<28} max abs {:>10.3e}  max |ref| {:>10.3e}  rel {:>10.3e}  ({:<12}) {}",
                        c.name,
                        c.max_abs,
                        c.max_ref,
                        c.rel,
                        c.tolerance.to_string(),
                        if c.passed { "ok" } else { "FAIL" }
                    );
                }
            }
            Err(e) => {
                failed += 1;
                println!("  error: {e}");
            }
        }
    }
    println!("{} passed, {} failed", total.saturating_sub(failed), failed);
    Ok(if failed == 0 { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

/// `paths` with each folder replaced by the `.safetensors` files under it
/// (sorted, subfolders included); a folder with none stays, so its error is
/// printed.
fn expand_folders(paths: &[PathBuf]) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        let mut entries: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "safetensors") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    for p in paths {
        let before = out.len();
        if p.is_dir() {
            walk(p, &mut out);
        }
        if out.len() == before {
            out.push(p.clone());
        }
    }
    out
}
