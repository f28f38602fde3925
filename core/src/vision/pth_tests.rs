//! Round trips through `.pth` files written here with the opcodes and layouts
//! `torch.save` uses (zip archive and the legacy stream), so the reader is
//! tested without Python or a 528 MB download.

use std::io::Write;
use std::path::PathBuf;

use super::super::weights::{VggWeights, WeightsError};

/// A storage to write: key, f32 data.
struct Storage {
    key: String,
    data: Vec<f32>,
}

/// A tensor entry: name, storage index, offset, shape, stride.
struct Entry {
    name: String,
    storage: usize,
    offset: usize,
    shape: Vec<usize>,
    stride: Vec<usize>,
}

fn unicode(out: &mut Vec<u8>, s: &str) {
    out.push(b'X');
    out.extend((s.len() as u32).to_le_bytes());
    out.extend(s.as_bytes());
}

fn int(out: &mut Vec<u8>, v: usize) {
    out.push(b'J');
    out.extend((v as i32).to_le_bytes());
}

fn int_tuple(out: &mut Vec<u8>, v: &[usize]) {
    out.push(b'(');
    for &x in v {
        int(out, x);
    }
    out.push(b't');
}

/// The state-dict pickle, as torch writes it (protocol 2, memoised globals).
/// `legacy` writes what 2017's torch did: 6-field persistent ids, tensors as
/// `torch.FloatTensor()` plus BUILD, the dict wrapped as `{"state_dict": …}`.
fn state_dict_pickle(storages: &[Storage], entries: &[Entry], legacy: bool) -> Vec<u8> {
    let mut p = vec![0x80, 2];
    if legacy {
        p.extend(b"}(");
        unicode(&mut p, "epoch");
        int(&mut p, 90);
        unicode(&mut p, "state_dict");
    }
    p.extend(b"ccollections\nOrderedDict\nq\x00)Rq\x01(");
    let mut first_storage_global = true;
    for e in entries {
        unicode(&mut p, &e.name);
        if legacy {
            p.extend(b"ctorch\nFloatTensor\n)R(");
        } else {
            p.extend(b"ctorch._utils\n_rebuild_tensor_v2\nq\x02(");
        }
        // Persistent id tuple.
        p.push(b'(');
        unicode(&mut p, "storage");
        if first_storage_global {
            p.extend(b"ctorch\nFloatStorage\nq\x03");
            first_storage_global = false;
        } else {
            p.extend(b"h\x03");
        }
        unicode(&mut p, &storages[e.storage].key);
        unicode(&mut p, "cpu");
        int(&mut p, storages[e.storage].data.len());
        if legacy {
            p.push(b'N');
        }
        p.extend(b"tQ");
        int(&mut p, e.offset);
        int_tuple(&mut p, &e.shape);
        int_tuple(&mut p, &e.stride);
        if legacy {
            p.extend(b"tb");
        } else {
            p.push(0x89);
            p.extend(b"h\x00)R");
            p.extend(b"tR");
        }
    }
    p.extend(b"u");
    if legacy {
        p.extend(b"u");
    }
    p.push(b'.');
    p
}

