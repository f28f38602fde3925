//! The flags of `gast stylize` (shared with `bench step` and `check golden`
//! through [`FastArgs`]) and the configuration they make.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use gast_core::gpu::DeviceChoice;
use gast_core::style::config::LossWeights;
use gast_core::style::terms::{TERMS, Term};
use gast_core::style::{Focus, MatchMethod, MeanSteps, Mode, StyleConfig};
use gast_core::vision::ConvAlgo;
use gast_core::vision::style_depth::{DepthPolarity, DepthProvider};

use crate::views::Framing;

/// Arguments of `gast stylize`.
#[derive(Args, Debug)]
pub struct StylizeArgs {
    /// The scene: INRIA .ply, .compressed.ply, .spz, or a SOG folder.
    pub scene: PathBuf,
    /// The style image (PNG, JPEG, WebP): at least 4×4 pixels, no side more than 8 times the other.
    pub style: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "out/stylize")]
    pub out: PathBuf,
    /// File name of the stylized scene inside the output folder (a name, not a
    /// path); its ending picks the format: .ply, .compressed.ply, .spz, .sog,
    /// or a SOG folder (ending in /).
    #[arg(long, default_value = "stylized.ply")]
    pub scene_name: PathBuf,
    #[command(flatten)]
    pub save: super::super::convert::SaveArgs,
    /// How much of the stylization the written scene keeps (the colour-matched
    /// scene, written beside it as colour_matched.ply, is 0%).
    #[command(flatten)]
    pub strength: super::super::convert::StrengthArgs,
    /// Optimisation cameras (COLMAP sparse/0, an LLFF poses_bounds.npy or its folder, cameras.json, transforms.json);
    /// without it, the cameras beside the scene (its folder's, as `gast fit`
    /// writes them, or an INRIA model folder's cameras.json), else `--views`
    /// orbit views generated around the scene.
    #[arg(long)]
    pub cameras: Option<PathBuf>,
    /// Generate orbit views even when the scene's folder holds cameras.
    #[arg(long, conflicts_with = "cameras")]
    pub orbit: bool,
    /// Number of generated orbit views, 1 to 3,600 (when no cameras are read).
    #[arg(long, default_value_t = 36, value_parser = crate::views::view_count::<usize>())]
    pub views: usize,
    /// Vertical field of view of generated views, degrees (1 to 170).
    #[arg(long, default_value_t = 50.0, value_parser = crate::views::fov_degrees)]
    pub fov: f32,
    /// Generated views: `object` fits each view to the object (it spans 90% of
    /// the longer side), `full` is the plain orbit around its bounding sphere.
    #[arg(long, value_enum, default_value_t = Framing::Object)]
    pub framing: Framing,
    /// With --cameras: crop each view to the region the object covers.
    #[arg(long)]
    pub crop: bool,
    /// A preset file (JSON StyleConfig), or `paper` for the reference's
    /// behaviour (whole-frame losses, style depth near dark, no object
    /// recipe); flags below override it.
    #[arg(long)]
    pub preset: Option<PathBuf>,
    /// Keep the object recipe off (by default, with the losses on the object,
    /// the run uses λ_asc 10 and λ_as 0.015, the focus study's winner, when
    /// both are 0, and the palette hold λ_pal 100, which keeps the object's
    /// colour-matched brightness, when λ_pal is 0).
    #[arg(long)]
    pub no_object_recipe: bool,
    /// Keep the depth's sliced Wasserstein term off on full-frame scenes (by
    /// default, with the losses on the whole frame and λ_swd = 0, the run
    /// uses λ_swd 1: the style's relief in the depth, docs/geometry.md).
    #[arg(long)]
    pub no_frame_recipe: bool,
    /// Write the effective configuration to this preset file and continue
    /// (an existing file is replaced only if it is a preset).
    #[arg(long)]
    pub save_preset: Option<PathBuf>,
    /// VGG weights (.safetensors or .pth); else $GAST_WEIGHTS, the caches, or a download.
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// A depth image for the style (PNG 8/16-bit or EXR); implies `--depth-provider image`.
    #[arg(long)]
    pub style_depth: Option<PathBuf>,
    /// Where the style's depth comes from: learned (Depth Anything V2), image (`--style-depth`)
    /// or heuristic [default: learned, or image with `--style-depth`].
    #[arg(long, value_parser = DepthProvider::parse)]
    pub depth_provider: Option<DepthProvider>,
    /// Depth Anything V2 checkpoint: a folder with model.safetensors and config.json, or the
    /// file; else $GAST_DEPTH_MODEL, the caches, or a one-time download of the Small model.
    #[arg(long)]
    pub depth_model: Option<PathBuf>,
    /// Cycles K [default: 30; a planned CPU run (no --resolution or --preset)
    /// takes the cycles that fit about 10 min, set again after its first cycle
    /// from the measured pace].
    #[arg(long)]
    pub cycles: Option<u32>,
    /// Steps per cycle N_c + N_g [default: 100].
    #[arg(long)]
    pub steps_per_cycle: Option<u32>,
    /// Geometry share of a cycle N_g / (N_c + N_g) [default: 0.9].
    #[arg(long)]
    pub ratio_geo: Option<f32>,
    /// decoupled, joint, color-only or geometry-only [default: decoupled].
    #[arg(long)]
    pub mode: Option<Mode>,
    /// Texture scale: the style's height in pixels (128, 256, 512 = 0.5x, 1x, 2x) [default: 256; with
    /// whole-frame losses and without --preset, scaled with the working resolution as the reference's 256 px
    /// at its 1,008: 64 px at 256, 128 at 504].
    #[arg(long)]
    pub texture_scale: Option<u32>,
    /// Working resolution: longer side of the optimisation renders [default:
    /// follows the object: the smallest size (a multiple of 32) at which it
    /// spans 64 relu3 positions across its longer side, at most the size where a
    /// CPU step takes about 1 s; on a 2-core CPU a step with the object focus
    /// takes about 0.29 s at 256 px, 0.58 s at 384 px and 0.94 s at 512 px;
    /// with whole-frame losses 0.30 s at 256 px and 1.2 s at 512 px (0.57 and
    /// 2.3 s with --texture-scale 256 kept at any resolution), for a scene of
    /// about 100,000 Gaussians: each million more adds about 1.2 s. Without
    /// this or --preset, a CPU run is planned to about 10 min, taking fewer
    /// cycles unless --cycles is given, and after its first cycle takes the
    /// cycles its measured pace fits, up to --cycles' default].
    #[arg(long)]
    pub resolution: Option<u32>,
    /// One flag per loss weight (`--lambda-gc`, …), from `gast_core::style::terms`.
    #[command(flatten)]
    pub loss_weights: WeightFlags,
    /// Which steps λ_mean acts on: every, or colour (the colour steps only;
    /// the geometry steps follow GCFM alone) [default: every].
    #[arg(long, value_name = "colour|every")]
    pub mean_steps: Option<MeanSteps>,
    /// Learning rate of the SH DC colour [default: 0.01].
    #[arg(long)]
    pub lr_color: Option<f32>,
    /// Learning rate of the means, times the scene extent [default: 1e-4].
    #[arg(long)]
    pub lr_means: Option<f32>,
    /// Learning rate of the log-scales [default: 0.005].
    #[arg(long)]
    pub lr_scales: Option<f32>,
    /// Learning rate of the quaternions [default: 0.001].
    #[arg(long)]
    pub lr_quats: Option<f32>,
    /// Learning rate of the opacity logits [default: 0.05].
    #[arg(long)]
    pub lr_opacity: Option<f32>,
    /// Style depth polarity: near-bright (like the rendered inverse depth) or
    /// near-dark (the reference implementation's) [default: near-bright].
    #[arg(long, value_parser = parse_polarity)]
    pub depth_polarity: Option<DepthPolarity>,
    /// Seed of the view order [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Convolution and matching choices.
    #[command(flatten)]
    pub fast: FastArgs,
    /// Where GCFM, content and TV look: frame (every pixel, the paper), object
    /// (the pixels the scene covers), auto (object when the scene covers less
    /// than half of the views) [default: auto].
    #[arg(long)]
    pub focus: Option<Focus>,
    /// Keep colours out of the clamp's dead zone: after each colour step no
    /// channel of a Gaussian's base colour goes below 0 [default: off].
    #[arg(long)]
    pub color_floor: Option<bool>,
    /// The parameter regularisers' form: norm (the paper's λ‖x − x^c‖ over all
    /// Gaussians, which holds opacity, scale and rotation unless the loss's pull
    /// over all Gaussians exceeds λ) or mean-square (λ·mean over Gaussians of
    /// ‖x_i − x_i^c‖², a tether that grows with each Gaussian's own change)
    /// [default: norm].
    #[arg(long)]
    pub param_regulariser: Option<gast_core::style::config::ParamRegulariser>,
    /// Carry the colour steps' geometry gradients (and the geometry steps'
    /// colour gradients) over to the other phase's next step, as the
    /// reference's code does: their sum over a cycle's colour steps is
    /// applied on its first geometry step [default: off].
    #[arg(long)]
    pub phase_leak: Option<bool>,
    /// Split every Gaussian whose standard deviation spans more than this
    /// many pixels in some view (at the working resolution) in two, repeatedly,
    /// before optimising: room for the style's relief on large smooth
    /// surfaces, at up to 8× the Gaussians. 0 keeps the scene [default: 0].
    #[arg(long)]
    pub split_px: Option<f32>,
    /// Compare the depth's relief with the style depth's: both depth maps
    /// minus their blur of this radius (px), centred on 0.5, before VGG, so
    /// an object's layout and silhouette do not take the 0–1 range. 0 is the
    /// paper's min-max normalised depth [default: 0].
    #[arg(long, value_name = "PX")]
    pub depth_relief: Option<u32>,
    /// Views rendered before/after into the output folder.
    #[arg(long, default_value_t = 4)]
    pub preview_views: usize,
    /// Where the optimisation runs: auto (a hardware GPU when there is one,
    /// else the CPU), cpu, or gpu (any adapter, software ones included).
    #[arg(long, default_value_t = DeviceChoice::Auto)]
    pub device: DeviceChoice,
    /// Every this many seconds of steps, and at Ctrl-C, write the stylized
    /// scene as it stands to `stylized.checkpoint.ply` in the output folder
    /// (INRIA .ply, named after --scene-name) with its record
    /// (`stylized.checkpoint.json`) and the optimiser's state
    /// (`stylized.checkpoint.adam.safetensors`), so a run killed or crashed
    /// keeps what it had and `--resume` goes on from it; removed once the
    /// scene is written. 0: none between (Ctrl-C still writes one).
    #[arg(long, default_value_t = crate::checkpoint::DEFAULT_CHECKPOINT_S,
          value_parser = crate::views::within(crate::checkpoint::CHECKPOINT_SECONDS))]
    pub checkpoint_every: u64,
    /// Go on from the checkpoint in the output folder, left by a run of the
    /// same command that was killed, crashed or stopped with Ctrl-C: the
    /// steps go on from its step, with the views, phases and optimiser
    /// state the whole run would have had (fresh moments, said so, where the
    /// state file is missing or unreadable). Refused, naming
    /// what differs, when the scene, style, views or settings are not the
    /// checkpoint's; the working resolution, texture scale and cycles the
    /// first run planned are taken from it.
    #[arg(long)]
    pub resume: bool,
}

