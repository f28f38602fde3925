//! The side panel's widgets: the [`StyleConfig`] editor (the same struct as
//! preset files and CLI flags), the run buttons and the loss chart.

use egui::{Color32, Ui};
use gast_core::session::{LossTerms, StepReport};
use gast_core::style::config::{
    FRAME_RECIPE_SLICED_DEPTH, OBJECT_RECIPE_ASSIGN, OBJECT_RECIPE_ASSIGN_COS, OBJECT_RECIPE_PALETTE, ParamRegulariser,
};
use gast_core::style::terms::TERMS;
use gast_core::style::{Focus, MeanSteps, Mode, Phase, StyleConfig};

/// Label of a focus in menus.
pub fn focus_label(f: Focus) -> &'static str {
    match f {
        Focus::Frame => "frame (every pixel)",
        Focus::Object => "object (covered pixels)",
        Focus::Auto => "auto (object below half coverage)",
    }
}

/// Label of a mode in menus.
pub fn mode_label(m: Mode) -> &'static str {
    match m {
        Mode::Decoupled => "decoupled",
        Mode::Joint => "joint",
        Mode::ColorOnly => "colour only",
        Mode::GeometryOnly => "geometry only",
    }
}

/// Label of a parameter regulariser's form in menus.
pub fn regulariser_label(r: ParamRegulariser) -> &'static str {
    match r {
        ParamRegulariser::Norm => "norm over all Gaussians (paper)",
        ParamRegulariser::MeanSquare => "per-Gaussian mean square (tether)",
    }
}

/// Label of a choice of λ_mean's steps in menus.
pub fn mean_steps_label(m: MeanSteps) -> &'static str {
    match m {
        MeanSteps::Colour => "colour steps",
        MeanSteps::Every => "every step",
    }
}

/// A slider of the run's settings: a value from a preset, a plan or a kept
/// run outside its range stays as it is (the default clamping changed a
/// working resolution of 1,512 px to 1,024 as the editor showed it, and a
/// live run's editor then sent that on); only a user's edit is kept within.
fn slider<Num: egui::emath::Numeric>(value: &mut Num, range: std::ops::RangeInclusive<Num>) -> egui::Slider<'_> {
    egui::Slider::new(value, range).clamping(egui::SliderClamping::Edits)
}

fn weight(ui: &mut Ui, value: &mut f32, max: f32, label: &str, hover: &str) -> bool {
    ui.add(slider(value, 0.0..=max).logarithmic(true).smallest_positive(1e-5).text(label))
        .on_hover_text(hover)
        .changed()
}

/// The loss weights a run of `c` uses that differ from its sliders because a
/// recipe lifts them ([`StyleConfig::recipe_lifts`]): (term symbol, the value
/// the run uses). `coverage`: the running session's mean coverage; without a
/// run, only a fixed focus tells which recipe applies.
pub fn recipe_weights(c: &StyleConfig, coverage: Option<f32>) -> Vec<(&'static str, f32)> {
    let coverage = match (coverage, c.focus) {
        (Some(v), _) => v,
        (None, Focus::Auto) => return Vec::new(),
        // A fixed focus ignores the coverage.
        (None, _) => 1.0,
    };
    c.recipe_lifts(coverage).into_iter().map(|(t, v)| (t.symbol, v)).collect()
}

/// The time a step of `c` takes, under the resolution slider: the plan's
/// model for the run's focus (the running session's `coverage` settles
/// `auto`; without one it reads as the object) with the style at `c`'s
/// texture scale, `style` (width, height) pixels when one is chosen, for a
/// scene of `gaussians` when one is open; on this machine as a run's plan
/// takes it once a run has probed its rate (`gemm_gflops`,
/// [`gast_core::session::plan::StepModel::on_machine`]), on a 2-core CPU before.
pub fn step_hint(
    c: &StyleConfig,
    coverage: Option<f32>,
    style: Option<[usize; 2]>,
    gaussians: Option<usize>,
    gemm_gflops: Option<f64>,
) -> String {
    use gast_core::session::plan::{StepModel, step_time_hint};
    let object = coverage.map_or(c.focus != Focus::Frame, |v| c.focus.is_object(v));
    let [width, height] = style.unwrap_or([1, 1]);
    let model = StepModel::for_run(object, Some(c.texture_scale))
        .with_style(width, height)
        .with_gaussians(gaussians.unwrap_or(0));
    step_time_hint(gemm_gflops.map_or(model, |g| model.on_machine(g)), c.resolution)
}

