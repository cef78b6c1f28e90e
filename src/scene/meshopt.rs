//! glTF's `EXT_meshopt_compression` (what `gltfpack -c` writes) and its ratified successor
//! `KHR_meshopt_compression` (`gltfpack -cz`, or `-ce khr`): buffer views whose bytes are
//! stored compressed by meshoptimizer's vertex or index codec, possibly after a filter
//! (octahedral normals, quaternions, exponent-and-mantissa floats; the KHR extension also
//! allows the vertex codec's second version and a colour filter).
//!
//! Each compressed view is decoded once, by `meshoptimizer-rs` (a port of meshoptimizer 1.3's
//! decoders, the format's reference), into a buffer of its own that the document is rewritten
//! to point to: the rest of the loader reads it as it reads any view. The view's own `buffer`
//! is the uncompressed fallback, which such files usually leave empty (a buffer marked
//! `fallback`, with no data): it is never read for a decoded view.

use ::gltf::Gltf;
use ::gltf::json::validation::USize64;
use ::gltf::json::{self, Index};
use anyhow::{Result, anyhow, bail};
use meshoptimizer_rs::codec::{
    Filter, Mode, decode_buffer_view, decode_filter_color, decode_filter_exp, decode_filter_oct,
    decode_filter_quat, decode_index_buffer, decode_index_sequence, decode_vertex_buffer,
};
use meshoptimizer_rs::{Limits, Workspace};
use serde_json::Value;

/// The extension's name, as files list it.
pub(super) const EXTENSION: &str = "EXT_meshopt_compression";

/// The ratified extension's name: the same fields, a newer codec version and one more filter.
pub(super) const KHR_EXTENSION: &str = "KHR_meshopt_compression";

/// Both names.
pub(super) const EXTENSIONS: [&str; 2] = [EXTENSION, KHR_EXTENSION];

/// A buffer's bytes, or why it has none (said when something reads it).
pub(super) type Buffer = std::result::Result<Vec<u8>, String>;

/// True when `b` is a fallback buffer of the extension: the uncompressed data a reader without
/// it would read, which files may leave out (no URI, no data).
pub(super) fn is_fallback(b: &::gltf::Buffer) -> bool {
    EXTENSIONS.iter().any(|ext| {
        b.extension_value(ext)
            .and_then(|e| e.get("fallback"))
            .and_then(Value::as_bool)
            .unwrap_or(false)
    })
}

