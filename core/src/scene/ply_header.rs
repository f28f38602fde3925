//! The PLY container shared by the INRIA and the PlayCanvas compressed readers:
//! header parsing and bounds-checked access to element rows.
//!
//! Both formats are plain PLY underneath, so the header grammar, the three
//! encodings and the element layout live here once. Nothing is allocated from a
//! header count before the count has been checked against the bytes the file
//! actually holds: a header that claims 10¹² vertices fails at once.

use std::path::Path;

use super::SceneError;

/// How the element data after `end_header` is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Encoding {
    /// Whitespace-separated decimal text.
    Ascii,
    /// Packed binary, little-endian.
    BinaryLe,
    /// Packed binary, big-endian.
    BinaryBe,
}

/// A scalar property type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    /// Size in bytes in the binary encodings.
    pub(crate) fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// The PLY spelling, for messages.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::I8 => "char",
            Self::U8 => "uchar",
            Self::I16 => "short",
            Self::U16 => "ushort",
            Self::I32 => "int",
            Self::U32 => "uint",
            Self::F32 => "float",
            Self::F64 => "double",
        }
    }
}

/// One scalar property of an element.
#[derive(Clone, Debug)]
pub(crate) struct Property {
    pub name: String,
    pub ty: Scalar,
}

/// One element declaration (`element vertex 1000` and its properties).
#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub name: String,
    pub count: usize,
    pub props: Vec<Property>,
}

impl Element {
    /// Index of the property called `name`.
    pub(crate) fn find(&self, name: &str) -> Option<usize> {
        self.props.iter().position(|p| p.name == name)
    }

    fn row_size(&self) -> usize {
        self.props.iter().map(|p| p.ty.size()).sum()
    }

    /// The property names, for messages.
    pub(crate) fn prop_list(&self) -> String {
        let names: Vec<&str> = self.props.iter().map(|p| p.name.as_str()).collect();
        if names.is_empty() { "no properties".into() } else { names.join(" ") }
    }
}

/// A parsed header plus where the element data starts.
#[derive(Clone, Debug)]
pub(crate) struct Header {
    pub encoding: Encoding,
    pub elements: Vec<Element>,
    pub body_offset: usize,
}

impl Header {
    /// The element called `name`, with its index.
    pub(crate) fn element(&self, name: &str) -> Option<(usize, &Element)> {
        self.elements.iter().enumerate().find(|(_, e)| e.name == name)
    }
}

/// The longest header accepted; real headers are a few kilobytes.
const MAX_HEADER: usize = 1 << 20;

/// Parses the header of a PLY file held in `bytes`.
pub(crate) fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, SceneError> {
    let fmt = |what: &str, expected: &str, found: String| SceneError::format(path, what, expected, found);
    if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
        let shown: Vec<u8> = bytes.iter().take(8).copied().collect();
        return Err(fmt("header", "magic line `ply`", format!("{:?}", String::from_utf8_lossy(&shown))));
    }
    let window = &bytes[..bytes.len().min(MAX_HEADER)];
    let end = find_end_header(window).ok_or_else(|| {
        fmt("header", "an `end_header` line within the first MiB", format!("{} bytes without one", window.len()))
    })?;
    let text = std::str::from_utf8(&bytes[..end.0])
        .map_err(|e| fmt("header", "ASCII header text", format!("invalid UTF-8 ({e})")))?;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for (lineno, raw) in text.lines().enumerate().skip(1) {
        let line = raw.trim();
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else { continue };
        let at = format!("header line {}", lineno + 1);
        match keyword {
            "format" => {
                let kind = words.next().unwrap_or("");
                encoding = Some(match kind {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLe,
                    "binary_big_endian" => Encoding::BinaryBe,
                    other => {
                        return Err(fmt(
                            &at,
                            "format ascii, binary_little_endian or binary_big_endian",
                            format!("format {other:?}"),
                        ));
                    }
                });
            }
            "comment" | "obj_info" => {}
            "element" => {
                let (Some(name), Some(count)) = (words.next(), words.next()) else {
                    return Err(fmt(&at, "`element <name> <count>`", format!("{line:?}")));
                };
                let count: usize = count
                    .parse()
                    .map_err(|_| fmt(&at, "a non-negative element count", format!("{count:?} for element {name}")))?;
                elements.push(Element { name: name.to_string(), count, props: Vec::new() });
            }
            "property" => {
                let Some(el) = elements.last_mut() else {
                    return Err(fmt(&at, "`element` before `property`", format!("{line:?}")));
                };
                let (Some(ty), Some(name)) = (words.next(), words.next()) else {
                    return Err(fmt(&at, "`property <type> <name>`", format!("{line:?}")));
                };
                if ty == "list" {
                    return Err(fmt(
                        &format!("{}.{}", el.name, words.last().unwrap_or(name)),
                        "scalar properties (splat files have no lists)",
                        "a list property".to_string(),
                    ));
                }
                let ty = Scalar::parse(ty)
                    .ok_or_else(|| fmt(&format!("{}.{name}", el.name), "a PLY scalar type", format!("type {ty:?}")))?;
                if el.find(name).is_some() {
                    return Err(fmt(&format!("{}.{name}", el.name), "unique property names", "a duplicate".into()));
                }
                el.props.push(Property { name: name.to_string(), ty });
            }
            other => return Err(fmt(&at, "a header keyword", format!("{other:?}"))),
        }
    }
    let encoding = encoding.ok_or_else(|| fmt("header", "a `format` line", "none".into()))?;
    let header = Header { encoding, elements, body_offset: end.1 };
    check_sizes(path, bytes.len(), &header)?;
    Ok(header)
}

