//! The K-cycle schedule: which phase each optimisation step belongs to.
//!
//! The decoupled method alternates `N_c` colour-only steps and `N_g`
//! geometry-only steps in each of `K` cycles. The ablation modes keep the same
//! step budget (`K · (N_c + N_g)`) and change only what each step updates.

use serde::{Deserialize, Serialize};

/// How steps are assigned to phases.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// Colour steps then geometry steps in every cycle (the paper's method).
    #[default]
    Decoupled,
    /// Every step updates colour and geometry together with the geometry loss.
    Joint,
    /// Every step is a colour step (`N_g = 0`).
    ColorOnly,
    /// Every step is a geometry step (`N_c = 0`).
    GeometryOnly,
}

impl Mode {
    /// All modes, for ablations and menus.
    pub const ALL: [Mode; 4] = [Mode::Decoupled, Mode::Joint, Mode::ColorOnly, Mode::GeometryOnly];

    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Decoupled => "decoupled",
            Mode::Joint => "joint",
            Mode::ColorOnly => "color-only",
            Mode::GeometryOnly => "geometry-only",
        }
    }
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Mode::ALL
            .into_iter()
            .find(|m| m.name() == s || (s == "colour-only" && *m == Mode::ColorOnly))
            .ok_or_else(|| format!("expected one of decoupled, joint, color-only, geometry-only; found {s:?}"))
    }
}

/// What one step updates and which loss it uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Phase {
    /// SH DC only; GCFM + content + TV.
    Color,
    /// Means, scales, rotations, opacities; plus the parameter and depth regularisers.
    Geometry,
    /// Colour and geometry together with the geometry loss (the `joint` ablation).
    Joint,
}

impl Phase {
    /// Whether the step updates the SH DC coefficients.
    pub fn updates_color(self) -> bool {
        matches!(self, Phase::Color | Phase::Joint)
    }
    /// Whether the step updates the geometric parameters (and adds the regularisers).
    pub fn updates_geometry(self) -> bool {
        matches!(self, Phase::Geometry | Phase::Joint)
    }
}

/// The step plan of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    /// Number of cycles `K`.
    pub cycles: u32,
    /// Colour steps per cycle `N_c` (decoupled mode).
    pub color_steps: u32,
    /// Geometry steps per cycle `N_g` (decoupled mode).
    pub geometry_steps: u32,
    /// The mode.
    pub mode: Mode,
}

impl Schedule {
    /// A schedule from `K`, the steps per cycle and the geometry ratio `N_g / (N_c + N_g)`
    /// (0.9 of 100 gives the default `N_c = 10`, `N_g = 90`).
    pub fn from_ratio(cycles: u32, steps_per_cycle: u32, ratio_geo: f32, mode: Mode) -> Self {
        let ratio = if ratio_geo.is_finite() { ratio_geo.clamp(0.0, 1.0) } else { 0.9 };
        let geometry_steps = (ratio * steps_per_cycle as f32).round() as u32;
        Self { cycles, color_steps: steps_per_cycle - geometry_steps, geometry_steps, mode }
    }

    /// Steps per cycle.
    pub fn steps_per_cycle(&self) -> u32 {
        self.color_steps + self.geometry_steps
    }

    /// The whole budget `K · (N_c + N_g)`.
    pub fn total_steps(&self) -> u32 {
        self.cycles.saturating_mul(self.steps_per_cycle())
    }

    /// The cycle (from 0) and phase of step `step` (from 0), or `None` past the end.
    pub fn at(&self, step: u32) -> Option<(u32, Phase)> {
        let per = self.steps_per_cycle();
        if per == 0 || step >= self.total_steps() {
            return None;
        }
        let cycle = step / per;
        let phase = match self.mode {
            Mode::Decoupled if step % per < self.color_steps => Phase::Color,
            Mode::Decoupled => Phase::Geometry,
            Mode::Joint => Phase::Joint,
            Mode::ColorOnly => Phase::Color,
            Mode::GeometryOnly => Phase::Geometry,
        };
        Some((cycle, phase))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_schedule_is_10_colour_then_90_geometry() {
        let s = Schedule::from_ratio(30, 100, 0.9, Mode::Decoupled);
        assert_eq!((s.color_steps, s.geometry_steps, s.total_steps()), (10, 90, 3000));
        assert_eq!(s.at(0), Some((0, Phase::Color)));
        assert_eq!(s.at(9), Some((0, Phase::Color)));
        assert_eq!(s.at(10), Some((0, Phase::Geometry)));
        assert_eq!(s.at(99), Some((0, Phase::Geometry)));
        assert_eq!(s.at(100), Some((1, Phase::Color)));
        assert_eq!(s.at(2999), Some((29, Phase::Geometry)));
        assert_eq!(s.at(3000), None);
        let colour = (0..3000).filter(|&i| s.at(i).map(|x| x.1) == Some(Phase::Color)).count();
        assert_eq!(colour, 300);
    }

    #[test]
    fn ablations_keep_the_budget() {
        for mode in Mode::ALL {
            let s = Schedule::from_ratio(30, 100, 0.9, mode);
            assert_eq!(s.total_steps(), 3000, "{mode:?}");
            let phases: std::collections::HashSet<_> = (0..3000).filter_map(|i| s.at(i)).map(|x| x.1).collect();
            let want: &[Phase] = match mode {
                Mode::Decoupled => &[Phase::Color, Phase::Geometry],
                Mode::Joint => &[Phase::Joint],
                Mode::ColorOnly => &[Phase::Color],
                Mode::GeometryOnly => &[Phase::Geometry],
            };
            assert_eq!(phases, want.iter().copied().collect(), "{mode:?}");
        }
        for r in [0.0, 0.3, 0.6, 0.9, 1.0] {
            let s = Schedule::from_ratio(2, 100, r, Mode::Decoupled);
            assert_eq!(s.geometry_steps, (r * 100.0f32).round() as u32);
            assert_eq!(s.total_steps(), 200);
        }
        assert_eq!("color-only".parse::<Mode>(), Ok(Mode::ColorOnly));
        assert!("sideways".parse::<Mode>().is_err());
    }
}