impl StylizeArgs {
    /// The preset (if any) with the flags applied.
    pub fn config(&self) -> anyhow::Result<StyleConfig> {
        let mut c = match &self.preset {
            Some(p) if p.as_os_str() == "paper" && !p.exists() => StyleConfig::paper(),
            Some(p) => {
                let text =
                    std::fs::read_to_string(p).with_context(|| format!("could not read the preset {}", p.display()))?;
                StyleConfig::from_json(&text)
                    .with_context(|| format!("{}: expected a StyleConfig JSON preset", p.display()))?
            }
            None => StyleConfig::default(),
        };
        macro_rules! set {
            ($flag:expr, $field:expr) => {
                if let Some(v) = $flag {
                    $field = v;
                }
            };
        }
        if self.no_object_recipe {
            c.object_recipe = false;
        }
        if self.no_frame_recipe {
            c.frame_recipe = false;
        }
        set!(self.cycles, c.cycles);
        set!(self.steps_per_cycle, c.steps_per_cycle);
        set!(self.ratio_geo, c.ratio_geo);
        set!(self.mode, c.mode);
        set!(self.texture_scale, c.texture_scale);
        set!(self.resolution, c.resolution);
        self.loss_weights.apply(&mut c.weights);
        set!(self.mean_steps, c.feature_mean_steps);
        set!(self.lr_color, c.lr.color);
        set!(self.lr_means, c.lr.means_per_extent);
        set!(self.lr_scales, c.lr.scales);
        set!(self.lr_quats, c.lr.quats);
        set!(self.lr_opacity, c.lr.opacity);
        set!(self.depth_polarity, c.depth_polarity);
        if self.style_depth.is_some() {
            c.depth_provider = DepthProvider::Image;
        }
        set!(self.depth_provider, c.depth_provider);
        set!(self.seed, c.seed);
        self.fast.apply(&mut c);
        set!(self.focus, c.focus);
        set!(self.color_floor, c.color_floor);
        set!(self.param_regulariser, c.param_regulariser);
        set!(self.phase_leak, c.phase_leak);
        set!(self.split_px, c.split_px);
        set!(self.depth_relief, c.depth_relief_px);
        // A preset's bad value would otherwise read as if a flag had set it.
        crate::cli::checked(c).map_err(|e| match &self.preset {
            Some(p) if p.is_file() => e.context(format!("{} with the flags", p.display())),
            _ => e,
        })
    }
}