/// Finds `end_header` followed by a newline; returns (header text end, body start).
fn find_end_header(bytes: &[u8]) -> Option<(usize, usize)> {
    let key = b"end_header";
    let mut from = 0;
    while let Some(pos) = bytes.get(from..)?.windows(key.len()).position(|w| w == key) {
        let at = from + pos;
        let after = at + key.len();
        let at_line_start = at == 0 || bytes.get(at - 1) == Some(&b'\n');
        match (bytes.get(after), bytes.get(after + 1)) {
            (Some(b'\n'), _) if at_line_start => return Some((at, after + 1)),
            (Some(b'\r'), Some(b'\n')) if at_line_start => return Some((at, after + 2)),
            _ => from = after,
        }
    }
    None
}

/// Rejects counts the file cannot possibly hold, before anything is allocated.
fn check_sizes(path: &Path, file_len: usize, h: &Header) -> Result<(), SceneError> {
    let available = file_len.saturating_sub(h.body_offset);
    let mut needed: usize = 0;
    for el in &h.elements {
        // ASCII needs at least two bytes per value ("0 "), binary the row size.
        let per_row = match h.encoding {
            Encoding::Ascii => 2 * el.props.len(),
            _ => el.row_size(),
        }
        .max(1);
        let bytes = el.count.checked_mul(per_row).and_then(|b| b.checked_add(needed));
        match bytes {
            Some(b) if b <= available.saturating_add(1) => needed = b,
            _ => {
                return Err(SceneError::format(
                    path,
                    format!("element {}", el.name),
                    format!("at most {available} bytes of data after the header"),
                    format!("a count of {} needing {} bytes", el.count, describe(bytes, el.count, per_row)),
                ));
            }
        }
    }
    Ok(())
}

fn describe(bytes: Option<usize>, count: usize, per_row: usize) -> String {
    match bytes {
        Some(b) => b.to_string(),
        None => format!("{count}×{per_row} (overflows)"),
    }
}

/// Read access to the rows of every element of a PLY body.
pub(crate) struct Body<'a> {
    header: &'a Header,
    bytes: &'a [u8],
    /// Binary: byte offset of each element's first row.
    offsets: Vec<usize>,
    /// ASCII: all values of each element, row-major.
    ascii: Vec<Vec<f64>>,
}

