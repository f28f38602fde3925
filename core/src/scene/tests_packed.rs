//! Synthetic compressed PLY, SPZ (gzip v3 and zstd v4) and SOG files: exact
//! decoding of known values, and the ways each container can be broken.

use std::path::Path;
use std::time::Instant;

use super::super::spz::encode_for_test;
use super::super::test_util::{Scratch, scratch};
use super::super::{SH_C0, SceneError, load, load_from_bytes};
use super::{expect_err, write};

// ---------------------------------------------------------------- compressed PLY

const CHUNK_PROPS: [&str; 18] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
    "min_r",
    "min_g",
    "min_b",
    "max_r",
    "max_g",
    "max_b",
];

/// One chunk, two vertices, optional degree-1 `sh` element.
fn compressed(chunks: usize, position_type: &str, sh_props: usize) -> Vec<u8> {
    let mut h = format!("ply\nformat binary_little_endian 1.0\nelement chunk {chunks}\n");
    for p in CHUNK_PROPS {
        h.push_str(&format!("property float {p}\n"));
    }
    h.push_str(&format!("element vertex 2\nproperty {position_type} packed_position\n"));
    h.push_str("property uint packed_rotation\nproperty uint packed_scale\nproperty uint packed_color\n");
    if sh_props > 0 {
        h.push_str("element sh 2\n");
        for j in 0..sh_props {
            h.push_str(&format!("property uchar f_rest_{j}\n"));
        }
    }
    h.push_str("end_header\n");
    let mut b = h.into_bytes();
    let bounds: [f32; 18] =
        [-1.0, -2.0, -3.0, 1.0, 2.0, 3.0, -5.0, -6.0, -7.0, -1.0, -2.0, -3.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    for _ in 0..chunks {
        b.extend(bounds.iter().flat_map(|v| v.to_le_bytes()));
    }
    let mid = 511u32;
    let words: [[u32; 4]; 2] = [
        [2047 << 21, (mid << 20) | (mid << 10) | mid, 0, 0xff_00_80_ff],
        [(1023 << 11) | 2047, (3 << 30) | (mid << 20) | (mid << 10) | mid, 0xffff_ffff, 0x00_00_00_80],
    ];
    for w in words {
        b.extend(w.iter().flat_map(|v| v.to_le_bytes()));
    }
    for i in 0..2 * sh_props {
        b.push(if i % 2 == 0 { 0 } else { 255 });
    }
    b
}

#[test]
fn compressed_ply_decodes_known_values() {
    let dir = scratch("cply");
    let g = load(write(&dir, "c.compressed.ply", &compressed(1, "uint", 9))).expect("load");
    assert_eq!((g.len(), g.sh_degree), (2, 1));
    assert_eq!(g.means[0], [1.0, -2.0, -3.0]);
    assert_eq!(g.means[1], [-1.0, 2.0 * (1023.0 / 1023.0), 3.0]);
    assert_eq!(g.log_scales[0], [-5.0, -6.0, -7.0]);
    assert_eq!(g.log_scales[1], [-1.0, -2.0, -3.0]);
    assert!((g.quats[0][0] - 1.0).abs() < 1e-5 && (g.quats[1][3] - 1.0).abs() < 1e-5);
    let dc = g.sh_of(0);
    assert!((dc[0] - 0.5 / SH_C0).abs() < 1e-6 && (dc[1] + 0.5 / SH_C0).abs() < 1e-6);
    assert!(g.opacity_logits[0] > 13.0 && g.opacity_logits[1].abs() < 0.01);
    // sh row 0 is bytes 0,255,0,… (f_rest_0 = 0 → −4, f_rest_1 = 255 → 4), channel-major.
    assert_eq!(g.sh_of(0)[3], -4.0); // coefficient 1, red = f_rest_0
    assert_eq!(g.sh_of(0)[6], 4.0); // coefficient 2, red = f_rest_1
}

#[test]
fn compressed_ply_structure_errors() {
    let dir = scratch("cply_bad");
    expect_err(
        &write(&dir, "chunks.ply", &compressed(2, "uint", 0)),
        &["element chunk", "1 chunks for 2 vertices", "2 chunks"],
    );
    expect_err(
        &write(&dir, "type.ply", &compressed(1, "float", 0)),
        &["vertex.packed_position", "type uint", "type float"],
    );
    expect_err(&write(&dir, "sh.ply", &compressed(1, "uint", 10)), &["element sh", "10 properties"]);
    let mut b = compressed(1, "uint", 0);
    b.truncate(b.len() - 3);
    expect_err(&write(&dir, "cut.ply", &b), &["element vertex", "a count of 2"]);
    // Renaming a colour bound keeps the byte length but loses the property.
    let bytes: Vec<u8> = compressed(1, "uint", 0);
    let at = bytes.windows(5).position(|w| w == b"max_b").expect("max_b");
    let mut renamed = bytes.clone();
    renamed[at + 4] = b'q';
    expect_err(&write(&dir, "renamed.ply", &renamed), &["chunk.max_b", "no such property"]);
    let mut nan = compressed(1, "uint", 0);
    let start = nan.windows(11).position(|w| w == b"end_header\n").expect("end") + 11;
    nan[start + 4..start + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    expect_err(&write(&dir, "nan.ply", &nan), &["chunk 0: min_y", "finite"]);
}

// ---------------------------------------------------------------- SPZ

/// Two Gaussians of degree 1 as raw SPZ arrays.
fn spz_parts() -> [Vec<u8>; 6] {
    let fixed = |v: f32| {
        let i = (v * 4096.0).round() as i32;
        [i as u8, (i >> 8) as u8, (i >> 16) as u8]
    };
    let pos: Vec<u8> = [1.0, 2.0, -3.0, -0.5, 0.25, 100.0].iter().flat_map(|&v| fixed(v)).collect();
    let alphas = vec![255, 0];
    let colours = vec![128, 0, 255, 128, 128, 128];
    let scales = vec![160, 0, 255, 160, 160, 160];
    let mut rot = Vec::new();
    rot.extend_from_slice(&(3u32 << 30).to_le_bytes()); // identity, w largest
    rot.extend_from_slice(&0u32.to_le_bytes()); // x largest, others +0
    let sh = vec![192; 18];
    [pos, alphas, colours, scales, rot, sh]
}

#[test]
fn spz_gzip_v3_and_zstd_v4_decode_the_same_known_values() {
    let dir = scratch("spz");
    let v3 = load(write(&dir, "a.spz", &encode_for_test(3, 2, 1, &spz_parts()))).expect("v3");
    let v4 = load(write(&dir, "b.spz", &encode_for_test(4, 2, 1, &spz_parts()))).expect("v4");
    assert_eq!(v3, v4);
    let g = v3;
    // RUB → RDF: y and z negated.
    assert_eq!(g.means[0], [1.0, -2.0, 3.0]);
    assert_eq!(g.means[1], [-0.5, -0.25, -100.0]);
    assert_eq!(g.quats[0], [1.0, 0.0, -0.0, -0.0]);
    assert_eq!(g.quats[1], [0.0, 1.0, -0.0, -0.0]);
    assert_eq!(g.log_scales[0], [0.0, -10.0, 255.0 / 16.0 - 10.0]);
    assert!(g.opacity_logits[0] > 13.0 && g.opacity_logits[1] < -13.0);
    assert!((g.sh_of(0)[0] - (128.0 / 255.0 - 0.5) / 0.15).abs() < 1e-6);
    assert!((g.sh_of(0)[1] - (-0.5 / 0.15)).abs() < 1e-6);
    // SH 0.5 everywhere, with the band-1 signs of the (y, z) flip: y −, z −, x +.
    assert_eq!(&g.sh_of(0)[3..], &[-0.5, -0.5, -0.5, -0.5, -0.5, -0.5, 0.5, 0.5, 0.5]);
}

#[test]
fn spz_broken_files() {
    let dir = scratch("spz_bad");
    let mut gz = vec![0x1f, 0x8b, 8, 0];
    gz.extend_from_slice(b"definitely not deflate data at all");
    expect_err(&write(&dir, "bad.spz", &gz), &["gzip"]);

    let v3 = encode_for_test(3, 2, 1, &spz_parts());
    expect_err(&write(&dir, "cut3.spz", &v3[..v3.len() / 2]), &["gzip"]);

    let v4 = encode_for_test(4, 2, 1, &spz_parts());
    expect_err(&write(&dir, "cut4.spz", &v4[..v4.len() - 3]), &["stream 5 (sh)", "truncated"]);
    expect_err(&write(&dir, "short.spz", &v4[..20]), &["header", "32-byte"]);

    let mut huge = v4.clone();
    huge[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    let t = Instant::now();
    expect_err(&write(&dir, "huge.spz", &huge), &["header.num_points", "4294967295"]);
    assert!(t.elapsed().as_secs_f64() < 0.5);

    let mut version = v4.clone();
    version[4] = 7;
    expect_err(&write(&dir, "version.spz", &version), &["header.version", "7"]);
    let mut degree = v4.clone();
    degree[12] = 4;
    expect_err(&write(&dir, "degree.spz", &degree), &["header.sh_degree", "0 to 3", "4"]);
    let mut streams = v4.clone();
    streams[15] = 5;
    expect_err(&write(&dir, "streams.spz", &streams), &["header.num_streams", "6", "5"]);
    let mut size = v4.clone();
    size[32 + 8] = 99; // positions uncompressed size
    expect_err(&write(&dir, "size.spz", &size), &["stream 0 (positions)", "18 uncompressed bytes", "99"]);
    let mut frame = v4.clone();
    let first = 32 + 16 * 6;
    frame[first..first + 4].copy_from_slice(b"JUNK");
    expect_err(&write(&dir, "frame.spz", &frame), &["stream 0 (positions)", "zstd"]);
}

// ---------------------------------------------------------------- SOG

fn webp(dir: &Path, name: &str, w: u32, h: u32, rgba: &[u8]) {
    let mut out = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut out)
        .encode(rgba, w, h, image::ExtendedColorType::Rgba8)
        .expect("encode webp");
    std::fs::write(dir.join(name), out).expect("write webp");
}

fn sog_meta(count: usize, palette: usize) -> String {
    let code = |f: &dyn Fn(usize) -> f32| (0..256).map(|i| f(i).to_string()).collect::<Vec<_>>().join(",");
    format!(
        r#"{{"version":2,"count":{count},
        "means":{{"mins":[-1,-1,-1],"maxs":[1,1,1],"files":["means_l.webp","means_u.webp"]}},
        "scales":{{"codebook":[{}],"files":["scales.webp"]}},
        "quats":{{"files":["quats.webp"]}},
        "sh0":{{"codebook":[{}],"files":["sh0.webp"]}},
        "shN":{{"count":{palette},"bands":1,"codebook":[{}],"files":["shN_centroids.webp","shN_labels.webp"]}}}}"#,
        code(&|i| i as f32 * 0.01 - 5.0),
        code(&|i| (i as f32 - 128.0) / 100.0),
        code(&|i| (i as f32 - 128.0) / 64.0),
    )
}

