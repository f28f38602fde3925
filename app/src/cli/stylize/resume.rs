//! `gast stylize --resume`: a run killed, crashed or stopped goes on from
//! the checkpoint beside its output (`stylized.checkpoint.ply`) with its
//! record (`stylized.checkpoint.json`: the step, the inputs, the views and
//! the settings), when this run's are the same, and with the optimiser's
//! state (`stylized.checkpoint.adam.safetensors`) where it was written.

use std::path::{Path, PathBuf};

use anyhow::Context;
use gast_core::style::StyleConfig;
use serde::{Deserialize, Serialize};

use super::StylizeArgs;
use crate::checkpoint;

/// What a stylization's checkpoint records beside its scene: enough to go
/// on (`--resume`) and to refuse going on with other inputs or settings.
#[derive(Serialize, Deserialize, Debug, PartialEq, Clone)]
pub struct Record {
    /// Steps done when the scene was written.
    pub step: u32,
    /// The scene stylized (its absolute path where it resolves) and its Gaussians.
    pub scene: PathBuf,
    pub gaussians: usize,
    /// The style image and the style depth's image or network, when given.
    pub style: PathBuf,
    /// The style image's bytes ([`checkpoint::file_fingerprint`]); `None` in
    /// a record written before it was kept, which then goes unchecked.
    #[serde(default)]
    pub style_file: Option<String>,
    pub style_depth: Option<PathBuf>,
    pub depth_model: Option<PathBuf>,
    /// The optimisation views: their number and a fingerprint of their poses and sizes.
    pub cameras: String,
    /// The settings the run was given (after its plan: the working
    /// resolution, texture scale and cycles it chose).
    pub config: StyleConfig,
    /// A CPU plan's re-plan of the cycles still to come (the checkpoint was
    /// written before the first cycle with a steady pace ended), which the
    /// resumed run makes in its place; `None` once made, or without a plan.
    #[serde(default)]
    pub replan: Option<PendingReplan>,
}

/// A re-plan still to come ([`Record::replan`]).
#[derive(Serialize, Deserialize, Debug, PartialEq, Clone, Copy)]
pub struct PendingReplan {
    /// The cycles asked for before the plan: the most a re-plan gives.
    pub most: u32,
    /// The plan's model's seconds a step.
    pub model_s: f64,
    /// Seconds of steps the run had taken.
    pub elapsed_s: f64,
}

impl Record {
    /// This run's record after `step` steps, its style file's bytes `style_file`.
    pub fn of(
        args: &StylizeArgs,
        style_file: Option<String>,
        gaussians: usize,
        cameras: &[gast_core::Camera],
        config: &StyleConfig,
        step: u32,
        replan: Option<PendingReplan>,
    ) -> Self {
        let absolute = |p: &Path| p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
        Self {
            step,
            scene: absolute(&args.scene),
            gaussians,
            style: absolute(&args.style),
            style_file,
            style_depth: args.style_depth.as_deref().map(absolute),
            depth_model: args.depth_model.as_deref().map(absolute),
            cameras: checkpoint::cameras_fingerprint(cameras),
            config: config.clone(),
            replan,
        }
    }
}

/// A checkpoint `--resume` goes on from: its record, and where it lies.
pub struct Resume {
    pub path: PathBuf,
    pub record: Record,
}

impl Resume {
    /// The checkpoint at `path` (beside the run's output) and its record; an
    /// error when either is missing or unreadable.
    pub fn read(args: &StylizeArgs, path: &Path) -> anyhow::Result<Self> {
        let record = checkpoint::read_record(&args.out.join(&args.scene_name), path, "stylization")?;
        Ok(Self { path: path.to_path_buf(), record })
    }

    /// Takes the recorded working resolution, texture scale and cycles where
    /// this run would choose them itself (their flags not given): the plan
    /// rests on a measure of this machine's speed, which may differ now.
    pub fn take_planned(&self, args: &StylizeArgs, config: &mut StyleConfig) {
        let from_preset = args.preset.is_some();
        if args.resolution.is_none() && !from_preset {
            config.resolution = self.record.config.resolution;
        }
        if args.texture_scale.is_none() && !from_preset {
            config.texture_scale = self.record.config.texture_scale;
        }
        if args.cycles.is_none() {
            config.cycles = self.record.config.cycles;
        }
    }

