//! The loss terms described once. Each [`Term`] names its weight's preset
//! key, command-line flag, symbol, help line, slider range, chart line and the
//! engines that compute it; the flags of `gast stylize`, the studio's
//! sliders and loss chart, the contact sheet's settings line, the preset
//! check and the GPU engine's refusal all read [`TERMS`]. A new term adds its
//! formula and kernel(s), a field in [`LossWeights`] and [`LossTerms`], and
//! one row here (`docs/ARCHITECTURE.md`, "Adding a loss term").

use serde::{Deserialize, Serialize};

/// Loss weights (λ of ALGORITHM.md).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LossWeights {
    /// λ_GC, the geometry-aware contrastive feature matching.
    pub gcfm: f32,
    /// λ_cont, the content feature loss.
    pub content: f32,
    /// λ_TV, total variation of the rendered RGB.
    pub tv: f32,
    /// λ_α, opacity-logit regulariser (geometry phase).
    pub opacity: f32,
    /// λ_s, log-scale regulariser (geometry phase).
    pub scale: f32,
    /// λ_r, quaternion regulariser (geometry phase).
    pub rotation: f32,
    /// λ_d, inverse-depth regulariser (geometry phase).
    pub depth: f32,
    /// λ_mean, the feature-mean term ([`crate::style::feature_mean`]): the
    /// mean of the rendered RGB relu3 features over the positions the losses
    /// average over, pulled toward the style's. Not in the reference: 0 (off)
    /// by default. Both engines.
    pub feature_mean: f32,
    /// λ_out, the background hold ([`crate::style::outside`]): with object
    /// focus, the pixels the colour-matched scene leaves empty keep its
    /// render. Not in the reference: 0 (off) by default. Both engines.
    pub outside: f32,
    /// λ_pal, the palette hold ([`crate::style::palette`]): with object
    /// focus, the covered pixels' per-channel mean and deviation keep the
    /// colour-matched render's. Not in the reference: 0 by default, which
    /// the object recipe lifts on objects
    /// (`OBJECT_RECIPE_PALETTE` of [`crate::style::config`]).
    /// Both engines.
    #[serde(default)]
    pub palette: f32,
    /// λ_sw, the sliced Wasserstein term ([`crate::style::sliced`]): the
    /// distribution of the rendered RGB relu3 features over the positions the
    /// losses average over, pulled toward the style's along fixed random
    /// directions. Not in the reference: 0 (off) by default. CPU engine.
    pub sliced: f32,
    /// λ_swd, the same sliced Wasserstein term on the depth map's relu3
    /// features against the style depth's, on the steps that take the
    /// depth's gradient (geometry steps): GCFM's nearest neighbours are
    /// content with any fine depth texture, this asks for the style depth's
    /// whole distribution of features (its plateaus and its edges in their
    /// proportions). Not in the reference: 0 (off) by default. CPU engine.
    #[serde(default)]
    pub sliced_depth: f32,
    /// λ_as, the assignment term ([`crate::style::assignment`]): each
    /// rendered RGB relu3 feature over the positions the losses average over
    /// pulled to a distinct style feature, by a least-cost one-to-one
    /// assignment to a fresh sample of the style's features each step. Not in
    /// the reference: 0 (off) by default. Both engines.
    pub assignment: f32,
    /// λ_asc, the cosine assignment term ([`crate::style::assignment`]): the
    /// same pairing, made by cosine distance, pulling each feature's
    /// direction to its partner's (`1 − cos`). With it on, λ_as pulls along
    /// the cosine pairing. Not in the reference: 0 (off) by default. Both
    /// engines.
    pub assignment_cosine: f32,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            gcfm: 2.0,
            content: 1e-3,
            tv: 0.02,
            opacity: 1.0,
            scale: 1.0,
            rotation: 1.0,
            depth: 10.0,
            feature_mean: 0.0,
            outside: 0.0,
            palette: 0.0,
            sliced: 0.0,
            sliced_depth: 0.0,
            assignment: 0.0,
            assignment_cosine: 0.0,
        }
    }
}