/// The choices of issue 10 (fewer operations per step), shared by `stylize` and `bench step`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct FastArgs {
    /// Most rows of one least-cost block of the assignment terms' pairing (16 to 512): a step
    /// pairs up to 512 drawn positions one-to-one, serial host work that grows as the cube of
    /// the rows, so more rows than this are dealt into blocks paired on their own, in parallel
    /// (the pairs cost about 2% more at 256 than in one block); 512 pairs them all at once
    /// [default: 256].
    #[arg(long)]
    pub assign_block: Option<u32>,
    /// VGG convolutions: im2col (the reference) or winograd (4× fewer multiplies, exact) [default: winograd].
    #[arg(long)]
    pub conv: Option<ConvAlgo>,
    /// GCFM matching: exact, or pca (a principal-subspace index with exact re-ranking) [default: exact].
    #[arg(long)]
    pub matching: Option<MatchMethod>,
    /// Dimensions the pca index keeps, of 2304 [default: 128].
    #[arg(long)]
    pub matching_dims: Option<u32>,
    /// Candidates the pca index re-ranks exactly per position, nearest and farthest each [default: 32].
    #[arg(long)]
    pub matching_candidates: Option<u32>,
    /// Visits of a view that share one search of its matches (1: search every step) [default: 1].
    #[arg(long)]
    pub matching_reuse: Option<u32>,
    /// With object focus, run VGG only on what the object's feature positions depend on: their
    /// receptive-field window and, inside it on the CPU, the cone of their box (true), or on the whole
    /// frame (false); the same losses up to rounding either way [default: true].
    #[arg(long)]
    pub vgg_window: Option<bool>,
}

