//! COLMAP's sparse point cloud (`points3D.bin` / `points3D.txt`): the SfM
//! points a 3DGS fit starts from, in the same world frame as the model's
//! cameras (and as LLFF's `poses_bounds.npy`, which was made from them).
//!
//! Only positions and colours are kept; the reprojection error and the tracks
//! (which images saw each point) are skipped.

use std::path::{Path, PathBuf};

pub use super::colmap_records::ColmapPoints;
use super::colmap_records::check_point;
use super::{CameraError, colmap_bin};

/// The `points3D` file of a dataset, if it has one: `path` is a scene folder
/// (looked in: `sparse/0/`, `sparse/`, the folder itself), a COLMAP model
/// folder, or a camera file whose folder is searched the same way (an LLFF
/// `poses_bounds.npy`, a COLMAP `cameras.bin`). Binary is preferred over text.
pub fn find_colmap_points(path: &Path) -> Option<PathBuf> {
    let root = if path.is_dir() { path } else { path.parent().unwrap_or(Path::new(".")) };
    [root.join("sparse/0"), root.join("sparse"), root.to_path_buf()]
        .iter()
        .flat_map(|d| [d.join("points3D.bin"), d.join("points3D.txt")])
        .find(|p| p.is_file())
}

/// Reads `points3D.bin` or `points3D.txt` (by extension; a folder is searched
/// as [`find_colmap_points`] does).
pub fn load_colmap_points(path: impl AsRef<Path>) -> Result<ColmapPoints, CameraError> {
    let path = path.as_ref();
    let file = if path.is_dir() {
        find_colmap_points(path).ok_or_else(|| CameraError::NotFound {
            path: path.to_path_buf(),
            expected: "points3D.bin or points3D.txt (in sparse/0/, sparse/ or the folder itself)".into(),
        })?
    } else {
        path.to_path_buf()
    };
    if file.extension().is_some_and(|e| e == "txt") {
        read_points3d_txt(&file)
    } else {
        colmap_bin::read_points3d_bin(&file)
    }
}

/// `POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)`, one
/// point per line; `#` starts a comment line.
fn read_points3d_txt(path: &Path) -> Result<ColmapPoints, CameraError> {
    let text = std::fs::read_to_string(path).map_err(|e| CameraError::io(path, e))?;
    let mut points = ColmapPoints::default();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let rec = format!("line {}", n + 1);
        let toks: Vec<&str> = line.split_whitespace().collect();
        if toks.len() < 8 || !toks.len().is_multiple_of(2) {
            return Err(CameraError::format(
                path,
                &rec,
                "POINT3D_ID X Y Z R G B ERROR then (IMAGE_ID, POINT2D_IDX) pairs (an even count of 8 or more fields)",
                format!("{} fields", toks.len()),
            ));
        }
        let bad = |field: &str, what: &str, tok: &str| CameraError::format(path, format!("{rec}.{field}"), what, tok);
        toks[0].parse::<u64>().map_err(|_| bad("POINT3D_ID", "an unsigned point id", toks[0]))?;
        let mut xyz = [0.0; 3];
        for (i, v) in xyz.iter_mut().enumerate() {
            *v = toks[1 + i].parse().map_err(|_| bad(["X", "Y", "Z"][i], "a number", toks[1 + i]))?;
        }
        let mut rgb = [0u8; 3];
        for (i, v) in rgb.iter_mut().enumerate() {
            *v = toks[4 + i].parse().map_err(|_| bad(["R", "G", "B"][i], "an integer from 0 to 255", toks[4 + i]))?;
        }
        points.positions.push(check_point(path, &rec, xyz)?);
        points.colors.push(rgb);
    }
    Ok(points)
}
