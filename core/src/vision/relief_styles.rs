//! Style images whose depth is known: relief height fields, lit and shaded.
//!
//! The controlled case for the geometry half of the method (issue 29): a
//! depth network's estimate of a photo or painting is a guess, so when the
//! geometry does not take a style's structure it is unclear whether the cue
//! or the optimisation failed. These styles are drawn from a height field
//! (square blocks of several heights, hemispherical beads, wave crests) seen
//! from above under a low light with cast shadows, and come with that height
//! as their depth (near = 1), to pass with `--style-depth`. `gast assets`
//! writes them beside the demo styles.

/// The kinds of relief.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReliefKind {
    /// Square blocks of three heights on a grid, coloured by a palette.
    Blocks,
    /// Hemispherical beads of two sizes on a jittered grid.
    Beads,
    /// Wave crests: sharpened sinusoidal ridges, bent.
    Crests,
}

impl ReliefKind {
    /// Every kind, in a fixed order.
    pub const ALL: [ReliefKind; 3] = [ReliefKind::Blocks, ReliefKind::Beads, ReliefKind::Crests];

    /// The file stem `gast assets` uses.
    pub fn name(self) -> &'static str {
        match self {
            ReliefKind::Blocks => "relief_blocks",
            ReliefKind::Beads => "relief_beads",
            ReliefKind::Crests => "relief_crests",
        }
    }
}

/// A style image and its exact depth.
#[derive(Clone, Debug)]
pub struct ReliefStyle {
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// 8-bit RGB, HWC.
    pub rgb: Vec<u8>,
    /// The height field in [0, 1], near (raised) = 1, row-major.
    pub depth: Vec<f32>,
}

/// A small integer hash in [0, 1) (deterministic across platforms).
fn hash01(a: u32, b: u32, salt: u32) -> f32 {
    let mut x = a.wrapping_mul(0x9E37_79B1) ^ b.wrapping_mul(0x85EB_CA77) ^ salt.wrapping_mul(0xC2B2_AE3D);
    x ^= x >> 15;
    x = x.wrapping_mul(0x2C1B_3C6D);
    x ^= x >> 12;
    x = x.wrapping_mul(0x297A_2D39);
    x ^= x >> 15;
    (x >> 8) as f32 / (1u32 << 24) as f32
}

/// Height and albedo of one pixel of `kind` at (`x`, `y`) in a `size`-pixel square.
fn field(kind: ReliefKind, x: f32, y: f32, size: f32) -> (f32, [f32; 3]) {
    match kind {
        ReliefKind::Blocks => {
            let cell = size / 8.0;
            let (cx, cy) = ((x / cell).floor(), (y / cell).floor());
            let (fx, fy) = (x / cell - cx, y / cell - cy);
            let gap = 0.12;
            let inside = fx > gap && fx < 1.0 - gap && fy > gap && fy < 1.0 - gap;
            let level = (hash01(cx as u32, cy as u32, 1) * 3.0).floor();
            let palette = [[0.93, 0.55, 0.16], [0.18, 0.42, 0.78], [0.85, 0.82, 0.74]];
            if inside { (0.4 + 0.3 * level, palette[level as usize % 3]) } else { (0.0, [0.25, 0.22, 0.2]) }
        }
        ReliefKind::Beads => {
            let cell = size / 10.0;
            let mut best = (0.0f32, [0.08, 0.07, 0.1]);
            let (cx, cy) = ((x / cell).floor() as i32, (y / cell).floor() as i32);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (gx, gy) = ((cx + dx).max(0) as u32, (cy + dy).max(0) as u32);
                    let jx = (hash01(gx, gy, 2) - 0.5) * 0.4;
                    let jy = (hash01(gx, gy, 3) - 0.5) * 0.4;
                    let r = cell * if hash01(gx, gy, 4) < 0.5 { 0.42 } else { 0.3 };
                    let (bx, by) = ((gx as f32 + 0.5 + jx) * cell, (gy as f32 + 0.5 + jy) * cell);
                    let d2 = (x - bx).powi(2) + (y - by).powi(2);
                    if d2 < r * r {
                        let h = (1.0 - d2 / (r * r)).sqrt() * r / (cell * 0.42);
                        let albedo = if hash01(gx, gy, 5) < 0.6 { [0.82, 0.84, 0.88] } else { [0.9, 0.72, 0.3] };
                        if h > best.0 {
                            best = (h, albedo);
                        }
                    }
                }
            }
            best
        }
        ReliefKind::Crests => {
            let wave = size / 6.0;
            let bend = 0.35 * (std::f32::consts::TAU * y / (size / 2.0)).sin();
            let s = (std::f32::consts::TAU * (x / wave + bend)).sin();
            let h = (0.5 + 0.5 * s).powf(2.5);
            let (deep, foam) = ([0.05, 0.16, 0.38], [0.92, 0.95, 0.98]);
            (h, std::array::from_fn(|c| deep[c] + (foam[c] - deep[c]) * h))
        }
    }
}