impl FastArgs {
    /// Writes the given flags into `c`.
    pub fn apply(&self, c: &mut StyleConfig) {
        let pairs = [
            (self.matching_dims, &mut c.matching.dims),
            (self.matching_candidates, &mut c.matching.candidates),
            (self.matching_reuse, &mut c.matching.reuse),
        ];
        for (flag, field) in pairs {
            if let Some(v) = flag {
                *field = v;
            }
        }
        c.conv = self.conv.unwrap_or(c.conv);
        c.vgg_window = self.vgg_window.unwrap_or(c.vgg_window);
        c.assign_block = self.assign_block.unwrap_or(c.assign_block);
        c.matching.method = self.matching.unwrap_or(c.matching.method);
    }
}

fn parse_polarity(s: &str) -> Result<DepthPolarity, String> {
    match s {
        "near-bright" => Ok(DepthPolarity::NearBright),
        "near-dark" | "reference" => Ok(DepthPolarity::NearDark),
        _ => Err(format!("expected near-bright or near-dark, found {s:?}")),
    }
}

/// The loss weights given on the command line: one flag per term of
/// [`TERMS`] (its `flag`, `symbol` and `help`), so a new term gets its flag
/// from its row in the table.
#[derive(Clone, Debug, Default)]
pub struct WeightFlags(pub Vec<(&'static Term, f32)>);

impl WeightFlags {
    /// Sets the given weights in `w`.
    pub fn apply(&self, w: &mut LossWeights) {
        for (t, v) in &self.0 {
            *(t.weight)(w) = *v;
        }
    }
}

impl clap::FromArgMatches for WeightFlags {
    fn from_arg_matches(m: &clap::ArgMatches) -> Result<Self, clap::Error> {
        let mut flags = Self::default();
        flags.update_from_arg_matches(m)?;
        Ok(flags)
    }

    fn update_from_arg_matches(&mut self, m: &clap::ArgMatches) -> Result<(), clap::Error> {
        for t in &TERMS {
            if let Some(&v) = m.get_one::<f32>(t.flag) {
                self.0.retain(|(x, _)| x.key != t.key);
                self.0.push((t, v));
            }
        }
        Ok(())
    }
}

impl clap::Args for WeightFlags {
    fn augment_args(cmd: clap::Command) -> clap::Command {
        let defaults = LossWeights::default();
        TERMS.iter().fold(cmd, |cmd, t| {
            let default = match t.get(&defaults) {
                0.0 => "0, off".to_string(),
                v => format!("{v}"),
            };
            cmd.arg(
                clap::Arg::new(t.flag)
                    .long(t.flag)
                    .value_name("WEIGHT")
                    .value_parser(clap::value_parser!(f32))
                    .help(format!("{}, {} [default: {default}]", t.symbol, t.help)),
            )
        })
    }

    fn augment_args_for_update(cmd: clap::Command) -> clap::Command {
        Self::augment_args(cmd)
    }
}