/// Edits `c` in place; returns true when anything changed. `coverage`: the
/// running session's mean coverage, which settles `auto` focus and so which
/// recipe lifts which weight (shown under the slider it lifts); `style`: the
/// chosen style's size, and `gaussians` the open scene's, for the step time
/// under the resolution slider.
pub fn config_editor(
    ui: &mut Ui,
    c: &mut StyleConfig,
    coverage: Option<f32>,
    style: Option<[usize; 2]>,
    gaussians: Option<usize>,
) -> bool {
    let mut changed = false;
    ui.label(egui::RichText::new("Loss weights").strong());
    let lifted = recipe_weights(c, coverage);
    // One slider per loss term (`gast_core::style::terms`), with the choices that belong to a term after it.
    for t in &TERMS {
        let hover = if t.gpu { t.help.to_string() } else { format!("{} (CPU device only so far)", t.help) };
        changed |= weight(ui, (t.weight)(&mut c.weights), t.max, t.symbol, &hover);
        if let Some((_, used)) = lifted.iter().find(|(s, _)| *s == t.symbol) {
            ui.weak(format!("    the run uses {} {used} (a recipe below; set it here to override)", t.symbol));
        }
        if t.key == "rotation" {
            changed |= egui::ComboBox::from_label("λ_α, λ_s, λ_r form")
                .selected_text(regulariser_label(c.param_regulariser))
                .show_ui(ui, |ui| {
                    let mut any = false;
                    for r in [ParamRegulariser::Norm, ParamRegulariser::MeanSquare] {
                        any |= ui.selectable_value(&mut c.param_regulariser, r, regulariser_label(r)).changed();
                    }
                    any
                })
                .inner
                .unwrap_or(false);
        }
        if t.key == "feature_mean" && c.weights.feature_mean > 0.0 {
            egui::ComboBox::from_label("λ_mean acts on")
                .selected_text(mean_steps_label(c.feature_mean_steps))
                .show_ui(ui, |ui| {
                    for m in MeanSteps::ALL {
                        changed |= ui.selectable_value(&mut c.feature_mean_steps, m, mean_steps_label(m)).changed();
                    }
                })
                .response
                .on_hover_text(
                    "colour steps only leave the geometry steps to GCFM alone: better nearest-neighbour matches, \
                     less of the style's colour statistics (the focus study)",
                );
        }
    }
    changed |= ui
        .checkbox(
            &mut c.object_recipe,
            format!(
                "object recipe: λ_asc {OBJECT_RECIPE_ASSIGN_COS}, λ_as {OBJECT_RECIPE_ASSIGN}, λ_pal \
                 {OBJECT_RECIPE_PALETTE} on objects"
            ),
        )
        .on_hover_text(format!(
            "with the losses on the object and λ_as = λ_asc = 0, the run uses λ_asc {OBJECT_RECIPE_ASSIGN_COS} and \
             λ_as {OBJECT_RECIPE_ASSIGN} (the focus study's winner on guitar, biker and playbot); with λ_pal = 0, \
             the palette hold at λ_pal {OBJECT_RECIPE_PALETTE}, so the object keeps its colour-matched brightness \
             (the defaults study: without it guitar × stone darkens to near black); off in the paper"
        ))
        .changed();
    changed |= ui
        .checkbox(&mut c.frame_recipe, format!("frame recipe: λ_swd {FRAME_RECIPE_SLICED_DEPTH} on full frames"))
        .on_hover_text(format!(
            "with the losses on the whole frame and λ_swd = 0, the run uses λ_swd {FRAME_RECIPE_SLICED_DEPTH}: the \
             depth's feature distribution pulled toward the style depth's, so the style's relief forms in the \
             geometry (docs/geometry.md); off in the paper"
        ))
        .changed();

    ui.separator();
    ui.label(egui::RichText::new("Schedule").strong());
    egui::ComboBox::from_label("mode").selected_text(mode_label(c.mode)).show_ui(ui, |ui| {
        for m in Mode::ALL {
            changed |= ui.selectable_value(&mut c.mode, m, mode_label(m)).changed();
        }
    });
    changed |= ui.add(slider(&mut c.cycles, 1..=100).text("K (cycles)")).changed();
    changed |= ui.add(slider(&mut c.steps_per_cycle, 1..=500).text("steps per cycle")).changed();
    changed |= ui
        .add(slider(&mut c.ratio_geo, 0.0..=1.0).text("N_g / (N_c+N_g)"))
        .on_hover_text("geometry share of each cycle")
        .changed();
    let s = c.schedule();
    ui.weak(format!(
        "N_c = {}, N_g = {}, {} steps",
        s.color_steps,
        s.geometry_steps,
        s.cycles * (s.color_steps + s.geometry_steps)
    ));

    ui.separator();
    ui.label(egui::RichText::new("Texture and resolution").strong());
    ui.horizontal(|ui| {
        ui.label("texture scale");
        for (px, name) in [(128, "0.5×"), (256, "1×"), (512, "2×")] {
            changed |= ui
                .selectable_value(&mut c.texture_scale, px, name)
                .on_hover_text(format!("style image height {px} px"))
                .changed();
        }
    });
    changed |= ui.add(slider(&mut c.texture_scale, 16..=1024).text("style height (px)")).changed();
    changed |= ui.add(slider(&mut c.resolution, 64..=1024).text("working resolution")).changed();
    ui.weak(step_hint(c, coverage, style, gaussians, gast_core::session::plan::machine_gemm_gflops_known()));
    egui::ComboBox::from_label("focus").selected_text(focus_label(c.focus)).show_ui(ui, |ui| {
        for f in Focus::ALL {
            changed |= ui.selectable_value(&mut c.focus, f, focus_label(f)).changed();
        }
    });
    changed |= ui
        .checkbox(&mut c.color_floor, "colour floor")
        .on_hover_text("keep every Gaussian's base colour out of the clamp at 0, where no gradient reaches it")
        .changed();
    changed |= ui
        .add(slider(&mut c.depth_relief_px, 0..=64).text("depth relief (px)"))
        .on_hover_text(
            "above 0, VGG sees both depth maps minus their blur of this radius: relief compared with relief, \
             not the scene's layout; 0 is the paper's min-max depth",
        )
        .changed();
    changed |= ui
        .checkbox(&mut c.phase_leak, "phase leak (reference)")
        .on_hover_text(
            "as the reference's code does (decoupled mode): a colour step's gradient on the geometry, and a \
             geometry step's on the colour, are summed and applied at the other phase's next step",
        )
        .changed();

    ui.separator();
    egui::CollapsingHeader::new("Learning rates").default_open(false).show(ui, |ui| {
        let lr = &mut c.lr;
        changed |= weight(ui, &mut lr.color, 1.0, "colour", "SH DC (colour steps)");
        changed |=
            weight(ui, &mut lr.means_per_extent, 0.01, "means / extent", "position learning rate per scene extent");
        changed |= weight(ui, &mut lr.scales, 0.1, "scales", "log-scales");
        changed |= weight(ui, &mut lr.quats, 0.1, "rotations", "quaternions");
        changed |= weight(ui, &mut lr.opacity, 1.0, "opacity", "opacity logits");
    });
    changed
}