/// A two-Gaussian SOG directory; `quat_tag` and `label1` let tests break it.
fn sog_dir(name: &str, quat_tag: u8, label1: u8) -> Scratch {
    let dir = scratch(name);
    webp(&dir, "means_l.webp", 2, 1, &[255, 0, 0, 255, 0, 255, 0, 255]);
    webp(&dir, "means_u.webp", 2, 1, &[255, 0, 128, 255, 0, 255, 0, 255]);
    webp(&dir, "quats.webp", 2, 1, &[128, 128, 128, quat_tag, 255, 128, 0, 255]);
    webp(&dir, "scales.webp", 2, 1, &[0, 1, 255, 255, 10, 20, 30, 255]);
    webp(&dir, "sh0.webp", 2, 1, &[128, 228, 28, 255, 0, 0, 0, 128]);
    let mut centroids = vec![255u8; 192 * 4];
    for (p, v) in [(0usize, 128u8), (1, 192)] {
        for j in 0..3 {
            let t = (p * 3 + j) * 4;
            centroids[t..t + 3].copy_from_slice(&[v, v + j as u8, v]);
        }
    }
    webp(&dir, "shN_centroids.webp", 192, 1, &centroids);
    webp(&dir, "shN_labels.webp", 2, 1, &[1, 0, 0, 255, label1, 0, 0, 255]);
    std::fs::write(dir.join("meta.json"), sog_meta(2, 2)).expect("meta");
    dir
}