/// Decodes every compressed view of `doc` from `buffers` into one new buffer (appended to
/// `buffers`) and returns the document with those views pointing into it, the extension taken
/// off them. A document without compressed views is returned as it is. Errors name the file
/// (`name`) and the view.
pub(super) fn decompress(name: &str, doc: Gltf, buffers: &mut Vec<Buffer>) -> Result<Gltf> {
    let mut decoded: Vec<(usize, Vec<u8>)> = Vec::new();
    for view in doc.views() {
        let Some((ext_name, ext)) = EXTENSIONS
            .iter()
            .find_map(|n| view.extension_value(n).map(|e| (*n, e)))
        else {
            continue;
        };
        let at = format!("{name}: bufferViews[{}]: {ext_name}", view.index());
        let khr = ext_name == KHR_EXTENSION;
        let bytes = decode_view(&at, ext, khr, view.length(), buffers)?;
        decoded.push((view.index(), bytes));
    }
    if decoded.is_empty() {
        return Ok(doc);
    }
    let Gltf { document, blob } = doc;
    let mut root = document.into_json();
    // The decoded views one after another, each from a multiple of 16 bytes (every accessor
    // offset the views allow stays aligned).
    let mut data = Vec::new();
    let buffer = Index::new(root.buffers.len() as u32);
    for (i, bytes) in decoded {
        let offset = data.len().next_multiple_of(16);
        data.resize(offset, 0);
        data.extend_from_slice(&bytes);
        let view = &mut root.buffer_views[i];
        view.buffer = buffer;
        view.byte_offset = Some(USize64(offset as u64));
        if let Some(ext) = view.extensions.as_mut() {
            for n in EXTENSIONS {
                ext.others.remove(n);
            }
        }
    }
    root.buffers.push(json::Buffer {
        byte_length: USize64(data.len() as u64),
        name: Some("meshopt compression, decoded".into()),
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    buffers.push(Ok(data));
    Ok(Gltf {
        document: ::gltf::Document::from_json_without_validation(root),
        blob,
    })
}

/// The bytes of one compressed view of `length` bytes, described by its extension object `ext`
/// (of the KHR extension when `khr`).
fn decode_view(
    at: &str,
    ext: &Value,
    khr: bool,
    length: usize,
    buffers: &[Buffer],
) -> Result<Vec<u8>> {
    let field = |key: &str| -> Result<usize> {
        ext.get(key)
            .and_then(Value::as_u64)
            .and_then(|v| usize::try_from(v).ok())
            .ok_or_else(|| anyhow!("{at}: `{key}` is missing or not a count"))
    };
    let text = |key: &str, default: Option<&'static str>| -> Result<String> {
        match (ext.get(key), default) {
            (Some(Value::String(s)), _) => Ok(s.clone()),
            (None, Some(d)) => Ok(d.to_string()),
            _ => bail!("{at}: `{key}` is missing or not a string"),
        }
    };
    let b = field("buffer")?;
    let offset = match ext.get("byteOffset") {
        None => 0,
        Some(_) => field("byteOffset")?,
    };
    let (stored, stride, count) = (field("byteLength")?, field("byteStride")?, field("count")?);
    // What it decodes to is the view itself: checked before anything is decoded (or allocated).
    if count.checked_mul(stride) != Some(length) {
        bail!("{at}: {count} elements of {stride} bytes, where the view's byteLength is {length}");
    }
    let mode_name = text("mode", None)?;
    let filter_name = text("filter", Some("NONE"))?;
    let mode = Mode::parse(&mode_name).map_err(|_| anyhow!("{at}: unknown mode {mode_name}"))?;
    // The colour filter is the KHR extension's alone (the crate's EXT filters lack it).
    let color = khr && filter_name == "COLOR";
    let filter = if color {
        Filter::None
    } else {
        Filter::parse(&filter_name).map_err(|_| anyhow!("{at}: unknown filter {filter_name}"))?
    };
    let data = match buffers.get(b) {
        Some(Ok(d)) => d,
        Some(Err(why)) => bail!("{why}"),
        None => bail!("{at}: buffers[{b}] does not exist"),
    };
    let source = offset
        .checked_add(stored)
        .and_then(|end| data.get(offset..end))
        .ok_or_else(|| {
            anyhow!(
                "{at}: bytes {offset}..+{stored} run past buffers[{b}] ({} bytes)",
                data.len()
            )
        })?;
    let fail = |e| {
        anyhow!(
            "{at}: cannot decode {count} elements of {stride} bytes ({mode_name}, {filter_name}): {e:?}"
        )
    };
    let mut workspace = Workspace::new(Limits::default());
    if !khr {
        // The EXT extension's rules (the codecs' first version, the filters its modes allow)
        // checked by the crate's own decoder of such views.
        return decode_buffer_view(mode, filter, count, stride, source, &mut workspace)
            .map_err(fail);
    }
    if mode != Mode::Attributes && (color || filter != Filter::None) {
        bail!("{at}: the filter {filter_name} on {mode_name}: filters are for ATTRIBUTES only");
    }
    let w = &mut workspace;
    let mut data = match mode {
        Mode::Attributes => decode_vertex_buffer(count, stride, source, w),
        Mode::Triangles => decode_index_buffer(count, stride, source, w),
        Mode::Indices => decode_index_sequence(count, stride, source, w),
    }
    .map_err(fail)?;
    match filter {
        _ if color => decode_filter_color(&mut data, count, stride, w),
        Filter::None => Ok(()),
        Filter::Octahedral => decode_filter_oct(&mut data, count, stride, w),
        Filter::Quaternion => decode_filter_quat(&mut data, count, stride, w),
        Filter::Exponential => decode_filter_exp(&mut data, count, stride, w),
    }
    .map_err(fail)?;
    Ok(data)
}