/// Draws every loss term of the steps so far as a line, each on its own
/// scale (min to max of that term, printed beside its name in a legend band
/// above the curves, so no curve runs under a label), over a strip that
/// marks each step's phase (colour steps amber, geometry steps blue, joint
/// steps violet). The λ_mean, λ_out and λ_sw terms, off by default, get their
/// lines only when a step measured them.
pub fn loss_chart(ui: &mut Ui, steps: &[StepReport]) {
    const ROW: f32 = 13.0;
    const COLUMNS: usize = 3;
    // The total, then one line per loss term (`gast_core::style::terms`): GCFM, content and TV always,
    // the others once they are on.
    let total: fn(&LossTerms) -> f32 = |l| l.total;
    type Series = (&'static str, Color32, fn(&LossTerms) -> f32);
    let series: Vec<Series> = std::iter::once(("total", TOTAL_COLOUR, total))
        .chain(TERMS.iter().enumerate().map(|(k, t)| (t.chart, term_colour(k), t.value)))
        .enumerate()
        .filter(|(k, s)| *k < 4 || steps.iter().any(|r| (s.2)(&r.losses) > 0.0))
        .map(|(_, s)| s)
        .collect();
    let legend_rows = series.len().div_ceil(COLUMNS) as f32;
    let band = 4.0 + ROW * legend_rows + 2.0;
    // The curves keep 84 px, so the legend band does not push the first weight sliders below a
    // 1280×800 window's fold.
    let (rect, response) = ui.allocate_exact_size(egui::vec2(ui.available_width(), 84.0 + band), egui::Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 4.0, ui.visuals().extreme_bg_color);
    if steps.len() < 2 {
        painter.text(
            rect.center(),
            egui::Align2::CENTER_CENTER,
            "loss chart: no steps yet",
            egui::FontId::proportional(12.0),
            ui.visuals().weak_text_color(),
        );
        return;
    }
    let n = steps.len() as f32 - 1.0;
    let x = |i: usize| rect.left() + rect.width() * i as f32 / n;
    // Phase strip along the bottom.
    let strip = 5.0;
    for (i, s) in steps.iter().enumerate() {
        let color = match s.phase {
            Phase::Color => Color32::from_rgb(230, 160, 40),
            Phase::Geometry => Color32::from_rgb(60, 120, 230),
            Phase::Joint => Color32::from_rgb(170, 90, 220),
        };
        let x0 = x(i.saturating_sub(1)).max(rect.left());
        painter.rect_filled(
            egui::Rect::from_min_max(egui::pos2(x0, rect.bottom() - strip), egui::pos2(x(i) + 1.0, rect.bottom())),
            0.0,
            color,
        );
    }
    let (top, bottom) = (rect.top() + band + 4.0, rect.bottom() - strip - 3.0);
    painter.hline(rect.x_range(), rect.top() + band, egui::Stroke::new(1.0, ui.visuals().faint_bg_color));
    let column = rect.width() / COLUMNS as f32;
    // The curves are clipped to the plot: a raw spike past the smoothed range runs off it.
    let plot = painter.with_clip_rect(egui::Rect::from_x_y_ranges(rect.x_range(), top..=bottom));
    let mut ranges = vec![format!(
        "each curve: its own scale, smoothed over {} steps (raw values faint behind); its range:",
        smoothing_window(steps.len())
    )];
    for (k, (name, color, get)) in series.into_iter().enumerate() {
        let values: Vec<f32> = steps.iter().map(|s| get(&s.losses)).collect();
        let window = smoothing_window(values.len());
        let smooth = smoothed(&values, window);
        let at = rect.left_top() + egui::vec2(6.0 + column * (k % COLUMNS) as f32, 4.0 + ROW * (k / COLUMNS) as f32);
        let font = egui::FontId::proportional(10.5);
        let Some((lo, hi)) = chart_range(&smooth, window) else {
            painter.text(at, egui::Align2::LEFT_TOP, format!("{name} –"), font, color);
            continue;
        };
        let span = (hi - lo).max(hi.abs() * 1e-3).max(1e-12);
        let y = |v: f32| bottom - (bottom - top) * (v - lo) / span;
        let line = |vals: &[f32]| -> Vec<egui::Pos2> {
            vals.iter().enumerate().filter(|(_, v)| v.is_finite()).map(|(i, &v)| egui::pos2(x(i), y(v))).collect()
        };
        // The raw values faint behind, the smoothed curve on top.
        plot.add(egui::Shape::line(line(&values), egui::Stroke::new(1.0, color.gamma_multiply(0.25))));
        plot.add(egui::Shape::line(line(&smooth), egui::Stroke::new(1.6, color)));
        let now = smooth.iter().rev().find(|v| v.is_finite()).copied().unwrap_or(f32::NAN);
        painter.text(at, egui::Align2::LEFT_TOP, format!("{name} {}", loss_label(now)), font, color);
        ranges.push(format!("{name}: {} – {}, now {}", loss_label(lo), loss_label(hi), loss_label(now)));
    }
    response.on_hover_text(ranges.join("\n"));
}

/// The chart's colour of the total.
const TOTAL_COLOUR: Color32 = Color32::from_rgb(250, 200, 60);

/// The chart's colour of the `k`-th term of [`TERMS`].
fn term_colour(k: usize) -> Color32 {
    const COLOURS: [Color32; 12] = [
        Color32::from_rgb(90, 170, 250),
        Color32::from_rgb(120, 220, 120),
        Color32::from_rgb(230, 110, 110),
        Color32::from_rgb(160, 160, 120),
        Color32::from_rgb(140, 160, 200),
        Color32::from_rgb(200, 150, 150),
        Color32::from_rgb(200, 200, 200),
        Color32::from_rgb(220, 130, 230),
        Color32::from_rgb(120, 220, 220),
        Color32::from_rgb(240, 160, 90),
        Color32::from_rgb(170, 140, 250),
        Color32::from_rgb(250, 120, 180),
    ];
    COLOURS[k % COLOURS.len()]
}

/// The moving-average window of a chart of `n` steps: about a thirtieth of
/// the run, at least five steps (colour and geometry steps alternate, and
/// their terms differ).
pub(super) fn smoothing_window(n: usize) -> usize {
    (n / 30).max(5)
}

/// An exponential moving average of `values` over about `window` steps
/// (non-finite values are skipped, their place keeps the running mean).
pub(super) fn smoothed(values: &[f32], window: usize) -> Vec<f32> {
    let a = 2.0 / (window as f32 + 1.0);
    let mut mean = f32::NAN;
    values
        .iter()
        .map(|&v| {
            if v.is_finite() {
                mean = if mean.is_finite() { mean + a * (v - mean) } else { v };
            }
            mean
        })
        .collect()
}

/// The chart's vertical range of a series smoothed over `window` steps: its
/// [`robust_range`] past the first `window` steps (the average's warm-up,
/// still near the first raw values) once the run is twice that long.
pub(super) fn chart_range(smooth: &[f32], window: usize) -> Option<(f32, f32)> {
    let skip = if smooth.len() > 2 * window { window } else { 0 };
    robust_range(&smooth[skip..])
}

/// The chart's vertical range of a smoothed series: its 2nd to 98th
/// percentile, so that the first steps' spike does not flatten the rest;
/// `None` when it has no finite value.
pub(super) fn robust_range(values: &[f32]) -> Option<(f32, f32)> {
    let mut v: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f32::total_cmp);
    let at = |q: f32| v[((v.len() - 1) as f32 * q).round() as usize];
    Some((at(0.02), at(0.98)))
}