#[test]
fn sog_decodes_known_values() {
    let dir = sog_dir("sog", 252, 0);
    let g = load(&dir).expect("load");
    assert_eq!(load(dir.join("meta.json")).expect("meta.json"), g);
    assert_eq!((g.len(), g.sh_degree), (2, 1));
    let e1 = std::f32::consts::E - 1.0;
    assert!((g.means[0][0] - e1).abs() < 1e-5 && (g.means[0][1] + e1).abs() < 1e-5, "{:?}", g.means[0]);
    assert!((g.quats[0][0] - 1.0).abs() < 1e-4);
    // Tag 255: z is the largest; w = 1/√2, y = −1/√2 leave nothing for z.
    let h = std::f32::consts::FRAC_1_SQRT_2;
    assert!((g.quats[1][0] - h).abs() < 1e-6 && (g.quats[1][2] + h).abs() < 1e-6 && g.quats[1][3] == 0.0);
    let code = |i: f32| i * 0.01 - 5.0;
    assert_eq!(g.log_scales[0], [code(0.0), code(1.0), code(255.0)]);
    assert_eq!(&g.sh_of(0)[..3], &[0.0, 1.0, -1.0]);
    assert!(g.opacity_logits[0] > 13.0 && g.opacity_logits[1].abs() < 0.01);
    // Gaussian 0 → palette 1 (bytes 192, 192+j, 192): (64/64, (64+j)/64, 64/64).
    assert_eq!(&g.sh_of(0)[3..6], &[1.0, 1.0, 1.0]);
    assert_eq!(&g.sh_of(0)[6..9], &[1.0, 65.0 / 64.0, 1.0]);
    // Gaussian 1 → palette 0 (bytes 128, 128+j, 128).
    assert_eq!(&g.sh_of(1)[9..12], &[0.0, 2.0 / 64.0, 0.0]);
}

