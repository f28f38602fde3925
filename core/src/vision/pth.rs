//! Reading tensors out of PyTorch `torch.save` checkpoints without Python.
//!
//! A `.pth` state dict is a pickle whose tensors point at raw storages kept
//! beside it. Two layouts exist: the zip archive of PyTorch ≥ 1.6
//! (`<name>/data.pkl` plus one stored entry `<name>/data/<key>` per storage),
//! and the older stream (magic, protocol and sys-info pickles, the state-dict
//! pickle, the list of storage keys, then each storage as an 8-byte element
//! count and its bytes), which is what torchvision's `vgg16-397923af.pth` is.
//! The unpickler understands only the opcodes `torch.save` emits for a state
//! dict and builds no Python objects: a tensor becomes its storage key,
//! offset, shape and stride, and only the storages of the wanted tensors are
//! read (the VGG16 file is 528 MB, the layers we need 7 MB).
//!
//! It returns [`super::weights`]' tensor and error types, and `weights.rs`
//! calls it for a `.pth` file (beside its safetensors reader): one loader,
//! its pickle reader in its own file by size.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use super::weights_file::{RawTensor, WeightsError};

/// A tensor as the pickle describes it.
#[derive(Clone, Debug)]
struct TensorRef {
    key: String,
    storage_type: String,
    /// In elements, including the offset of a legacy storage view.
    offset: usize,
    shape: Vec<usize>,
    stride: Vec<usize>,
}

/// The few Python values a state-dict pickle is made of.
// Payloads that are only shown in error messages (Debug) count as unread.
#[allow(dead_code)]
#[derive(Clone, Debug)]
enum Value {
    None,
    Bool(bool),
    Int(i128),
    Float(f64),
    Str(String),
    Tuple(Vec<Value>),
    List(Vec<Value>),
    Dict(Vec<(Value, Value)>),
    Global(String, String),
    /// A storage from the persistent id: (type name, key, view offset).
    Storage(String, String, usize),
    Tensor(TensorRef),
    /// Anything else; its content does not matter to us.
    Opaque,
}

/// Reads the wanted tensors (by state-dict name) from a `.pth` file of either layout.
pub(crate) fn read_tensors(path: &Path, wanted: &[String]) -> Result<HashMap<String, RawTensor>, WeightsError> {
    let file = File::open(path).map_err(|e| WeightsError::io(path, e))?;
    let mut r = BufReader::new(file);
    let mut magic = [0u8; 4];
    r.read_exact(&mut magic).map_err(|e| WeightsError::io(path, e))?;
    r.seek(SeekFrom::Start(0)).map_err(|e| WeightsError::io(path, e))?;
    if &magic == b"PK\x03\x04" { read_zip(path, r.into_inner(), wanted) } else { read_legacy(path, r, wanted) }
}

fn read_zip(path: &Path, file: File, wanted: &[String]) -> Result<HashMap<String, RawTensor>, WeightsError> {
    let bad = |found: String| WeightsError::format(path, "a PyTorch zip checkpoint", found);
    let mut zip = zip::ZipArchive::new(file).map_err(|e| bad(format!("an unreadable zip ({e})")))?;
    let pkl_name = zip
        .file_names()
        .filter_map(Result::ok)
        .find(|n| n.ends_with("data.pkl"))
        .map(|n| n.into_owned())
        .ok_or_else(|| bad("a zip without data.pkl".into()))?;
    let prefix = pkl_name.trim_end_matches("data.pkl").to_owned();
    let mut pkl = Vec::new();
    zip.by_name(&pkl_name)
        .and_then(|mut f| f.read_to_end(&mut pkl).map_err(Into::into))
        .map_err(|e| bad(format!("an unreadable {pkl_name} ({e})")))?;
    if let Ok(mut f) = zip.by_name(&format!("{prefix}byteorder")) {
        let mut order = String::new();
        let _ = f.read_to_string(&mut order);
        if order.trim() == "big" {
            return Err(bad("big-endian storages".into()));
        }
    }
    let refs = tensor_refs(path, &mut pkl.as_slice(), wanted)?;
    let mut out = HashMap::new();
    for (name, t) in refs.wanted {
        let entry = format!("{prefix}data/{}", t.key);
        let mut bytes = Vec::new();
        zip.by_name(&entry)
            .and_then(|mut f| f.read_to_end(&mut bytes).map_err(Into::into))
            .map_err(|e| bad(format!("storage {entry} unreadable ({e})")))?;
        out.insert(name, gather(path, &t, &bytes)?);
    }
    Ok(out)
}

