//! The command line: `gast [COMMAND]`. No command opens the studio.

use std::path::PathBuf;

use clap::{Parser, Subcommand};

use crate::studio;

/// GAST Studio: geometry-aware style transfer on 3D Gaussian Splatting scenes.
#[derive(Debug, Parser)]
#[command(name = "gast", version)]
pub struct Cli {
    /// What to do; the studio when absent.
    #[command(subcommand)]
    pub command: Option<Commands>,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Commands {
    /// Open the studio window, optionally with a scene and a style image.
    Studio {
        /// A scene file (.ply); the demo scene when absent.
        scene: Option<PathBuf>,
        /// A style image; the first demo style when absent.
        style: Option<PathBuf>,
    },
    /// Regenerate the demo assets (scene, styles, icon) into a folder.
    Assets {
        /// Destination folder.
        #[arg(long, default_value = "assets")]
        out: PathBuf,
    },
    /// Measure the viewport's frame time on the first GPU adapter (headless).
    ViewportBench {
        /// A scene file; a synthetic scene of `--count` Gaussians when absent.
        scene: Option<PathBuf>,
        /// Gaussians in the synthetic scene.
        #[arg(long, default_value_t = 500_000)]
        count: usize,
        /// Frames to time.
        #[arg(long, default_value_t = 10)]
        frames: u32,
        /// Frame width in pixels.
        #[arg(long, default_value_t = 1280)]
        width: u32,
        /// Frame height in pixels.
        #[arg(long, default_value_t = 720)]
        height: u32,
    },
}

/// Parses the arguments and runs the command.
pub fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        None => studio::run(studio::StudioArgs::default()),
        Some(Commands::Studio { scene, style }) => studio::run(studio::StudioArgs { scene, style }),
        Some(Commands::Assets { out }) => {
            for p in studio::assets::generate(&out)? {
                println!("wrote {}", p.display());
            }
            Ok(())
        }
        Some(Commands::ViewportBench { scene, count, frames, width, height }) => {
            let report = studio::viewport::bench::run(scene.as_deref(), count, frames, width, height)?;
            println!("{report}");
            Ok(())
        }
    }
}