#[test]
fn sog_broken_inputs() {
    let dir = sog_dir("sog_bad", 252, 0);
    let meta = dir.join("meta.json");
    std::fs::write(&meta, "{\"version\": 2, \"count\": ").expect("write");
    let e = expect_err(&meta, &["meta.json", "SOG metadata", "EOF"]);
    assert!(matches!(e, SceneError::Format { .. }));
    std::fs::write(&meta, "{\"version\": 2}").expect("write");
    expect_err(&meta, &["missing field"]);
    std::fs::write(&meta, sog_meta(2, 2).replace("\"version\":2,", "")).expect("write");
    expect_err(&meta, &["version", "SOG v1"]);
    std::fs::write(&meta, sog_meta(5, 2)).expect("write");
    let e = load(&meta).expect_err("too few texels");
    let msg = e.to_string();
    assert!(msg.contains("means_l.webp") && msg.contains("at least 5 texels") && msg.contains("2×1"), "{msg}");
    std::fs::write(&meta, sog_meta(2, 2).replace("means_l.webp", "../x.webp")).expect("write");
    expect_err(&meta, &["means", "beside meta.json"]);
    std::fs::write(&meta, sog_meta(2, 2)).expect("write");
    std::fs::remove_file(dir.join("quats.webp")).expect("rm");
    let e = load(&dir).expect_err("missing texture");
    assert!(matches!(e, SceneError::Io { .. }) && e.to_string().contains("quats.webp"), "{e}");
    std::fs::write(dir.join("quats.webp"), b"RIFF\x10\x00\x00\x00WEBPjunkjunk").expect("write");
    let e = load(&dir).expect_err("garbage texture");
    assert!(e.to_string().contains("quats.webp") && e.to_string().contains("a WebP image"), "{e}");

    let e = load(sog_dir("sog_tag", 17, 0)).expect_err("bad tag");
    // A bad texel names its texture's file, not meta.json.
    let msg = e.to_string();
    assert!(msg.contains("quats.webp: quats texel 0") && msg.contains("17") && !msg.contains("meta.json"), "{msg}");
    let e = load(sog_dir("sog_label", 252, 9)).expect_err("bad label");
    let msg = e.to_string();
    assert!(msg.contains("shN_labels.webp: shN_labels texel 1") && msg.contains("below 2"), "{msg}");
}