/// Each loss term of a step, unweighted, and the weighted total.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LossTerms {
    /// Weighted sum of all terms of the step.
    pub total: f32,
    /// GCFM (contrastive feature matching).
    pub gcfm: f32,
    /// Content feature loss.
    pub content: f32,
    /// Total variation.
    pub tv: f32,
    /// ‖o − o^c‖₂ (geometry steps).
    pub reg_opacity: f32,
    /// ‖s − s^c‖₂ (geometry steps).
    pub reg_scale: f32,
    /// ‖q − q^c‖₂ (geometry steps).
    pub reg_rotation: f32,
    /// mean|D − D^c| (geometry steps).
    pub depth: f32,
    /// The feature-mean term (0 when λ_mean is 0).
    #[serde(default)]
    pub feature_mean: f32,
    /// The background hold (0 when λ_out is 0 or the focus is the frame).
    #[serde(default)]
    pub outside: f32,
    /// The palette hold (0 when λ_pal is 0 or the focus is the frame).
    #[serde(default)]
    pub palette: f32,
    /// The sliced Wasserstein term (0 when λ_sw is 0).
    #[serde(default)]
    pub sliced: f32,
    /// The sliced Wasserstein term on the depth features (0 when λ_swd is 0 or on colour steps).
    #[serde(default)]
    pub sliced_depth: f32,
    /// The assignment term, squared distance (0 when λ_as and λ_asc are 0).
    #[serde(default)]
    pub assignment: f32,
    /// The assignment term, cosine distance (0 when λ_as and λ_asc are 0).
    #[serde(default)]
    pub assignment_cosine: f32,
}

/// One loss term: where its weight lives and how every front end shows it.
#[derive(Clone, Copy, Debug)]
pub struct Term {
    /// The weight's field in [`LossWeights`] and its preset key (`weights.<key>`).
    pub key: &'static str,
    /// The command-line flag without its dashes (`--lambda-gc`).
    pub flag: &'static str,
    /// The symbol on sliders, sheets and tables (`λ_GC`).
    pub symbol: &'static str,
    /// The loss chart's name of the term's value.
    pub chart: &'static str,
    /// What it does, for `--help` and the slider's hover text.
    pub help: &'static str,
    /// The slider's upper end (a logarithmic slider from 0).
    pub max: f32,
    /// Whether the GPU engine computes it (the CPU engine computes them all).
    pub gpu: bool,
    /// Whether the paper has it (the others are off by default).
    pub paper: bool,
    /// The weight in a set of weights.
    pub weight: fn(&mut LossWeights) -> &mut f32,
    /// The term's unweighted value in a step's [`LossTerms`].
    pub value: fn(&LossTerms) -> f32,
}

impl Term {
    /// This term's weight in `w`.
    pub fn get(&self, w: &LossWeights) -> f32 {
        let mut w = *w;
        *(self.weight)(&mut w)
    }

    /// The term's short name, the help's first words up to its first comma
    /// or colon ("palette hold"), for lines that list terms with their values.
    pub fn name(&self) -> &'static str {
        self.help.split([',', ':']).next().unwrap_or(self.key)
    }

    /// The term by its preset key or flag.
    pub fn find(name: &str) -> Option<&'static Term> {
        TERMS.iter().find(|t| t.key == name || t.flag == name)
    }
}

