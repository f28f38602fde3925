//! The binary encoding of COLMAP models (`cameras.bin`, `images.bin`,
//! `points3D.bin`).
//!
//! Counts come from the file, so every count is checked against the bytes
//! left before anything is allocated or looped over: a corrupt count fails at
//! once instead of exhausting memory, and a short file fails with the record
//! and byte offset where it ends.
//!
//! The record types and their checks, shared with the text readers
//! (`colmap.rs`, `colmap_points.rs`, which call this for `.bin` files), are
//! `colmap_records.rs`'s.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use super::CameraError;
use super::colmap_records::{
    ColmapCamera, ColmapImage, ColmapPoints, MODELS, check_image, check_point, insert_camera, known_models,
};

/// A little-endian reader that knows the file length, so every read and
/// every count is checked against the bytes that are really there.
struct BinReader {
    path: PathBuf,
    inner: BufReader<File>,
    pos: u64,
    len: u64,
}

impl BinReader {
    fn open(path: &Path) -> Result<Self, CameraError> {
        let file = File::open(path).map_err(|e| CameraError::io(path, e))?;
        let len = file.metadata().map_err(|e| CameraError::io(path, e))?.len();
        Ok(Self { path: path.to_path_buf(), inner: BufReader::new(file), pos: 0, len })
    }

    fn remaining(&self) -> u64 {
        self.len - self.pos
    }

    fn need(&self, n: u64, record: &str) -> Result<(), CameraError> {
        if n > self.remaining() {
            return Err(CameraError::Truncated {
                path: self.path.clone(),
                record: record.into(),
                offset: self.pos,
                needed: n,
                available: self.remaining(),
            });
        }
        Ok(())
    }

    fn bytes<const N: usize>(&mut self, record: &str) -> Result<[u8; N], CameraError> {
        self.need(N as u64, record)?;
        let mut b = [0u8; N];
        self.inner.read_exact(&mut b).map_err(|e| CameraError::io(&self.path, e))?;
        self.pos += N as u64;
        Ok(b)
    }

    fn u32(&mut self, record: &str) -> Result<u32, CameraError> {
        self.bytes(record).map(u32::from_le_bytes)
    }

    fn i32(&mut self, record: &str) -> Result<i32, CameraError> {
        self.bytes(record).map(i32::from_le_bytes)
    }

    fn u64(&mut self, record: &str) -> Result<u64, CameraError> {
        self.bytes(record).map(u64::from_le_bytes)
    }

    fn f64(&mut self, record: &str) -> Result<f64, CameraError> {
        self.bytes(record).map(f64::from_le_bytes)
    }

    fn skip(&mut self, n: u64, record: &str) -> Result<(), CameraError> {
        self.need(n, record)?;
        let by =
            i64::try_from(n).map_err(|_| CameraError::format(&self.path, record, "a skippable size", n.to_string()))?;
        self.inner.seek_relative(by).map_err(|e| CameraError::io(&self.path, e))?;
        self.pos += n;
        Ok(())
    }

    /// A NUL-terminated string, bounded by the file.
    fn cstr(&mut self, record: &str) -> Result<String, CameraError> {
        let mut out = Vec::new();
        loop {
            let [b] = self.bytes::<1>(record)?;
            if b == 0 {
                return Ok(String::from_utf8_lossy(&out).into_owned());
            }
            out.push(b);
        }
    }

    /// A record count, rejected when even minimal records would not fit.
    fn count(&mut self, record: &str, min_record_bytes: u64) -> Result<u64, CameraError> {
        let n = self.u64(record)?;
        let fits = n.checked_mul(min_record_bytes).is_some_and(|b| b <= self.remaining());
        if !fits {
            return Err(CameraError::format(
                &self.path,
                record,
                format!(
                    "a count whose records fit in the {} bytes left (at least {min_record_bytes} bytes each)",
                    self.remaining()
                ),
                n.to_string(),
            ));
        }
        Ok(n)
    }

    fn u32_of_u64(&mut self, record: &str) -> Result<u32, CameraError> {
        let v = self.u64(record)?;
        u32::try_from(v).map_err(|_| CameraError::format(&self.path, record, "a value below 2^32", v.to_string()))
    }
}