fn bytes_of(data: &[f32]) -> Vec<u8> {
    data.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// The shared weights laid out as torch would: weights in their own storages,
/// all biases in one shared storage at offsets, a transposed (strided) weight,
/// plus tensors the loader must skip.
fn layout(w: &VggWeights) -> (Vec<Storage>, Vec<Entry>) {
    let mut storages = Vec::new();
    let mut entries = Vec::new();
    let mut biases = Vec::new();
    let mut bias_entries = Vec::new();
    for (i, (c, idx)) in w.convs.iter().zip(super::super::weights::CONV_INDICES).enumerate() {
        let (o, k) = (c.c_out, c.c_in * 9);
        if i == 1 {
            // Stored transposed: storage is (c_in·9) × c_out, the tensor views it with swapped strides.
            let mut t = vec![0.0; o * k];
            for a in 0..o {
                for b in 0..k {
                    t[b * o + a] = c.weight[a * k + b];
                }
            }
            storages.push(Storage { key: format!("{}", storages.len()), data: t });
            entries.push(Entry {
                name: format!("features.{idx}.weight"),
                storage: storages.len() - 1,
                offset: 0,
                shape: vec![o, c.c_in, 3, 3],
                stride: vec![1, 9 * o, 3 * o, o],
            });
        } else {
            storages.push(Storage { key: format!("{}", storages.len()), data: c.weight.clone() });
            entries.push(Entry {
                name: format!("features.{idx}.weight"),
                storage: storages.len() - 1,
                offset: 0,
                shape: vec![o, c.c_in, 3, 3],
                stride: vec![k, 9, 3, 1],
            });
        }
        bias_entries.push((format!("features.{idx}.bias"), biases.len(), o));
        biases.extend(&c.bias);
    }
    storages.push(Storage { key: "biases".into(), data: biases });
    let b = storages.len() - 1;
    for (name, offset, n) in bias_entries {
        entries.push(Entry { name, storage: b, offset, shape: vec![n], stride: vec![1] });
    }
    storages.push(Storage { key: "skipme".into(), data: (0..5000).map(|i| i as f32).collect() });
    entries.push(Entry {
        name: "features.16.weight".into(),
        storage: storages.len() - 1,
        offset: 0,
        shape: vec![5000],
        stride: vec![1],
    });
    (storages, entries)
}

fn shared_weights() -> Option<VggWeights> {
    let base = std::env::var_os("GAST_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let p = base.join("data/weights/vgg19-conv3.safetensors");
    if !p.exists() {
        eprintln!("\n!!!!!!!! SKIPPED: shared data file {} is absent !!!!!!!!\n", p.display());
        return None;
    }
    VggWeights::load(&p).ok()
}

fn temp_path(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gast-pth-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    dir.join(name)
}

#[test]
fn zip_pth_loads_like_safetensors() -> Result<(), Box<dyn std::error::Error>> {
    let Some(w) = shared_weights() else { return Ok(()) };
    let (storages, entries) = layout(&w);
    let path = temp_path("vgg16-zip.pth");
    let mut z = zip::ZipWriter::new(std::fs::File::create(&path)?);
    let opts = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    z.start_file("vgg16-zip/data.pkl", opts)?;
    z.write_all(&state_dict_pickle(&storages, &entries, false))?;
    z.start_file("vgg16-zip/byteorder", opts)?;
    z.write_all(b"little")?;
    for s in &storages {
        z.start_file(format!("vgg16-zip/data/{}", s.key), opts)?;
        z.write_all(&bytes_of(&s.data))?;
    }
    z.start_file("vgg16-zip/version", opts)?;
    z.write_all(b"3\n")?;
    z.finish()?;
    let loaded = VggWeights::load(&path)?;
    let _ = std::fs::remove_file(&path);
    assert!(loaded == w, "zip .pth weights differ from the safetensors ones");
    Ok(())
}

#[test]
fn legacy_pth_loads_like_safetensors() -> Result<(), Box<dyn std::error::Error>> {
    let Some(w) = shared_weights() else { return Ok(()) };
    let (storages, entries) = layout(&w);
    let mut f = Vec::new();
    // Magic number (LONG1), protocol version 1001, sys_info.
    f.extend(b"\x80\x02\x8a\x0a\x6c\xfc\x9c\x46\xf9\x20\x6a\xa8\x50\x19.");
    f.extend(b"\x80\x02M\xe9\x03.");
    f.extend(b"\x80\x02}q\x00(X\x0d\x00\x00\x00little_endian\x88u.");
    f.extend(state_dict_pickle(&storages, &entries, true));
    // Storage keys, then each storage: element count and bytes.
    f.extend(b"\x80\x02]q\x00(");
    for s in &storages {
        unicode(&mut f, &s.key);
    }
    f.extend(b"e.");
    for s in &storages {
        f.extend((s.data.len() as u64).to_le_bytes());
        f.extend(bytes_of(&s.data));
    }
    let path = temp_path("vgg16-legacy.pth");
    std::fs::write(&path, &f)?;
    let loaded = VggWeights::load(&path)?;
    assert!(loaded == w, "legacy .pth weights differ from the safetensors ones");

    // A truncated file is an error that names the file, not a panic.
    std::fs::write(&path, &f[..f.len() - 20_200])?;
    let err = VggWeights::load(&path).err().map(|e| e.to_string()).unwrap_or_default();
    let _ = std::fs::remove_file(&path);
    assert!(err.contains("vgg16-legacy.pth"), "{err}");
    Ok(())
}

#[test]
fn missing_tensor_is_named() -> Result<(), Box<dyn std::error::Error>> {
    let Some(w) = shared_weights() else { return Ok(()) };
    let (storages, mut entries) = layout(&w);
    entries.retain(|e| e.name != "features.12.bias");
    let path = temp_path("vgg16-missing.pth");
    let mut z = zip::ZipWriter::new(std::fs::File::create(&path)?);
    let opts = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    z.start_file("archive/data.pkl", opts)?;
    z.write_all(&state_dict_pickle(&storages, &entries, false))?;
    for s in &storages {
        z.start_file(format!("archive/data/{}", s.key), opts)?;
        z.write_all(&bytes_of(&s.data))?;
    }
    z.finish()?;
    let err = VggWeights::load(&path).err();
    let _ = std::fs::remove_file(&path);
    assert!(matches!(&err, Some(WeightsError::MissingTensor { name, .. }) if name == "features.12.bias"), "{err:?}");
    Ok(())
}
