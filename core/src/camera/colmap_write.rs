//! Writing cameras as a COLMAP sparse model, text or binary: for exporting the
//! studio's cameras (orbit paths included) to other tools, and for round-trip
//! tests of the reader.
//!
//! Every camera becomes one `PINHOLE` camera (id `k + 1`) and one image (id
//! `k + 1`) without 2D points. Values are written as `f64` converted from the
//! stored `f32`, so the text form reads back bit-exact.

use std::path::Path;

use glam::DQuat;

use super::{Camera, CameraError};

/// The COLMAP world-to-camera quaternion `(w, x, y, z)` of a camera, `w ≥ 0`.
fn qvec(c: &Camera) -> [f64; 4] {
    let q = DQuat::from_mat3(&c.rotation.as_dmat3()).normalize();
    let q = if q.w < 0.0 { -q } else { q };
    [q.w, q.x, q.y, q.z]
}

/// Writes the model's two files into `dir`, made if needed, both or neither
/// ([`crate::io::replace_all`]): a failed write keeps the old model whole, not
/// new cameras beside old images.
fn write(dir: &Path, files: [(&str, &[u8]); 2]) -> Result<(), CameraError> {
    crate::io::create_folder(dir).map_err(|e| CameraError::io(dir, e))?;
    let files = files.map(|(name, bytes)| (dir.join(name), bytes));
    crate::io::replace_all(&files).map_err(|(path, e)| CameraError::io(path, e))
}

/// Writes `cameras.txt` and `images.txt` into `dir` (created if needed).
pub fn write_colmap_text(dir: impl AsRef<Path>, cameras: &[Camera]) -> Result<(), CameraError> {
    let dir = dir.as_ref();
    let mut out = String::from(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    out += &format!("# Number of cameras: {}\n", cameras.len());
    for (k, c) in cameras.iter().enumerate() {
        out += &format!(
            "{} PINHOLE {} {} {} {} {} {}\n",
            k + 1,
            c.width,
            c.height,
            f64::from(c.fx),
            f64::from(c.fy),
            f64::from(c.cx),
            f64::from(c.cy)
        );
    }
    let cameras_txt = out;

    let mut out = String::from(
        "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    out += &format!("# Number of images: {}, mean observations per image: 0\n", cameras.len());
    for (k, c) in cameras.iter().enumerate() {
        let [qw, qx, qy, qz] = qvec(c);
        let t = c.translation.as_dvec3();
        out += &format!("{} {qw} {qx} {qy} {qz} {} {} {} {} {}\n\n", k + 1, t.x, t.y, t.z, k + 1, c.name);
    }
    write(dir, [("cameras.txt", cameras_txt.as_bytes()), ("images.txt", out.as_bytes())])
}

/// Writes `cameras.bin` and `images.bin` into `dir` (created if needed).
pub fn write_colmap_binary(dir: impl AsRef<Path>, cameras: &[Camera]) -> Result<(), CameraError> {
    let dir = dir.as_ref();
    let mut cams = Vec::new();
    cams.extend_from_slice(&(cameras.len() as u64).to_le_bytes());
    for (k, c) in cameras.iter().enumerate() {
        cams.extend_from_slice(&(k as u32 + 1).to_le_bytes());
        cams.extend_from_slice(&1i32.to_le_bytes()); // PINHOLE
        cams.extend_from_slice(&u64::from(c.width).to_le_bytes());
        cams.extend_from_slice(&u64::from(c.height).to_le_bytes());
        for v in [c.fx, c.fy, c.cx, c.cy] {
            cams.extend_from_slice(&f64::from(v).to_le_bytes());
        }
    }
    let mut ims = Vec::new();
    ims.extend_from_slice(&(cameras.len() as u64).to_le_bytes());
    for (k, c) in cameras.iter().enumerate() {
        ims.extend_from_slice(&(k as u32 + 1).to_le_bytes());
        let t = c.translation.as_dvec3();
        for v in qvec(c).into_iter().chain([t.x, t.y, t.z]) {
            ims.extend_from_slice(&v.to_le_bytes());
        }
        ims.extend_from_slice(&(k as u32 + 1).to_le_bytes());
        ims.extend_from_slice(c.name.as_bytes());
        ims.push(0);
        ims.extend_from_slice(&0u64.to_le_bytes());
    }
    write(dir, [("cameras.bin", &cams), ("images.bin", &ims)])
}