/// Draws `kind` at `size × size` pixels: the height field seen from above,
/// Lambertian shading under a low light from the upper left with cast
/// shadows, and the height as the depth.
pub fn relief_style(kind: ReliefKind, size: usize) -> ReliefStyle {
    let n = size * size;
    let s = size as f32;
    let mut depth = vec![0f32; n];
    let mut albedo = vec![[0f32; 3]; n];
    for i in 0..size {
        for j in 0..size {
            let (h, a) = field(kind, j as f32 + 0.5, i as f32 + 0.5, s);
            depth[i * size + j] = h;
            albedo[i * size + j] = a;
        }
    }
    // Relief amplitude in pixels: the tallest block stands a tenth of the image.
    let amp = s / 10.0;
    let light = glam::Vec3::new(-0.55, -0.45, 0.7).normalize();
    let at = |i: isize, j: isize| {
        depth[(i.clamp(0, size as isize - 1) as usize) * size + j.clamp(0, size as isize - 1) as usize]
    };
    let mut rgb = vec![0u8; n * 3];
    for i in 0..size as isize {
        for j in 0..size as isize {
            let gx = (at(i, j + 1) - at(i, j - 1)) * 0.5 * amp;
            let gy = (at(i + 1, j) - at(i - 1, j)) * 0.5 * amp;
            let normal = glam::Vec3::new(-gx, -gy, 1.0).normalize();
            let mut lit = normal.dot(light).max(0.0);
            // Shadow: march toward the light; blocked where the field rises above the ray.
            let h0 = at(i, j) * amp;
            let (step_x, step_y, rise) = (light.x, light.y, light.z / light.truncate().length());
            let mut t = 1.0f32;
            while t < amp * 3.0 {
                let (si, sj) = ((i as f32 + step_y * t).round() as isize, (j as f32 + step_x * t).round() as isize);
                if si < 0 || sj < 0 || si >= size as isize || sj >= size as isize {
                    break;
                }
                if at(si, sj) * amp > h0 + rise * t * light.truncate().length() {
                    lit *= 0.35;
                    break;
                }
                t += 1.0;
            }
            let shade = 0.3 + 0.7 * lit;
            let a = albedo[i as usize * size + j as usize];
            for c in 0..3 {
                rgb[(i as usize * size + j as usize) * 3 + c] = ((a[c] * shade).clamp(0.0, 1.0) * 255.0).round() as u8;
            }
        }
    }
    ReliefStyle { height: size, width: size, rgb, depth }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_has_relief_and_shading() {
        for kind in ReliefKind::ALL {
            let r = relief_style(kind, 64);
            assert_eq!((r.rgb.len(), r.depth.len()), (64 * 64 * 3, 64 * 64));
            let (lo, hi) = r.depth.iter().fold((1f32, 0f32), |(a, b), &v| (a.min(v), b.max(v)));
            assert!(lo >= 0.0 && hi <= 1.0 && hi - lo > 0.5, "{kind:?}: depth {lo}..{hi}");
            let distinct: std::collections::HashSet<&[u8]> = r.rgb.chunks_exact(3).collect();
            assert!(distinct.len() > 8, "{kind:?}: {} colours", distinct.len());
        }
        assert_eq!(relief_style(ReliefKind::Beads, 32).rgb, relief_style(ReliefKind::Beads, 32).rgb);
    }
}