fn read_legacy(
    path: &Path,
    mut r: BufReader<File>,
    wanted: &[String],
) -> Result<HashMap<String, RawTensor>, WeightsError> {
    let io = |e| WeightsError::io(path, e);
    let file_len = r.get_ref().metadata().map_err(io)?.len();
    let magic = unpickle(path, &mut r)?;
    if !matches!(magic, Value::Int(0x1950a86a20f9469cfc6c)) {
        return Err(WeightsError::format(
            path,
            "a PyTorch checkpoint (zip, or pickle with torch's magic number)",
            format!("{magic:?}"),
        ));
    }
    let _protocol = unpickle(path, &mut r)?;
    let _sys_info = unpickle(path, &mut r)?;
    let refs = tensor_refs(path, &mut r, wanted)?;
    let Value::List(keys) = unpickle(path, &mut r)? else {
        return Err(WeightsError::format(path, "the list of storage keys", "something else"));
    };
    let mut by_key: HashMap<&str, Vec<(&String, &TensorRef)>> = HashMap::new();
    for (name, t) in &refs.wanted {
        by_key.entry(t.key.as_str()).or_default().push((name, t));
    }
    let mut out = HashMap::new();
    for key in keys {
        if out.len() == refs.wanted.len() {
            break;
        }
        let Value::Str(key) = key else {
            return Err(WeightsError::format(path, "string storage keys", format!("{key:?}")));
        };
        let mut count = [0u8; 8];
        r.read_exact(&mut count).map_err(io)?;
        let count = u64::from_le_bytes(count);
        let users = by_key.get(key.as_str());
        let ty = refs.storage_types.get(&key).map_or("an unreferenced storage", String::as_str);
        let Some(elem) = element_size(ty) else {
            return Err(WeightsError::format(path, "a known storage type", format!("{ty} for storage {key}")));
        };
        let len = count.saturating_mul(elem as u64);
        let at = r.stream_position().map_err(io)?;
        if at.saturating_add(len) > file_len {
            return Err(WeightsError::format(
                path,
                format!("storage {key} of {len} bytes at offset {at}"),
                format!("a file of {file_len} bytes (truncated download?)"),
            ));
        }
        match users {
            Some(users) => {
                let mut bytes = vec![0u8; usize::try_from(len).unwrap_or(usize::MAX)];
                r.read_exact(&mut bytes).map_err(io)?;
                for (name, t) in users {
                    out.insert((*name).clone(), gather(path, t, &bytes)?);
                }
            }
            None => r.seek_relative(i64::try_from(len).unwrap_or(i64::MAX)).map_err(io)?,
        }
    }
    Ok(out)
}

fn element_size(storage_type: &str) -> Option<usize> {
    Some(match storage_type {
        "DoubleStorage" | "LongStorage" => 8,
        "FloatStorage" | "IntStorage" => 4,
        "HalfStorage" | "BFloat16Storage" | "ShortStorage" => 2,
        "ByteStorage" | "CharStorage" | "BoolStorage" => 1,
        _ => return None,
    })
}

/// The wanted tensors of a state dict, and the element type of every storage
/// any of its tensors uses (to step over the unwanted ones in a legacy file).
struct Refs {
    wanted: HashMap<String, TensorRef>,
    storage_types: HashMap<String, String>,
}