/// Every loss term, in the order of the sliders and the chart.
pub static TERMS: [Term; 14] = [
    Term {
        key: "gcfm",
        flag: "lambda-gc",
        symbol: "λ_GC",
        chart: "GCFM",
        help: "geometry-aware contrastive feature matching (RGB, depth and edge relu3 features against the style's)",
        max: 20.0,
        gpu: true,
        paper: true,
        weight: |w| &mut w.gcfm,
        value: |l| l.gcfm,
    },
    Term {
        key: "content",
        flag: "lambda-content",
        symbol: "λ_cont",
        chart: "content",
        help: "content: relu3 features of the render against the colour-matched scene's",
        max: 1.0,
        gpu: true,
        paper: true,
        weight: |w| &mut w.content,
        value: |l| l.content,
    },
    Term {
        key: "tv",
        flag: "lambda-tv",
        symbol: "λ_TV",
        chart: "TV",
        help: "total variation of the rendered RGB",
        max: 1.0,
        gpu: true,
        paper: true,
        weight: |w| &mut w.tv,
        value: |l| l.tv,
    },
    Term {
        key: "opacity",
        flag: "lambda-opacity",
        symbol: "λ_α",
        chart: "reg α",
        help: "opacity regulariser, geometry steps (its form: --param-regulariser)",
        max: 10.0,
        gpu: true,
        paper: true,
        weight: |w| &mut w.opacity,
        value: |l| l.reg_opacity,
    },
    Term {
        key: "scale",
        flag: "lambda-scale",
        symbol: "λ_s",
        chart: "reg s",
        help: "scale regulariser, geometry steps (its form: --param-regulariser)",
        max: 10.0,
        gpu: true,
        paper: true,
        weight: |w| &mut w.scale,
        value: |l| l.reg_scale,
    },
    Term {
        key: "rotation",
        flag: "lambda-rotation",
        symbol: "λ_r",
        chart: "reg r",
        help: "rotation regulariser, geometry steps (its form: --param-regulariser)",
        max: 10.0,
        gpu: true,
        paper: true,
        weight: |w| &mut w.rotation,
        value: |l| l.reg_rotation,
    },
    Term {
        key: "depth",
        flag: "lambda-depth",
        symbol: "λ_d",
        chart: "depth",
        help: "inverse-depth regulariser mean|D − D^c|, geometry steps",
        max: 100.0,
        gpu: true,
        paper: true,
        weight: |w| &mut w.depth,
        value: |l| l.depth,
    },
    Term {
        key: "feature_mean",
        flag: "lambda-mean",
        symbol: "λ_mean",
        chart: "mean",
        help: "feature mean, not in the paper: pulls the mean relu3 feature of the render (the object's with \
               object focus) toward the style's (--mean-steps picks the steps)",
        max: 1000.0,
        gpu: true,
        paper: false,
        weight: |w| &mut w.feature_mean,
        value: |l| l.feature_mean,
    },
    Term {
        key: "outside",
        flag: "lambda-outside",
        symbol: "λ_out",
        chart: "hold",
        help: "background hold, not in the paper: with object focus, the pixels the colour-matched scene leaves \
               empty keep its render, so no haze grows around the object",
        max: 1e6,
        gpu: true,
        paper: false,
        weight: |w| &mut w.outside,
        value: |l| l.outside,
    },
    Term {
        key: "palette",
        flag: "lambda-palette",
        symbol: "λ_pal",
        chart: "palette",
        help: "palette hold, not in the paper: with object focus, the covered pixels' per-channel mean and \
               deviation keep the colour-matched render's (the style's palette after colour matching), so the \
               object cannot darken or grey while its pattern changes (the object recipe: 100)",
        max: 1e4,
        gpu: true,
        paper: false,
        weight: |w| &mut w.palette,
        value: |l| l.palette,
    },
    Term {
        key: "sliced",
        flag: "lambda-sliced",
        symbol: "λ_sw",
        chart: "sliced",
        help: "sliced Wasserstein, not in the paper: pulls the distribution of the render's relu3 features toward \
               the style's along 128 fixed random directions (λ_mean is its first moment)",
        max: 1000.0,
        gpu: true,
        paper: false,
        weight: |w| &mut w.sliced,
        value: |l| l.sliced,
    },
    Term {
        key: "sliced_depth",
        flag: "lambda-sliced-depth",
        symbol: "λ_swd",
        chart: "sliced depth",
        help: "sliced Wasserstein on depth, not in the paper: pulls the distribution of the rendered depth map's \
               relu3 features toward the style depth's, on geometry steps",
        max: 1000.0,
        gpu: true,
        paper: false,
        weight: |w| &mut w.sliced_depth,
        value: |l| l.sliced_depth,
    },
    Term {
        key: "assignment",
        flag: "lambda-assign",
        symbol: "λ_as",
        chart: "assign",
        help: "assignment, not in the paper: pairs each relu3 feature of the render with a distinct style \
               feature drawn anew each step (least total squared distance) and pulls it there; with λ_asc on, \
               along the cosine pairing",
        max: 1000.0,
        gpu: true,
        paper: false,
        weight: |w| &mut w.assignment,
        value: |l| l.assignment,
    },
    Term {
        key: "assignment_cosine",
        flag: "lambda-assign-cos",
        symbol: "λ_asc",
        chart: "assign cos",
        help: "cosine assignment, not in the paper: the same one-to-one pairing by cosine distance, turning each \
               feature's direction to its partner's (the object recipe: 10, with λ_as 0.015)",
        max: 1000.0,
        gpu: true,
        paper: false,
        weight: |w| &mut w.assignment_cosine,
        value: |l| l.assignment_cosine,
    },
];