impl<'a> Body<'a> {
    /// Checks that the body holds every element completely and indexes it.
    pub(crate) fn new(path: &Path, header: &'a Header, bytes: &'a [u8]) -> Result<Self, SceneError> {
        let mut offsets = Vec::with_capacity(header.elements.len());
        let mut ascii = Vec::new();
        let body = bytes.get(header.body_offset..).unwrap_or(&[]);
        match header.encoding {
            Encoding::Ascii => {
                let text = String::from_utf8_lossy(body);
                let mut tokens = text.split_ascii_whitespace();
                for el in &header.elements {
                    let mut values = Vec::with_capacity(el.count * el.props.len());
                    for row in 0..el.count {
                        for p in &el.props {
                            let tok = tokens.next().ok_or_else(|| {
                                SceneError::format(
                                    path,
                                    format!("{}[{row}].{}", el.name, p.name),
                                    format!("{} rows", el.count),
                                    "end of file (truncated)",
                                )
                            })?;
                            let v: f64 = tok.parse().map_err(|_| {
                                SceneError::format(
                                    path,
                                    format!("{}[{row}].{}", el.name, p.name),
                                    format!("a {} number", p.ty.name()),
                                    format!("{tok:?}"),
                                )
                            })?;
                            values.push(v);
                        }
                    }
                    ascii.push(values);
                    offsets.push(0);
                }
            }
            Encoding::BinaryLe | Encoding::BinaryBe => {
                let mut at = header.body_offset;
                for el in &header.elements {
                    offsets.push(at);
                    let size = el.count.saturating_mul(el.row_size());
                    let end = at.saturating_add(size);
                    if end > bytes.len() {
                        let rows_there = bytes.len().saturating_sub(at) / el.row_size().max(1);
                        return Err(SceneError::format(
                            path,
                            format!("element {}", el.name),
                            format!("{} rows ({size} bytes)", el.count),
                            format!("{rows_there} complete rows before the end of the file (truncated)"),
                        ));
                    }
                    at = end;
                }
            }
        }
        Ok(Self { header, bytes, offsets, ascii })
    }

    /// Value of property `prop` of row `row` of element `el`, as f64 (exact
    /// for every PLY scalar type). Indices must come from the header; anything
    /// out of range reads as NaN, which the validators then report.
    pub(crate) fn get(&self, el: usize, row: usize, prop: usize) -> f64 {
        let Some(element) = self.header.elements.get(el) else { return f64::NAN };
        if row >= element.count || prop >= element.props.len() {
            return f64::NAN;
        }
        if self.header.encoding == Encoding::Ascii {
            let k = row * element.props.len() + prop;
            return self.ascii.get(el).and_then(|v| v.get(k)).copied().unwrap_or(f64::NAN);
        }
        let in_row: usize = element.props[..prop].iter().map(|p| p.ty.size()).sum();
        let ty = element.props[prop].ty;
        let start = self.offsets[el] + row * element.row_size() + in_row;
        let Some(b) = self.bytes.get(start..start + ty.size()) else { return f64::NAN };
        decode(ty, b, self.header.encoding == Encoding::BinaryBe)
    }

    /// A column reader for one property: precomputes the offsets `get` needs.
    pub(crate) fn column(&self, el: usize, prop: usize) -> Column<'_> {
        let found = self.header.elements.get(el).and_then(|e| Some((e, e.props.get(prop)?)));
        let Some((element, p)) = found else {
            // Not a header index: a column that reads NaN everywhere.
            return Column { body: self, el, prop, start: usize::MAX, stride: 0, ty: Scalar::F32 };
        };
        let in_row: usize = element.props[..prop].iter().map(|p| p.ty.size()).sum();
        Column {
            body: self,
            el,
            prop,
            start: self.offsets.get(el).copied().unwrap_or(usize::MAX).saturating_add(in_row),
            stride: element.row_size(),
            ty: p.ty,
        }
    }
}

/// Fast sequential access to one property of one element.
pub(crate) struct Column<'a> {
    body: &'a Body<'a>,
    el: usize,
    prop: usize,
    start: usize,
    stride: usize,
    ty: Scalar,
}

impl Column<'_> {
    /// The value in `row`; NaN when out of range (never panics).
    #[inline]
    pub(crate) fn get(&self, row: usize) -> f64 {
        if self.body.header.encoding == Encoding::Ascii {
            return self.body.get(self.el, row, self.prop);
        }
        let at = self.start.saturating_add(row.saturating_mul(self.stride));
        match self.body.bytes.get(at..at.saturating_add(self.ty.size())) {
            Some(b) => decode(self.ty, b, self.body.header.encoding == Encoding::BinaryBe),
            None => f64::NAN,
        }
    }
}

fn decode(ty: Scalar, b: &[u8], be: bool) -> f64 {
    macro_rules! num {
        ($t:ty, $n:expr) => {{
            let mut a = [0u8; $n];
            a.copy_from_slice(&b[..$n]);
            (if be { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
        }};
    }
    match ty {
        Scalar::I8 => num!(i8, 1),
        Scalar::U8 => num!(u8, 1),
        Scalar::I16 => num!(i16, 2),
        Scalar::U16 => num!(u16, 2),
        Scalar::I32 => num!(i32, 4),
        Scalar::U32 => num!(u32, 4),
        Scalar::F32 => num!(f32, 4),
        Scalar::F64 => num!(f64, 8),
    }
}