/// Unpickles the state dict and returns the wanted tensors' references.
fn tensor_refs(path: &Path, r: &mut impl Read, wanted: &[String]) -> Result<Refs, WeightsError> {
    let mut dict = match unpickle(path, r)? {
        Value::Dict(d) => d,
        other => return Err(WeightsError::format(path, "a state dict (a dict of tensors)", format!("{other:?}"))),
    };
    // Training checkpoints wrap the state dict: {"state_dict": {...}} or {"model": {...}}.
    let inner = dict
        .iter()
        .position(|(k, v)| matches!((k, v), (Value::Str(k), Value::Dict(_)) if k == "state_dict" || k == "model"));
    if let Some(i) = inner
        && let (_, Value::Dict(d)) = dict.swap_remove(i)
    {
        dict = d;
    }
    let mut refs = Refs { wanted: HashMap::new(), storage_types: HashMap::new() };
    for (k, v) in dict {
        if let (Value::Str(k), Value::Tensor(t)) = (k, v) {
            refs.storage_types.insert(t.key.clone(), t.storage_type.clone());
            let k = k.strip_prefix("module.").map(str::to_owned).unwrap_or(k);
            if wanted.contains(&k) {
                refs.wanted.insert(k, t);
            }
        }
    }
    Ok(refs)
}

/// Copies a (possibly strided) f32 tensor out of its storage bytes.
fn gather(path: &Path, t: &TensorRef, bytes: &[u8]) -> Result<RawTensor, WeightsError> {
    if t.storage_type != "FloatStorage" {
        return Ok(RawTensor { shape: t.shape.clone(), dtype: t.storage_type.clone(), data: None });
    }
    let numel: usize = t.shape.iter().product();
    let storage_len = bytes.len() / 4;
    let max = t.offset + t.shape.iter().zip(&t.stride).map(|(n, s)| n.saturating_sub(1) * s).sum::<usize>();
    if numel > 0 && max >= storage_len {
        return Err(WeightsError::format(
            path,
            format!("storage {} to hold element {max}", t.key),
            format!("{storage_len} elements"),
        ));
    }
    let read = |i: usize| {
        let b = &bytes[4 * i..4 * i + 4];
        f32::from_le_bytes([b[0], b[1], b[2], b[3]])
    };
    let mut data = Vec::with_capacity(numel);
    let mut idx = vec![0usize; t.shape.len()];
    for _ in 0..numel {
        data.push(read(t.offset + idx.iter().zip(&t.stride).map(|(i, s)| i * s).sum::<usize>()));
        for d in (0..idx.len()).rev() {
            idx[d] += 1;
            if idx[d] < t.shape[d] {
                break;
            }
            idx[d] = 0;
        }
    }
    Ok(RawTensor { shape: t.shape.clone(), dtype: t.storage_type.clone(), data: Some(data) })
}