pub(crate) fn read_cameras_bin(path: &Path) -> Result<BTreeMap<u32, ColmapCamera>, CameraError> {
    let mut r = BinReader::open(path)?;
    // camera_id u32, model_id i32, width u64, height u64, then ≥ 3 f64 params.
    let n = r.count("num_cameras", 4 + 4 + 8 + 8 + 3 * 8)?;
    let mut map = BTreeMap::new();
    for k in 0..n {
        let rec = format!("camera record {k}");
        let id = r.u32(&rec)?;
        let rec = format!("camera {id}");
        let model_id = r.i32(&format!("{rec}.model_id"))?;
        let model = MODELS.iter().find(|m| m.id == model_id).ok_or_else(|| CameraError::UnknownModel {
            path: path.to_path_buf(),
            camera_id: id.into(),
            model: format!("model id {model_id}"),
            known: known_models(),
        })?;
        let width = r.u32_of_u64(&format!("{rec}.width"))?;
        let height = r.u32_of_u64(&format!("{rec}.height"))?;
        let prec = format!("{rec}.params ({} for {})", model.params, model.name);
        r.need(8 * model.params as u64, &prec)?;
        let params = (0..model.params).map(|_| r.f64(&prec)).collect::<Result<Vec<_>, _>>()?;
        insert_camera(path, &mut map, id, ColmapCamera { model, width, height, params })?;
    }
    trailing(&r)?;
    Ok(map)
}

pub(crate) fn read_images_bin(path: &Path) -> Result<Vec<ColmapImage>, CameraError> {
    let mut r = BinReader::open(path)?;
    // image_id u32, qvec 4 f64, tvec 3 f64, camera_id u32, name ≥ 1 byte, num_points2D u64.
    const MIN_IMAGE: u64 = 4 + 7 * 8 + 4 + 1 + 8;
    let n = r.count("num_reg_images", MIN_IMAGE)?;
    let mut images = Vec::with_capacity(n as usize);
    for k in 0..n {
        let rec = format!("image record {k}");
        let id = r.u32(&rec)?;
        let rec = format!("image {id}");
        let mut qvec = [0.0; 4];
        for v in &mut qvec {
            *v = r.f64(&format!("{rec}.qvec"))?;
        }
        let mut tvec = [0.0; 3];
        for v in &mut tvec {
            *v = r.f64(&format!("{rec}.tvec"))?;
        }
        let camera_id = r.u32(&format!("{rec}.camera_id"))?;
        let name = r.cstr(&format!("{rec}.name"))?;
        // x f64, y f64, point3D_id i64 per 2D point.
        let points = r.count(&format!("{rec} ({name}).num_points2D"), 24)?;
        r.skip(points * 24, &format!("{rec} ({name}).points2D"))?;
        let im = ColmapImage { id, qvec, tvec, camera_id, name };
        check_image(path, &im)?;
        images.push(im);
    }
    trailing(&r)?;
    Ok(images)
}

pub(crate) fn read_points3d_bin(path: &Path) -> Result<ColmapPoints, CameraError> {
    let mut r = BinReader::open(path)?;
    // point3D_id u64, xyz 3 f64, rgb 3 u8, error f64, track_length u64.
    const MIN_POINT: u64 = 8 + 3 * 8 + 3 + 8 + 8;
    let n = r.count("num_points3D", MIN_POINT)?;
    let mut points = ColmapPoints::with_capacity(n as usize);
    for k in 0..n {
        let id = r.u64(&format!("point record {k}"))?;
        let rec = format!("point {id}");
        let mut xyz = [0.0; 3];
        for v in &mut xyz {
            *v = r.f64(&format!("{rec}.xyz"))?;
        }
        let rgb = r.bytes::<3>(&format!("{rec}.rgb"))?;
        r.f64(&format!("{rec}.error"))?;
        // image_id i32, point2D_idx i32 per track element.
        let track = r.count(&format!("{rec}.track_length"), 8)?;
        r.skip(track * 8, &format!("{rec}.track"))?;
        let p = check_point(path, &rec, xyz)?;
        points.positions.push(p);
        points.colors.push(rgb);
    }
    trailing(&r)?;
    Ok(points)
}

fn trailing(r: &BinReader) -> Result<(), CameraError> {
    if r.remaining() != 0 {
        return Err(CameraError::format(
            &r.path,
            "end of file",
            format!("the file to end after the last record at byte {}", r.pos),
            format!("{} more bytes", r.remaining()),
        ));
    }
    Ok(())
}