/// A loss value for the chart's legend: three decimals, or three significant
/// digits in scientific notation when it is small (content and TV losses sit
/// around 1e-4 and would all read 0.000).
pub(super) fn loss_label(v: f32) -> String {
    if v == 0.0 || v.abs() >= 0.01 { format!("{v:.3}") } else { format!("{v:.2e}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_editor_names_the_weights_a_recipe_lifts_for_the_run() {
        let auto = StyleConfig::default();
        assert_eq!(auto.focus, Focus::Auto);
        // Before a run, auto focus does not say which recipe applies.
        assert!(recipe_weights(&auto, None).is_empty());
        // A full frame: the frame recipe's λ_swd, nothing else.
        let frame = recipe_weights(&auto, Some(1.0));
        assert_eq!(frame.len(), 1, "{frame:?}");
        assert_eq!(frame[0].1, FRAME_RECIPE_SLICED_DEPTH);
        // An object: the two assignment weights and the palette hold.
        let mut object: Vec<f32> = recipe_weights(&auto, Some(0.2)).into_iter().map(|(_, v)| v).collect();
        object.sort_by(f32::total_cmp);
        assert_eq!(object, vec![OBJECT_RECIPE_ASSIGN, OBJECT_RECIPE_ASSIGN_COS, OBJECT_RECIPE_PALETTE]);
        // A fixed focus tells without a run; a weight the user set, or the paper's preset, lifts nothing.
        assert_eq!(recipe_weights(&StyleConfig { focus: Focus::Frame, ..auto.clone() }, None).len(), 1);
        let mut own = auto.clone();
        own.weights.sliced_depth = 3.0;
        assert!(recipe_weights(&own, Some(1.0)).is_empty());
        assert!(recipe_weights(&StyleConfig::paper(), Some(1.0)).is_empty());
    }
}