/// One pickle from the reader, as far as a state dict needs.
fn unpickle(path: &Path, r: &mut impl Read) -> Result<Value, WeightsError> {
    let bad = |found: String| WeightsError::format(path, "a pickled PyTorch state dict", found);
    let mut stack: Vec<Value> = Vec::new();
    let mut marks: Vec<usize> = Vec::new();
    let mut memo: HashMap<u32, Value> = HashMap::new();
    let io = |e: std::io::Error| bad(format!("a truncated pickle ({e})"));
    macro_rules! bytes {
        ($n:expr) => {{
            let mut b = vec![0u8; $n];
            r.read_exact(&mut b).map_err(io)?;
            b
        }};
    }
    macro_rules! uint {
        ($n:expr) => {{
            let b = bytes!($n);
            let mut v = 0u64;
            for (i, x) in b.iter().enumerate() {
                v |= (*x as u64) << (8 * i);
            }
            v
        }};
    }
    macro_rules! pop {
        () => {
            stack.pop().ok_or_else(|| bad("a pickle popping an empty stack".into()))?
        };
    }
    let line = |r: &mut dyn Read| -> Result<String, WeightsError> {
        let mut s = Vec::new();
        let mut b = [0u8; 1];
        loop {
            r.read_exact(&mut b).map_err(io)?;
            if b[0] == b'\n' {
                return Ok(String::from_utf8_lossy(&s).into_owned());
            }
            s.push(b[0]);
        }
    };
    loop {
        let op = bytes!(1)[0];
        match op {
            0x80 => drop(bytes!(1)),                                                 // PROTO
            0x95 => drop(bytes!(8)),                                                 // FRAME
            b'.' => return stack.pop().ok_or_else(|| bad("an empty pickle".into())), // STOP
            b'(' => marks.push(stack.len()),                                         // MARK
            b'N' => stack.push(Value::None),
            0x88 => stack.push(Value::Bool(true)),
            0x89 => stack.push(Value::Bool(false)),
            b'K' => stack.push(Value::Int(uint!(1) as i128)),
            b'M' => stack.push(Value::Int(uint!(2) as i128)),
            b'J' => stack.push(Value::Int(uint!(4) as u32 as i32 as i128)),
            0x8a => {
                // LONG1: little-endian two's complement of n bytes.
                let n = uint!(1) as usize;
                let b = bytes!(n);
                if n > 16 {
                    stack.push(Value::Opaque);
                } else {
                    let mut v: i128 = 0;
                    for (i, x) in b.iter().enumerate() {
                        v |= (*x as i128) << (8 * i);
                    }
                    if n > 0 && n < 16 && b[n - 1] & 0x80 != 0 {
                        v -= 1i128 << (8 * n);
                    }
                    stack.push(Value::Int(v));
                }
            }
            b'G' => stack.push(Value::Float(f64::from_be_bytes(bytes!(8).try_into().unwrap_or([0; 8])))),
            b'X' => {
                let n = uint!(4) as usize;
                stack.push(Value::Str(String::from_utf8_lossy(&bytes!(n)).into_owned()));
            }
            0x8c => {
                let n = uint!(1) as usize;
                stack.push(Value::Str(String::from_utf8_lossy(&bytes!(n)).into_owned()));
            }
            0x8d => {
                let n = uint!(8) as usize;
                stack.push(Value::Str(String::from_utf8_lossy(&bytes!(n)).into_owned()));
            }
            b'U' | b'C' => {
                let n = uint!(1) as usize;
                stack.push(Value::Str(bytes!(n).iter().map(|&c| c as char).collect()));
            }
            b'T' | b'B' => {
                let n = uint!(4) as usize;
                stack.push(Value::Str(bytes!(n).iter().map(|&c| c as char).collect()));
            }
            b'c' => {
                let module = line(r)?;
                let name = line(r)?;
                stack.push(Value::Global(module, name));
            }
            0x93 => {
                let name = pop!();
                let module = pop!();
                match (module, name) {
                    (Value::Str(m), Value::Str(n)) => stack.push(Value::Global(m, n)),
                    _ => return Err(bad("STACK_GLOBAL without strings".into())),
                }
            }
            b')' => stack.push(Value::Tuple(Vec::new())),
            b']' => stack.push(Value::List(Vec::new())),
            b'}' => stack.push(Value::Dict(Vec::new())),
            0x85..=0x87 => {
                let n = (op - 0x84) as usize;
                if stack.len() < n {
                    return Err(bad("TUPLEn on a short stack".into()));
                }
                let items = stack.split_off(stack.len() - n);
                stack.push(Value::Tuple(items));
            }
            b't' | b'l' | b'd' | b'e' | b'u' | b'a' => {
                let item = if op == b'a' {
                    vec![pop!()]
                } else {
                    let m = marks.pop().ok_or_else(|| bad("a collection without MARK".into()))?;
                    stack.split_off(m.min(stack.len()))
                };
                match op {
                    b't' => stack.push(Value::Tuple(item)),
                    b'l' => stack.push(Value::List(item)),
                    b'd' => stack.push(Value::Dict(pairs(item))),
                    _ => match stack.last_mut() {
                        Some(Value::List(l)) if op != b'u' => l.extend(item),
                        Some(Value::Dict(d)) if op == b'u' => d.extend(pairs(item)),
                        _ => {}
                    },
                }
            }
            b's' => {
                let v = pop!();
                let k = pop!();
                if let Some(Value::Dict(d)) = stack.last_mut() {
                    d.push((k, v));
                }
            }
            b'q' => drop(memo.insert(uint!(1) as u32, stack.last().cloned().unwrap_or(Value::None))),
            b'r' => drop(memo.insert(uint!(4) as u32, stack.last().cloned().unwrap_or(Value::None))),
            0x94 => drop(memo.insert(memo.len() as u32, stack.last().cloned().unwrap_or(Value::None))),
            b'h' => stack.push(memo.get(&(uint!(1) as u32)).cloned().ok_or_else(|| bad("a memo miss".into()))?),
            b'j' => stack.push(memo.get(&(uint!(4) as u32)).cloned().ok_or_else(|| bad("a memo miss".into()))?),
            b'Q' => {
                let pid = pop!();
                stack.push(persistent_load(pid).ok_or_else(|| bad("an unknown persistent id".into()))?);
            }
            b'R' => {
                let args = pop!();
                let func = pop!();
                stack.push(reduce(func, args));
            }
            0x81 => {
                let _args = pop!();
                let _cls = pop!();
                stack.push(Value::Opaque);
            }
            b'b' => {
                // BUILD: state is ignored, the object stays, except for a tensor
                // class built from (storage, offset, size, stride) as very old torch did.
                let state = pop!();
                if let Some(Value::Global(m, n)) = stack.last()
                    && m == "torch"
                    && n.ends_with("Tensor")
                    && let Value::Tensor(t) =
                        reduce(Value::Global("torch._utils".into(), "_rebuild_tensor".into()), state)
                {
                    *stack.last_mut().ok_or_else(|| bad("BUILD on an empty stack".into()))? = Value::Tensor(t);
                }
            }
            other => {
                return Err(bad(format!(
                    "pickle opcode 0x{other:02x}, which torch.save does not write for a state dict"
                )));
            }
        }
    }
}