// ---------------------------------------------------------------- fuzzing

/// Every truncation and a few thousand single-byte corruptions of each
/// synthetic file either load or fail with an error: none may panic.
#[test]
fn truncations_and_corruptions_never_panic() {
    let dir = scratch("fuzz");
    let mut ascii = String::from("ply\nformat ascii 1.0\nelement vertex 2\n");
    for p in super::PROPS {
        ascii.push_str(&format!("property float {p}\n"));
    }
    ascii.push_str("end_header\n0 0 0 0.5 0.1 0.2 0.3 -1 -2 -3 1 0 0 0\n1 1 1 0.5 0.1 0.2 0.3 -1 -2 -3 1 0 0 0\n");
    let files: Vec<(&str, Vec<u8>)> = vec![
        ("le.ply", super::binary_le(3)),
        ("ascii.ply", ascii.into_bytes()),
        ("c.ply", compressed(1, "uint", 9)),
        ("v3.spz", encode_for_test(3, 2, 1, &spz_parts())),
        ("v4.spz", encode_for_test(4, 2, 1, &spz_parts())),
    ];
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut rand = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut outcomes = [0usize; 2];
    let mut try_load = |p: &Path, b: &[u8]| outcomes[load_from_bytes(p, b).is_ok() as usize] += 1;
    for (name, bytes) in &files {
        let p = dir.join(name);
        for len in 0..bytes.len() {
            try_load(&p, &bytes[..len]);
        }
        for _ in 0..1000 {
            let mut b = bytes.clone();
            for _ in 0..1 + rand() % 3 {
                let at = (rand() as usize) % b.len();
                b[at] = rand() as u8;
            }
            try_load(&p, &b);
        }
    }
    let sog = sog_dir("fuzz_sog", 252, 0);
    let meta_path = sog.join("meta.json");
    let meta = std::fs::read(&meta_path).expect("meta");
    for len in (0..meta.len()).step_by(5) {
        try_load(&meta_path, &meta[..len]);
    }
    let quats = std::fs::read(sog.join("quats.webp")).expect("quats");
    for len in 0..quats.len() {
        std::fs::write(sog.join("quats.webp"), &quats[..len]).expect("write");
        try_load(&meta_path, &meta);
    }
    eprintln!("fuzz: {} errors, {} loads", outcomes[0], outcomes[1]);
}

/// The same SOG files zipped into a `.sog` bundle (stored or deflated) load
/// identically; broken bundles give errors naming the bundle.
#[test]
fn sog_zip_bundle() {
    use std::io::Write;
    let dir = sog_dir("sog_zip", 252, 0);
    let want = load(&dir).expect("directory");
    let names = crate::scene::sog_write::FILE_NAMES;
    let bundle = |method: zip::CompressionMethod, skip: &str| {
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let opts = zip::write::SimpleFileOptions::default().compression_method(method);
        for n in names.iter().filter(|n| **n != skip) {
            w.start_file(*n, opts).expect("start");
            w.write_all(&std::fs::read(dir.join(n)).expect("read")).expect("write");
        }
        w.finish().expect("finish").into_inner()
    };
    for method in [zip::CompressionMethod::Stored, zip::CompressionMethod::Deflated] {
        let p = write(&dir, "scene.sog", &bundle(method, ""));
        assert_eq!(load(&p).expect("bundle"), want);
    }
    expect_err(
        &write(&dir, "no_meta.sog", &bundle(zip::CompressionMethod::Stored, "meta.json")),
        &["meta.json", "zip entry"],
    );
    expect_err(
        &write(&dir, "no_quats.sog", &bundle(zip::CompressionMethod::Stored, "quats.webp")),
        &["quats.webp", "zip entry"],
    );
    expect_err(&write(&dir, "broken.sog", b"PK\x03\x04 this is not a zip archive"), &["zip archive"]);
    // Truncated bundles fail without panicking.
    let b = bundle(zip::CompressionMethod::Deflated, "");
    for len in (0..b.len() - 1).step_by(3) {
        assert!(load_from_bytes(dir.join("t.sog"), &b[..len]).is_err());
    }
}