    /// Refuses other inputs or settings than the record's (`now`, at its step),
    /// naming each that differs; else reads the checkpoint's scene, which
    /// must hold the run's Gaussians (as many as the input, unless the run
    /// splits them).
    pub fn check_and_load(&self, now: &Record) -> anyhow::Result<gast_core::Gaussians> {
        // An older record without the style's bytes takes this run's.
        let style_file = if self.record.style_file.is_some() { now.style_file.clone() } else { None };
        let now = Record { step: self.record.step, replan: self.record.replan, style_file, ..now.clone() };
        checkpoint::refuse_other_settings(&self.path, &self.record, &now)?;
        let scene = gast_core::scene::load(&self.path)
            .with_context(|| format!("could not read the checkpoint {} to resume from", self.path.display()))?;
        if now.config.split_px == 0.0 && scene.len() != now.gaussians {
            anyhow::bail!(
                "{}: expected the run's {} Gaussians to resume from, found {}: not this run's checkpoint",
                self.path.display(),
                now.gaussians,
                scene.len()
            );
        }
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Another scene put in the checkpoint's place is refused before the
    /// run prepares, by its count.
    #[test]
    fn a_checkpoint_of_other_gaussians_is_refused_at_once() {
        let dir = std::env::temp_dir().join(format!("gast-resume-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a folder");
        let path = dir.join("stylized.checkpoint.ply");
        let two = gast_core::Gaussians {
            means: vec![[0.0; 3], [1.0; 3]],
            log_scales: vec![[-2.0; 3]; 2],
            quats: vec![[1.0, 0.0, 0.0, 0.0]; 2],
            opacity_logits: vec![0.0; 2],
            sh_degree: 0,
            sh: vec![0.5; 6],
        };
        gast_core::scene::save(&path, &two, &Default::default()).expect("written");
        let record = Record {
            step: 7,
            scene: "scene.ply".into(),
            gaussians: 3,
            style: "style.jpg".into(),
            style_file: None,
            style_depth: None,
            depth_model: None,
            cameras: "1 views, 0".into(),
            config: StyleConfig::default(),
            replan: None,
        };
        let resume = Resume { path: path.clone(), record: record.clone() };
        let e = resume.check_and_load(&Record { step: 0, ..record.clone() }).expect_err("refused").to_string();
        assert!(e.contains("expected the run's 3 Gaussians to resume from, found 2"), "{e}");
        let two_now = Record { gaussians: 2, ..record.clone() };
        let e = resume.check_and_load(&two_now).expect_err("refused").to_string();
        assert!(e.contains("gaussians: 3 then, 2 now"), "{e}");
        let resume = Resume { path: path.clone(), record: two_now.clone() };
        assert_eq!(resume.check_and_load(&two_now).expect("its own").len(), 2);
        // A re-plan still to come is the checkpoint's to hand on, not a setting that differs.
        let pending = PendingReplan { most: 30, model_s: 0.29, elapsed_s: 12.5 };
        let resume = Resume { path, record: Record { replan: Some(pending), ..two_now.clone() } };
        assert_eq!(resume.check_and_load(&two_now).expect("not refused").len(), 2);
        let json = serde_json::to_value(&resume.record).expect("json");
        assert_eq!(json["replan"]["most"], 30);
        // A record written before the field reads as one with no re-plan to come.
        let mut older = serde_json::to_value(&two_now).expect("json");
        older.as_object_mut().expect("an object").remove("replan");
        assert_eq!(serde_json::from_value::<Record>(older).expect("reads"), two_now);
        // Another image written under the style's name is refused, saying
        // so; a record written before the style's bytes were kept goes on.
        let style = dir.join("style.png");
        std::fs::write(&style, b"one image").expect("written");
        let kept = Record { style_file: checkpoint::file_fingerprint(&style), ..two_now.clone() };
        std::fs::write(&style, b"another one").expect("written");
        let now = Record { style_file: checkpoint::file_fingerprint(&style), ..two_now.clone() };
        assert!(kept.style_file.as_deref().is_some_and(|f| f.starts_with("9 bytes, ")), "{kept:?}");
        let resume = Resume { path: resume.path.clone(), record: kept };
        let e = resume.check_and_load(&now).expect_err("refused").to_string();
        assert!(e.contains("style_file: \"9 bytes, ") && e.contains("\"11 bytes, "), "{e}");
        let resume = Resume { path: resume.path.clone(), record: two_now.clone() };
        assert_eq!(resume.check_and_load(&now).expect("an older record").len(), 2);
        std::fs::remove_dir_all(&dir).ok();
    }
}