fn pairs(items: Vec<Value>) -> Vec<(Value, Value)> {
    let mut it = items.into_iter();
    let mut out = Vec::new();
    while let (Some(k), Some(v)) = (it.next(), it.next()) {
        out.push((k, v));
    }
    out
}

fn int(v: &Value) -> Option<usize> {
    match v {
        Value::Int(i) => usize::try_from(*i).ok(),
        _ => None,
    }
}

fn ints(v: &Value) -> Option<Vec<usize>> {
    match v {
        Value::Tuple(t) | Value::List(t) => t.iter().map(int).collect(),
        _ => None,
    }
}

/// `('storage', storage_type, key, location, numel[, view_metadata])`.
fn persistent_load(pid: Value) -> Option<Value> {
    let Value::Tuple(t) = pid else { return None };
    match (t.first(), t.get(1), t.get(2)) {
        (Some(Value::Str(kind)), Some(Value::Global(_, ty)), Some(Value::Str(key))) if kind == "storage" => {
            let view_offset = match t.get(5) {
                Some(Value::Tuple(view)) => view.get(1).and_then(int).unwrap_or(0),
                _ => 0,
            };
            Some(Value::Storage(ty.clone(), key.clone(), view_offset))
        }
        _ => None,
    }
}

fn reduce(func: Value, args: Value) -> Value {
    let Value::Global(module, name) = func else { return Value::Opaque };
    let Value::Tuple(args) = args else { return Value::Opaque };
    match (module.as_str(), name.as_str()) {
        ("collections", "OrderedDict") => Value::Dict(Vec::new()),
        ("torch._utils", "_rebuild_tensor" | "_rebuild_tensor_v2") => {
            let (Some(Value::Storage(ty, key, view_offset)), Some(offset), Some(shape), Some(stride)) =
                (args.first(), args.get(1).and_then(int), args.get(2).and_then(ints), args.get(3).and_then(ints))
            else {
                return Value::Opaque;
            };
            Value::Tensor(TensorRef {
                key: key.clone(),
                storage_type: ty.clone(),
                offset: offset + view_offset,
                shape,
                stride,
            })
        }
        // torch.FloatTensor() etc.: filled in by the BUILD that follows.
        ("torch", n) if n.ends_with("Tensor") && args.is_empty() => Value::Global(module.clone(), name.clone()),
        ("torch._utils", "_rebuild_parameter" | "_rebuild_parameter_with_state") => {
            args.into_iter().next().unwrap_or(Value::Opaque)
        }
        _ => Value::Opaque,
    }
}

#[cfg(test)]
#[path = "pth_tests.rs"]
mod tests;