impl LossTerms {
    /// `Σ weight · term` over every term of [`TERMS`] (the regularisers
    /// included: 0 on steps that do not take them).
    pub fn weighted(&self, w: &LossWeights) -> f32 {
        w.terms().map(|(t, weight)| weight * (t.value)(self)).sum()
    }
}

impl LossWeights {
    /// Every weight with its term, in [`TERMS`] order.
    pub fn terms(&self) -> impl Iterator<Item = (&'static Term, f32)> + '_ {
        TERMS.iter().map(move |t| (t, t.get(self)))
    }

    /// The terms that are on (weight > 0) and that the GPU engine does not compute.
    pub fn cpu_only(&self) -> impl Iterator<Item = (&'static Term, f32)> + '_ {
        self.terms().filter(|(t, v)| !t.gpu && *v > 0.0)
    }

    /// The terms whose weight here differs from `other`'s, with the weight here.
    pub fn differing<'a>(&'a self, other: &'a LossWeights) -> impl Iterator<Item = (&'static Term, f32)> + 'a {
        self.terms().filter(move |(t, v)| *v != t.get(other))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_weight_has_one_term_whose_key_is_its_preset_key() {
        let json = serde_json::to_value(LossWeights::default()).expect("json");
        let keys: Vec<&String> = json.as_object().expect("object").keys().collect();
        assert_eq!(keys.len(), TERMS.len(), "a weight without a term, or a term without a weight");
        for t in &TERMS {
            assert!(keys.iter().any(|k| *k == t.key), "{} is not a field of LossWeights", t.key);
            // The accessor reaches the field the key names.
            let mut w = LossWeights::default();
            *(t.weight)(&mut w) = 123.0;
            assert_eq!(serde_json::to_value(w).expect("json")[t.key], 123.0, "{}", t.key);
            assert!(t.flag.starts_with("lambda-") && t.symbol.starts_with('λ') && !t.help.is_empty());
            assert!(t.max > 0.0);
        }
        for (k, a) in TERMS.iter().enumerate() {
            for b in &TERMS[k + 1..] {
                assert!(a.key != b.key && a.flag != b.flag && a.symbol != b.symbol && a.chart != b.chart);
            }
        }
    }

    #[test]
    fn each_term_reads_its_own_value_from_a_step() {
        // Distinct values per field: each term's value accessor names one of them, no two the same.
        let v: serde_json::Value = serde_json::json!({
            "total": 0.5, "gcfm": 1.0, "content": 2.0, "tv": 3.0, "reg_opacity": 4.0, "reg_scale": 5.0,
            "reg_rotation": 6.0, "depth": 7.0, "feature_mean": 8.0, "outside": 9.0, "palette": 10.0,
            "sliced": 11.0, "sliced_depth": 12.0, "assignment": 13.0, "assignment_cosine": 14.0
        });
        let l: LossTerms = serde_json::from_value(v).expect("terms");
        let values: Vec<f32> = TERMS.iter().map(|t| (t.value)(&l)).collect();
        assert_eq!(values, (1..=14).map(|k| k as f32).collect::<Vec<_>>());
    }

    #[test]
    fn the_paper_terms_are_the_defaults_that_are_on() {
        let d = LossWeights::default();
        for (t, v) in d.terms() {
            assert_eq!(t.paper, v > 0.0, "{}", t.key);
        }
        assert_eq!(d.cpu_only().count(), 0);
        // λ_sw, λ_swd and λ_pal, once CPU-only terms, run on the GPU too.
        let w = LossWeights { sliced: 1.0, sliced_depth: 1.0, palette: 1.0, ..d };
        assert_eq!(w.cpu_only().count(), 0);
        assert_eq!(Term::find("lambda-assign-cos").map(|t| t.key), Some("assignment_cosine"));
        assert_eq!(Term::find("tv").map(|t| t.flag), Some("lambda-tv"));
    }

    #[test]
    fn a_terms_name_is_its_helps_first_words() {
        let name = |key| Term::find(key).map(|t| t.name());
        assert_eq!(name("palette"), Some("palette hold"));
        assert_eq!(name("opacity"), Some("opacity regulariser"));
        assert_eq!(name("sliced_depth"), Some("sliced Wasserstein on depth"));
        assert_eq!(name("tv"), Some("total variation of the rendered RGB"));
        for t in &TERMS {
            assert!(!t.name().is_empty() && !t.name().contains([',', ':']), "{}", t.key);
        }
    }
}
